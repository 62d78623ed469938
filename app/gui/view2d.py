"""The skeleton drawn with QPainter, for machines where OpenGL is missing or will not
start (a remote desktop, a virtual machine without a GPU driver, PyOpenGL not installed).

Same calls as ``SkeletonView`` (``show_pose``, ``set_segment_colours``, ``set_trail``,
``set_view``, ``follow``), so every panel works with either; an orthographic projection
of the same camera presets.

It is also the outdoor view's skeleton by choice: drawn by QPainter it costs a fraction of
what software GL does (no GL pipeline, no read-back of a rendered frame), and with
``side_on`` the camera stays beside the subject as they turn, which is how a runner's legs
are read. A frame's drawing is a few batched calls (one pen per colour, the grid's lines in
one call), since on a laptop on battery every redraw is CPU.
"""

from __future__ import annotations

import math

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from app.gui.colours import CONTACT_OFF, CONTACT_ON, INFERRED, JOINT, TRAIL, qcolor_tuple
from app.gui.skeleton_geometry import TRAIL_POINTS, VIEWS, bone_segments
from inference.body.body import Body, contact_points
from inference.body.conventions import wrap_angle, yaw_of
from inference.body.skeleton import N_SEGMENTS

SPAN_M = 2.6  # metres of world that fit the widget's height
GRID_M = 0.5
BACKGROUND = (24, 26, 30)
SIDE_ELEVATION_DEG = 5.0
PEN_CACHE = 64  # pens kept for reuse (a handful of colours per frame)
HEADING_SMOOTH = 0.15  # per pose: the side-on camera follows the pelvis' heading over ~1/3 s, not its sway


class _Figure2D:
    def __init__(self, colour: tuple[float, ...]) -> None:
        self.segment_colours = np.tile(np.asarray(colour, float), (N_SEGMENTS, 1))
        self.lines: np.ndarray | None = None
        self.owner: np.ndarray | None = None
        self.points: np.ndarray | None = None
        self.contacts = np.zeros(4, bool)
        self.root = np.zeros(3)
        self.visible = True
        self.groups: tuple[tuple[bytes, bytes], list] | None = None  # (colours and owners, lines by colour)


