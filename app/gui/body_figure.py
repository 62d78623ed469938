"""A flat drawing of a person facing the viewer with the 13 sensor sites as spots to click.

Why a drawing and not a list of names: "l_upperarm" on a list is read as the viewer's
left by half the people strapping sensors; a figure facing you, with L and R written on
it, is how Xsens MVN and SlimeVR show it, and one glance tells which sites are chosen,
which have a device, which has dropped out.
"""

from __future__ import annotations

from PySide6 import QtCore, QtGui, QtWidgets

from inference.body.skeleton import SITES

W, H = 200.0, 420.0  # the figure's own coordinates; scaled to the widget keeping the aspect

# the subject faces the viewer: their left side is on the right of the picture
SPOTS: dict[str, tuple[float, float]] = {
    "head": (100, 34), "torso": (100, 118), "pelvis": (100, 196),
    "l_upperarm": (144, 122), "r_upperarm": (56, 122), "l_wrist": (158, 204), "r_wrist": (42, 204),
    "l_thigh": (121, 252), "r_thigh": (79, 252), "l_shank": (122, 352), "r_shank": (78, 352),
    "l_foot": (130, 402), "r_foot": (70, 402),
}
LIMBS = (  # polylines of the body drawn under the spots
    ((100, 64), (100, 200)),  # spine
    ((62, 86), (138, 86)),  # shoulders
    ((138, 86), (152, 150), (160, 214)), ((62, 86), (48, 150), (40, 214)),  # arms
    ((80, 204), (120, 204)),  # hips
    ((120, 204), (121, 296), (123, 390), (136, 404)), ((80, 204), (79, 296), (77, 390), (64, 404)),  # legs
)
SPOT_R = 9.0

COLOURS = {
    "off": QtGui.QColor(235, 237, 240), "chosen": QtGui.QColor(245, 160, 40), "assigned": QtGui.QColor(60, 190, 110),
    "alarm": QtGui.QColor(225, 50, 50), "highlight": QtGui.QColor(255, 230, 40), "body": QtGui.QColor(150, 156, 168),
    "insoles": QtGui.QColor(70, 130, 230),
}


class BodyFigure(QtWidgets.QWidget):
    """``siteClicked(site)`` on a click; what each spot shows is set from outside
    (``set_state``), so the same figure serves the setup and the devices panels."""

    siteClicked = QtCore.Signal(str)

    def __init__(self, parent: QtWidgets.QWidget | None = None) -> None:
        super().__init__(parent)
        self.chosen: set[str] = set()
        self.assigned: dict[str, str] = {}
        self.alarm: set[str] = set()
        self.highlight: str | None = None
        self.insoles = False
        self.setMinimumSize(170, 330)
        self.setMouseTracking(True)
        self.setSizePolicy(QtWidgets.QSizePolicy.Policy.Preferred, QtWidgets.QSizePolicy.Policy.Expanding)

    def set_state(self, chosen: set[str] | tuple[str, ...], assigned: dict[str, str], alarm: set[str] | None = None,
                  highlight: str | None = None, insoles: bool = False) -> None:
        self.chosen, self.assigned = set(chosen), dict(assigned)
        self.alarm, self.highlight, self.insoles = set(alarm or ()), highlight, insoles
        self.update()

    # ------------------------------------------------------------------ geometry
    def _transform(self) -> QtGui.QTransform:
        s = min(self.width() / W, self.height() / H)
        t = QtGui.QTransform()
        t.translate((self.width() - W * s) / 2, (self.height() - H * s) / 2)
        t.scale(s, s)
        return t

    def spot_at(self, pos: QtCore.QPointF) -> str | None:
        inv, ok = self._transform().inverted()
        if not ok:
            return None
        p = inv.map(pos)
        best = min(SITES, key=lambda s: (SPOTS[s][0] - p.x()) ** 2 + (SPOTS[s][1] - p.y()) ** 2)
        x, y = SPOTS[best]
        return best if (x - p.x()) ** 2 + (y - p.y()) ** 2 <= (SPOT_R * 1.6) ** 2 else None

    def spot_center(self, site: str) -> QtCore.QPoint:
        """Where ``site`` is on screen (for tests that click it, and for tooltips)."""
        return self._transform().map(QtCore.QPointF(*SPOTS[site])).toPoint()

    # ------------------------------------------------------------------ events
    def mousePressEvent(self, event: QtGui.QMouseEvent) -> None:  # noqa: N802 (Qt's name)
        site = self.spot_at(event.position())
        if site is not None and event.button() == QtCore.Qt.MouseButton.LeftButton:
            self.siteClicked.emit(site)

    def mouseMoveEvent(self, event: QtGui.QMouseEvent) -> None:  # noqa: N802
        site = self.spot_at(event.position())
        self.setCursor(QtCore.Qt.CursorShape.PointingHandCursor if site else QtCore.Qt.CursorShape.ArrowCursor)
        if site:
            url = self.assigned.get(site)
            tip = f"{site}: {url}" if url else f"{site}: {'no device yet' if site in self.chosen else 'not used'}"
            QtWidgets.QToolTip.showText(event.globalPosition().toPoint(), tip, self)
        else:
            QtWidgets.QToolTip.hideText()

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:  # noqa: N802
        p = QtGui.QPainter(self)
        p.setRenderHint(QtGui.QPainter.RenderHint.Antialiasing)
        p.setTransform(self._transform())
        body = QtGui.QPen(COLOURS["body"], 16, QtCore.Qt.PenStyle.SolidLine, QtCore.Qt.PenCapStyle.RoundCap,
                          QtCore.Qt.PenJoinStyle.RoundJoin)
        p.setPen(body)
        for line in LIMBS:
            p.drawPolyline(QtGui.QPolygonF([QtCore.QPointF(*xy) for xy in line]))
        p.setBrush(COLOURS["body"])
        p.setPen(QtCore.Qt.PenStyle.NoPen)
        p.drawEllipse(QtCore.QPointF(100, 38), 22, 26)
        if self.insoles:
            p.setBrush(COLOURS["insoles"])
            for x in (64, 136):
                p.drawRoundedRect(QtCore.QRectF(x - 14, 408, 28, 8), 3, 3)
        for site in SITES:
            self._spot(p, site)
        p.setPen(QtGui.QColor(90, 96, 110))
        font = p.font()
        font.setPointSizeF(9)
        font.setBold(True)
        p.setFont(font)
        p.drawText(QtCore.QRectF(170, 0, 30, 20), QtCore.Qt.AlignmentFlag.AlignCenter, "L")
        p.drawText(QtCore.QRectF(0, 0, 30, 20), QtCore.Qt.AlignmentFlag.AlignCenter, "R")
        p.end()

    def _spot(self, p: QtGui.QPainter, site: str) -> None:
        x, y = SPOTS[site]
        if site in self.alarm:
            fill = COLOURS["alarm"]
        elif site in self.chosen:
            fill = COLOURS["assigned"] if self.assigned.get(site) else COLOURS["chosen"]
        else:
            fill = COLOURS["off"]
        p.setBrush(fill)
        p.setPen(QtGui.QPen(QtGui.QColor(40, 44, 52), 1.5))
        p.drawEllipse(QtCore.QPointF(x, y), SPOT_R, SPOT_R)
        if site == self.highlight:
            p.setBrush(QtCore.Qt.BrushStyle.NoBrush)
            p.setPen(QtGui.QPen(COLOURS["highlight"], 4))
            p.drawEllipse(QtCore.QPointF(x, y), SPOT_R + 5, SPOT_R + 5)
