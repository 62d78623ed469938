"""Pictures of what each calibration step asks for: N-pose, T-pose, the walk, sensors on
a table, strapping on.

Why pictures: the person being calibrated reads a prompt from across the room, often in
a second language; a figure with its arms in the right place is understood at once, as
the Xsens and Rokoko apps show it.
"""

from __future__ import annotations

import math

from PySide6 import QtCore, QtGui, QtWidgets

W, H = 220.0, 260.0
INK = QtGui.QColor(70, 76, 90)
SENSOR = QtGui.QColor(245, 160, 40)
AXES = (QtGui.QColor(220, 60, 60), QtGui.QColor(50, 170, 80), QtGui.QColor(60, 110, 230))  # x, y, z
POSES = ("npose", "tpose", "walk", "table", "strap")


def _pt(x: float, y: float) -> QtCore.QPointF:
    return QtCore.QPointF(x, y)


class PosePicture(QtWidgets.QWidget):
    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.pose = "npose"
        self.setMinimumSize(180, 210)

    def set_pose(self, pose: str) -> None:
        if pose != self.pose:
            self.pose = pose if pose in POSES else "npose"
            self.update()

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:  # noqa: N802 (Qt's name)
        p = QtGui.QPainter(self)
        p.setRenderHint(QtGui.QPainter.RenderHint.Antialiasing)
        p.fillRect(self.rect(), QtGui.QColor(250, 250, 252))
        s = min(self.width() / W, self.height() / H)
        p.translate((self.width() - W * s) / 2, (self.height() - H * s) / 2)
        p.scale(s, s)
        getattr(self, f"_draw_{self.pose}")(p)
        p.end()

    # ------------------------------------------------------------------ pieces
    @staticmethod
    def _pen(p: QtGui.QPainter, colour: QtGui.QColor = INK, width: float = 9.0) -> None:
        p.setPen(QtGui.QPen(colour, width, QtCore.Qt.PenStyle.SolidLine, QtCore.Qt.PenCapStyle.RoundCap,
                            QtCore.Qt.PenJoinStyle.RoundJoin))
        p.setBrush(QtCore.Qt.BrushStyle.NoBrush)

    def _front_figure(self, p: QtGui.QPainter, arms: str, sensors: bool = False) -> None:
        """A person facing the viewer; arms ``down`` (N-pose) or ``level`` (T-pose)."""
        self._pen(p)
        p.drawLine(_pt(110, 70), _pt(110, 150))  # trunk
        p.drawLine(_pt(90, 80), _pt(130, 80))  # shoulders
        p.drawLine(_pt(98, 150), _pt(122, 150))  # hips
        p.drawPolyline(QtGui.QPolygonF([_pt(100, 150), _pt(98, 200), _pt(96, 245)]))
        p.drawPolyline(QtGui.QPolygonF([_pt(120, 150), _pt(122, 200), _pt(124, 245)]))
        if arms == "level":
            p.drawLine(_pt(90, 80), _pt(25, 80))
            p.drawLine(_pt(130, 80), _pt(195, 80))
            hands = (_pt(25, 80), _pt(195, 80))
        else:
            p.drawPolyline(QtGui.QPolygonF([_pt(90, 80), _pt(84, 118), _pt(82, 152)]))
            p.drawPolyline(QtGui.QPolygonF([_pt(130, 80), _pt(136, 118), _pt(138, 152)]))
            hands = (_pt(82, 152), _pt(138, 152))
        p.setBrush(INK)
        p.setPen(QtCore.Qt.PenStyle.NoPen)
        p.drawEllipse(_pt(110, 45), 16, 19)
        if sensors:
            p.setBrush(SENSOR)
            for c in (_pt(110, 145), _pt(110, 40), *hands, _pt(97, 228), _pt(123, 228)):
                p.drawRoundedRect(QtCore.QRectF(c.x() - 6, c.y() - 5, 12, 10), 2, 2)

    def _caption(self, p: QtGui.QPainter, text: str) -> None:
        p.setPen(INK)
        f = p.font()
        f.setPointSizeF(10)
        p.setFont(f)
        p.drawText(QtCore.QRectF(0, 0, W, 18), QtCore.Qt.AlignmentFlag.AlignCenter, text)

    # ------------------------------------------------------------------ poses
    def _draw_npose(self, p: QtGui.QPainter) -> None:
        self._front_figure(p, "down")
        self._caption(p, "N-pose: stand, arms by the side")

    def _draw_tpose(self, p: QtGui.QPainter) -> None:
        self._front_figure(p, "level")
        self._caption(p, "T-pose: arms level, palms down")

    def _draw_strap(self, p: QtGui.QPainter) -> None:
        self._front_figure(p, "level", sensors=True)
        self._caption(p, "strap the sensors on")

    def _draw_walk(self, p: QtGui.QPainter) -> None:
        """Seen from the side, mid-stride, walking to the right."""
        self._pen(p)
        hip, sh = _pt(100, 150), _pt(106, 80)
        p.drawLine(hip, sh)
        p.drawPolyline(QtGui.QPolygonF([hip, _pt(125, 198), _pt(140, 243), _pt(154, 243)]))  # front leg
        p.drawPolyline(QtGui.QPolygonF([hip, _pt(88, 198), _pt(68, 238), _pt(78, 246)]))  # back leg
        p.drawPolyline(QtGui.QPolygonF([sh, _pt(122, 112), _pt(136, 136)]))  # arm swinging forward
        p.drawPolyline(QtGui.QPolygonF([sh, _pt(92, 112), _pt(80, 138)]))
        p.setBrush(INK)
        p.setPen(QtCore.Qt.PenStyle.NoPen)
        p.drawEllipse(_pt(110, 52), 16, 19)
        # the direction and the count of steps
        self._pen(p, QtGui.QColor(60, 110, 230), 4)
        p.drawLine(_pt(150, 60), _pt(205, 60))
        p.setBrush(QtGui.QColor(60, 110, 230))
        p.drawPolygon(QtGui.QPolygonF([_pt(212, 60), _pt(200, 53), _pt(200, 67)]))
        for k in range(5):
            p.setPen(QtCore.Qt.PenStyle.NoPen)
            p.setBrush(QtGui.QColor(180, 186, 198))
            p.drawEllipse(_pt(20 + 40 * k, 255), 7, 3)
        self._caption(p, "walk 4-6 steps straight ahead, then stand")

    def _draw_table(self, p: QtGui.QPainter) -> None:
        """Sensors laid on a table, all the same way: x forward, y left, z up."""
        top = QtGui.QPolygonF([_pt(30, 150), _pt(190, 150), _pt(210, 200), _pt(10, 200)])
        p.setPen(QtGui.QPen(INK, 3))
        p.setBrush(QtGui.QColor(215, 190, 150))
        p.drawPolygon(top)
        self._pen(p, INK, 6)
        for x in (22, 198):
            p.drawLine(_pt(x, 200), _pt(x, 250))
        for k in range(4):
            cx, cy = 50 + 40 * k, 176
            p.setPen(QtGui.QPen(INK, 1.5))
            p.setBrush(SENSOR)
            p.drawRoundedRect(QtCore.QRectF(cx - 12, cy - 8, 24, 16), 3, 3)
        # one sensor's axes, drawn large above the table
        o = _pt(110, 95)
        for colour, (dx, dy), name in zip(AXES, ((-30, 22), (-42, -6), (0, -45)), "xyz"):
            self._pen(p, colour, 4)
            end = _pt(o.x() + dx, o.y() + dy)
            p.drawLine(o, end)
            ang = math.atan2(dy, dx)
            p.setBrush(colour)
            p.setPen(QtCore.Qt.PenStyle.NoPen)
            p.drawPolygon(QtGui.QPolygonF([
                _pt(end.x() + 8 * math.cos(ang), end.y() + 8 * math.sin(ang)),
                _pt(end.x() + 6 * math.cos(ang + 2.2), end.y() + 6 * math.sin(ang + 2.2)),
                _pt(end.x() + 6 * math.cos(ang - 2.2), end.y() + 6 * math.sin(ang - 2.2))]))
            p.setPen(colour)
            p.drawText(_pt(end.x() + 10 * math.cos(ang) - 4, end.y() + 14 * math.sin(ang) + 4), name)
        self._caption(p, "all sensors on the table: x forward, y left, z up")