class Skeleton2DView(QtWidgets.QWidget):
    is_gl = False

    def __init__(self, parent: QtWidgets.QWidget | None = None, figures: int = 1) -> None:
        super().__init__(parent)
        self.setMinimumSize(320, 240)
        self.figures = [_Figure2D(INFERRED) for _ in range(max(1, figures))]
        self.follow = True
        self.follow_figure = 0
        self.elevation, self.azimuth = VIEWS["free"]
        self.center = np.array([0.0, 0.0, 0.9])
        self._trail = np.zeros((0, 3))
        self.background = QtGui.QColor(*BACKGROUND)
        self.line_px = 4.0
        self.joint_px = 3.5
        self.grid_alpha = 50
        # the camera on the subject's right, square to the pelvis' heading, whichever way they turn
        self.side_on = False
        self._heading: float | None = None
        self._pens: dict[tuple[tuple[float, ...], float], QtGui.QPen] = {}

    def setBackgroundColor(self, colour: str | QtGui.QColor) -> None:  # noqa: N802 (SkeletonView's name)
        """A QColor or a name Qt reads ("#rrggbb", "black"); anything else is an error, not black."""
        c = QtGui.QColor(colour)
        if not c.isValid():
            raise ValueError(f"background colour {colour!r}: not a colour Qt reads (use \"#rrggbb\")")
        self.background = c
        self.update()

    def set_side_on(self, on: bool) -> None:
        self.side_on = on
        self._heading = None
        if on:
            self.elevation = SIDE_ELEVATION_DEG
        self.update()

    # ------------------------------------------------------------------ the SkeletonView calls
    def add_figure(self, colour: tuple[float, ...]) -> int:
        self.figures.append(_Figure2D(colour))
        return len(self.figures) - 1

    def set_segment_colours(self, colours: np.ndarray, figure: int = 0) -> None:
        self.figures[figure].segment_colours = np.asarray(colours, dtype=float)

    def show_pose(self, joints: np.ndarray, rot: np.ndarray, contacts: np.ndarray, body: Body, figure: int = 0,
                  offset: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        f = self.figures[figure]
        j = np.asarray(joints, dtype=np.float64) + np.asarray(offset, dtype=float)
        f.lines, f.owner = bone_segments(j, rot)
        f.points = np.concatenate([j, contact_points(np.asarray(rot, np.float64), j, body)])
        f.contacts = np.asarray(contacts, bool)
        f.root = j[0]
        if self.follow and figure == self.follow_figure:
            self.center = np.array([j[0, 0], j[0, 1], 0.9])
            if self.side_on:
                self._follow_heading(float(yaw_of(np.asarray(rot, np.float64)[0])))
        self.update()

    def _follow_heading(self, heading: float) -> None:
        """Camera on the subject's right: the azimuth 90 deg behind the smoothed heading, so the
        subject walks left to right across the screen."""
        if self._heading is None:
            self._heading = heading
        else:
            self._heading += HEADING_SMOOTH * float(wrap_angle(heading - self._heading))
        self.azimuth = math.degrees(self._heading) - 90.0

    def set_figure_visible(self, figure: int, on: bool) -> None:
        self.figures[figure].visible = on
        self.update()

    def set_trail(self, points: np.ndarray) -> None:
        self._trail = np.asarray(points, dtype=float)[-TRAIL_POINTS:]
        self.update()

    def look_at(self, point: np.ndarray) -> None:
        self.center = np.asarray(point, dtype=float).copy()
        self.update()

    def set_view(self, name: str) -> None:
        self.elevation, self.azimuth = VIEWS[name]
        self.update()

    # ------------------------------------------------------------------ drawing
    def _axes(self) -> tuple[np.ndarray, np.ndarray]:
        """Screen right and up as world directions, for a camera at (elevation, azimuth)
        looking at the centre (GL's convention: azimuth 0 puts the camera on +X)."""
        el, az = math.radians(self.elevation), math.radians(self.azimuth)
        cam = np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])
        fwd = -cam
        right = np.cross(fwd, [0.0, 0.0, 1.0])
        if np.linalg.norm(right) < 1e-6:
            right = np.array([-math.sin(az), math.cos(az), 0.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, fwd)
        return right, up

    def project(self, p: np.ndarray) -> np.ndarray:
        """(N, 3) world -> (N, 2) widget pixels."""
        right, up = self._axes()
        d = np.asarray(p, float) - self.center
        s = self.height() / SPAN_M
        x = self.width() / 2 + s * (d @ right)
        y = self.height() / 2 - s * (d @ up)
        return np.stack([x, y], axis=-1)

    @staticmethod
    def _groups(f: _Figure2D) -> list[tuple[tuple[float, ...], list[int]]]:
        """The figure's lines by colour, worked out again only when its colours change."""
        key = (f.segment_colours.tobytes(), f.owner.tobytes())
        if f.groups is None or f.groups[0] != key:
            colours = f.segment_colours[f.owner]
            groups = [(tuple(float(x) for x in c), np.flatnonzero((colours == c).all(axis=1)).tolist())
                      for c in np.unique(colours, axis=0)]
            f.groups = (key, groups)
        return f.groups[1]

    def _pen(self, colour: tuple[float, ...], width: float) -> QtGui.QPen:
        key = (tuple(float(c) for c in colour), width)
        pen = self._pens.get(key)
        if pen is None:
            if len(self._pens) >= PEN_CACHE:  # colours by spread change every frame: keep the cache small
                self._pens.clear()
            pen = QtGui.QPen(QtGui.QColor(*qcolor_tuple(colour)), width, QtCore.Qt.PenStyle.SolidLine,
                             QtCore.Qt.PenCapStyle.RoundCap)
            self._pens[key] = pen
        return pen

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:  # noqa: N802 (Qt's name)
        p = QtGui.QPainter(self)
        p.setRenderHint(QtGui.QPainter.RenderHint.Antialiasing)
        p.fillRect(self.rect(), self.background)
        if self.side_on:
            self._ground(p)
        else:
            self._grid(p)
        if len(self._trail) >= 2:
            q = self._trail.copy()
            q[:, 2] = 0.0
            xy = self.project(q)
            p.setPen(QtGui.QPen(QtGui.QColor(*qcolor_tuple(TRAIL)), 2))
            p.drawPolyline(QtGui.QPolygonF([QtCore.QPointF(*v) for v in xy]))
        for f in self.figures:
            if f.visible and f.lines is not None:
                self._figure(p, f)
        p.end()

    def _ground(self, p: QtGui.QPainter) -> None:
        """Side on, the floor grid is a band of lines seen edge on: the floor's line and a tick
        every GRID_M along it (they pass under the walker, so walking shows), unsmoothed."""
        p.setRenderHint(QtGui.QPainter.RenderHint.Antialiasing, False)
        p.setPen(QtGui.QPen(QtGui.QColor(255, 255, 255, self.grid_alpha), 2))
        right, _ = self._axes()
        along = np.array([right[0], right[1], 0.0])
        half = 0.5 * SPAN_M * self.width() / max(self.height(), 1)
        ends = self.center * np.array([1.0, 1.0, 0.0]) + np.outer([-half - GRID_M, half + GRID_M], along)
        (x0, y0), (x1, y1) = self.project(ends)
        p.drawLine(QtCore.QLineF(x0, y0, x1, y1))
        s = float(self.center[:2] @ along[:2])  # the centre's place along the line, in metres
        k = np.arange(np.floor((s - half) / GRID_M), np.ceil((s + half) / GRID_M) + 1) * GRID_M - s
        feet = self.center * np.array([1.0, 1.0, 0.0]) + np.outer(k, along)
        xy = self.project(feet)
        tick = 0.012 * self.height()
        p.drawLines([QtCore.QLineF(x, y, x, y + tick) for x, y in xy.tolist()])
        p.setRenderHint(QtGui.QPainter.RenderHint.Antialiasing, True)

    def _grid(self, p: QtGui.QPainter) -> None:
        p.setPen(QtGui.QPen(QtGui.QColor(255, 255, 255, self.grid_alpha), 1))
        cx, cy = (round(c / GRID_M) * GRID_M for c in self.center[:2])
        k = np.arange(-3.0, 3.0 + 1e-9, GRID_M)
        n = len(k)
        ends = np.zeros((2 * n, 2, 3))  # lines along y at each x, then along x at each y, on the floor
        ends[:n, :, 0] = (cx + k)[:, None]
        ends[:n, 0, 1], ends[:n, 1, 1] = cy - 3.0, cy + 3.0
        ends[n:, :, 1] = (cy + k)[:, None]
        ends[n:, 0, 0], ends[n:, 1, 0] = cx - 3.0, cx + 3.0
        xy = self.project(ends.reshape(-1, 3)).reshape(-1, 4)
        p.drawLines([QtCore.QLineF(*row) for row in xy.tolist()])

    def _figure(self, p: QtGui.QPainter, f: _Figure2D) -> None:
        xy = self.project(f.lines).reshape(-1, 4).tolist()
        for colour, rows in self._groups(f):  # one pen per colour: a handful of calls a frame
            p.setPen(self._pen(colour, self.line_px))
            p.drawLines([QtCore.QLineF(*xy[k]) for k in rows])
        pts = self.project(f.points)
        p.setPen(QtCore.Qt.PenStyle.NoPen)
        r = self.joint_px
        for k, (x, y) in enumerate(pts.tolist()):
            if k < N_SEGMENTS:
                colour = JOINT
            else:
                colour = CONTACT_ON if f.contacts[k - N_SEGMENTS] else CONTACT_OFF
            p.setBrush(QtGui.QColor(*qcolor_tuple(colour)))
            p.drawEllipse(QtCore.QPointF(x, y), r, r)
