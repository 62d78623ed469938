"""Small widgets the panels share: the message bar, speed bars, the colour legend.

Why a message bar and not only dialogs: a device dropping out mid-session must be seen
from across the room without stopping anyone's work, and must stay until it is fixed; a
modal dialog would block the live view, a console line would never be read.
"""

from __future__ import annotations

import time

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from app.gui.colours import MEASURED, SPREAD_STOPS, qcolor_tuple, spread_colour

LEVEL_STYLE = {
    "info": "background: #e8f1fd; color: #123; border: 1px solid #9bbbe6;",
    "ok": "background: #e6f6ea; color: #123; border: 1px solid #8ccf9d;",
    "warning": "background: #fff4d6; color: #321; border: 1px solid #e8c15a;",
    "error": "background: #fbe3e3; color: #400; border: 1px solid #e07070;",
    "alarm": "background: #d93030; color: white; font-weight: bold; border: 1px solid #901010;",
}


class MessageBar(QtWidgets.QFrame):
    """One line of news at the top of the window. An alarm stays (and wins over other
    messages) until ``clear_alarm``; other messages can be closed, info fades by itself."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        lay = QtWidgets.QHBoxLayout(self)
        lay.setContentsMargins(8, 4, 4, 4)
        self.label = QtWidgets.QLabel()
        self.label.setWordWrap(True)
        self.label.setTextInteractionFlags(QtCore.Qt.TextInteractionFlag.TextSelectableByMouse)
        close = QtWidgets.QToolButton()
        close.setText("✕")
        close.setAutoRaise(True)
        close.clicked.connect(self.dismiss)
        lay.addWidget(self.label, 1)
        lay.addWidget(close)
        self.level = ""
        self.alarm_text: str | None = None
        self.history: list[tuple[float, str, str]] = []
        self._hide = QtCore.QTimer(self)
        self._hide.setSingleShot(True)
        self._hide.timeout.connect(self._expire)
        self.hide()

    def show_message(self, text: str, level: str = "info", seconds: float | None = None) -> None:
        self.history.append((time.monotonic(), level, text))
        if self.alarm_text is not None and level != "alarm":
            return  # the alarm stays on top; the message is in the history and the events list
        self.level = level
        self.label.setText(text)
        self.setStyleSheet(f"QFrame {{{LEVEL_STYLE.get(level, LEVEL_STYLE['info'])}}}")
        self.show()
        if seconds is None:
            seconds = 8.0 if level in ("info", "ok") else 0.0
        if seconds:
            self._hide.start(int(seconds * 1000))
        else:
            self._hide.stop()

    def alarm(self, text: str) -> None:
        self.alarm_text = text
        self.show_message(text, "alarm", seconds=0.0)

    def clear_alarm(self, then: str | None = None) -> None:
        self.alarm_text = None
        if then:
            self.show_message(then, "ok")
        elif self.level == "alarm":
            self.hide()

    def dismiss(self) -> None:
        if self.alarm_text is None:
            self.hide()

    def _expire(self) -> None:
        if self.alarm_text is None and self.level in ("info", "ok"):
            self.hide()


class SpeedBars(QtWidgets.QWidget):
    """Each sensor's angular speed against the stillness limits of the calibration step:
    green below ``still``, amber between, red above ``moved``."""

    def __init__(self, parent: QtWidgets.QWidget | None = None, full_scale: float = 120.0) -> None:
        super().__init__(parent)
        self.full_scale = full_scale
        self.speeds: dict[str, float] = {}
        self.still, self.moved = 20.0, 35.0
        self.setMinimumHeight(120)

    def set_speeds(self, speeds: dict[str, float], still: float, moved: float) -> None:
        self.speeds, self.still, self.moved = dict(speeds), still, moved
        self.setMinimumHeight(18 * max(len(speeds), 1) + 8)
        self.update()

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:  # noqa: N802 (Qt's name)
        p = QtGui.QPainter(self)
        p.setRenderHint(QtGui.QPainter.RenderHint.Antialiasing)
        label_w, row = 86, 18
        bar_w = max(self.width() - label_w - 70, 20)
        for k, (site, v) in enumerate(self.speeds.items()):
            y = 4 + k * row
            p.setPen(QtGui.QColor(40, 44, 52))
            p.drawText(QtCore.QRectF(0, y, label_w - 6, row - 2),
                       QtCore.Qt.AlignmentFlag.AlignRight | QtCore.Qt.AlignmentFlag.AlignVCenter, site)
            p.setPen(QtCore.Qt.PenStyle.NoPen)
            p.setBrush(QtGui.QColor(228, 230, 235))
            p.drawRect(QtCore.QRectF(label_w, y + 2, bar_w, row - 6))
            colour = (QtGui.QColor(60, 180, 90) if v < self.still else
                      QtGui.QColor(235, 170, 40) if v <= self.moved else QtGui.QColor(220, 60, 60))
            p.setBrush(colour)
            p.drawRect(QtCore.QRectF(label_w, y + 2, bar_w * min(v / self.full_scale, 1.0), row - 6))
            p.setPen(QtGui.QPen(QtGui.QColor(60, 60, 60), 1, QtCore.Qt.PenStyle.DashLine))
            for limit in (self.still, self.moved):
                x = label_w + bar_w * min(limit / self.full_scale, 1.0)
                p.drawLine(QtCore.QPointF(x, y), QtCore.QPointF(x, y + row - 2))
            p.setPen(QtGui.QColor(40, 44, 52))
            p.drawText(QtCore.QRectF(label_w + bar_w + 6, y, 64, row - 2),
                       QtCore.Qt.AlignmentFlag.AlignVCenter, f"{v:5.0f} °/s")
        p.end()


class Legend(QtWidgets.QWidget):
    """What the skeleton's colours mean: measured / inferred, and the spread ramp once
    the poser reports one."""

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.with_spread = False
        self.setFixedHeight(22)

    def set_spread(self, on: bool) -> None:
        if on != self.with_spread:
            self.with_spread = on
            self.update()

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:  # noqa: N802
        p = QtGui.QPainter(self)
        x = 4
        x = self._swatch(p, x, MEASURED, "measured by a sensor")
        if self.with_spread:
            p.setPen(QtGui.QColor(40, 44, 52))
            p.drawText(QtCore.QRectF(x, 2, 130, 18), QtCore.Qt.AlignmentFlag.AlignVCenter, "inferred, spread:")
            x += 112
            steps = 60
            for k in range(steps):
                deg = SPREAD_STOPS[-1][0] * k / (steps - 1)
                p.fillRect(QtCore.QRectF(x + 2 * k, 5, 2, 12), QtGui.QColor(*qcolor_tuple(spread_colour(deg))))
            p.drawText(QtCore.QRectF(x + 2 * steps + 4, 2, 80, 18), QtCore.Qt.AlignmentFlag.AlignVCenter,
                       f"0 … {SPREAD_STOPS[-1][0]:.0f}°+")
        else:
            self._swatch(p, x, (0.86, 0.88, 0.92, 1.0), "inferred by the model")
        p.end()

    @staticmethod
    def _swatch(p: QtGui.QPainter, x: float, rgba: tuple[float, ...], text: str) -> float:
        p.fillRect(QtCore.QRectF(x, 5, 22, 12), QtGui.QColor(*qcolor_tuple(rgba)))
        p.setPen(QtGui.QColor(40, 44, 52))
        p.drawText(QtCore.QRectF(x + 28, 2, 160, 18), QtCore.Qt.AlignmentFlag.AlignVCenter, text)
        return x + 28 + p.fontMetrics().horizontalAdvance(text) + 16


def fmt(v: float | None, spec: str = ".0f", unit: str = "", missing: str = "–") -> str:
    if v is None or (isinstance(v, float) and not np.isfinite(v)):
        return missing
    return f"{v:{spec}}{unit}"
