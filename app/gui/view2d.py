"""The skeleton drawn with QPainter, for machines where OpenGL is missing or will not
start (a remote desktop, a virtual machine without a GPU driver, PyOpenGL not installed).

Same calls as ``SkeletonView`` (``show_pose``, ``set_segment_colours``, ``set_trail``,
``set_view``, ``follow``), so every panel works with either; an orthographic projection
of the same camera presets.
"""

from __future__ import annotations

import math

import numpy as np
from PySide6 import QtCore, QtGui, QtWidgets

from app.gui.colours import CONTACT_OFF, CONTACT_ON, INFERRED, JOINT, TRAIL, qcolor_tuple
from app.gui.skeleton_geometry import TRAIL_POINTS, VIEWS, bone_segments
from inference.body.body import Body, contact_points
from inference.body.skeleton import N_SEGMENTS

SPAN_M = 2.6  # metres of world that fit the widget's height
GRID_M = 0.5


class _Figure2D:
    def __init__(self, colour: tuple[float, ...]) -> None:
        self.segment_colours = np.tile(np.asarray(colour, float), (N_SEGMENTS, 1))
        self.lines: np.ndarray | None = None
        self.owner: np.ndarray | None = None
        self.points: np.ndarray | None = None
        self.contacts = np.zeros(4, bool)
        self.root = np.zeros(3)
        self.visible = True


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
        self.update()

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

    def paintEvent(self, event: QtGui.QPaintEvent) -> None:  # noqa: N802 (Qt's name)
        p = QtGui.QPainter(self)
        p.setRenderHint(QtGui.QPainter.RenderHint.Antialiasing)
        p.fillRect(self.rect(), QtGui.QColor(24, 26, 30))
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

    def _grid(self, p: QtGui.QPainter) -> None:
        p.setPen(QtGui.QPen(QtGui.QColor(255, 255, 255, 50), 1))
        cx, cy = (round(c / GRID_M) * GRID_M for c in self.center[:2])
        ticks = np.arange(-3.0, 3.0 + 1e-9, GRID_M)
        for k in ticks:
            for a, b in (((cx + k, cy - 3, 0), (cx + k, cy + 3, 0)), ((cx - 3, cy + k, 0), (cx + 3, cy + k, 0))):
                (x0, y0), (x1, y1) = self.project(np.array([a, b], float))
                p.drawLine(QtCore.QPointF(x0, y0), QtCore.QPointF(x1, y1))

    def _figure(self, p: QtGui.QPainter, f: _Figure2D) -> None:
        xy = self.project(f.lines)
        for k, seg in enumerate(f.owner):
            p.setPen(QtGui.QPen(QtGui.QColor(*qcolor_tuple(f.segment_colours[seg])), 4,
                                QtCore.Qt.PenStyle.SolidLine, QtCore.Qt.PenCapStyle.RoundCap))
            p.drawLine(QtCore.QPointF(*xy[2 * k]), QtCore.QPointF(*xy[2 * k + 1]))
        pts = self.project(f.points)
        p.setPen(QtCore.Qt.PenStyle.NoPen)
        for k, (x, y) in enumerate(pts):
            if k < N_SEGMENTS:
                colour = JOINT
            else:
                colour = CONTACT_ON if f.contacts[k - N_SEGMENTS] else CONTACT_OFF
            p.setBrush(QtGui.QColor(*qcolor_tuple(colour)))
            p.drawEllipse(QtCore.QPointF(x, y), 3.5, 3.5)
