"""The 3D skeleton: GL line items for the bones, scatter items for the joints and contact
points, a floor grid, the root's trail, and a camera that follows the root or stays.

Why one line item per skeleton (with a colour per vertex) instead of an item per bone:
the view is redrawn 30 times a second next to the inference thread; one ``setData`` per
skeleton keeps that to a few GL calls. A second skeleton (the replay's re-run beside the
recording) is the same pair of items, drawn at an offset.
"""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
import pyqtgraph.opengl as gl

from app.gui.colours import CONTACT_OFF, CONTACT_ON, INFERRED, JOINT, TRAIL
from app.gui.skeleton_geometry import BONES, TRAIL_POINTS, VIEWS, bone_segments
from inference.body.body import Body, contact_points
from inference.body.skeleton import CONTACTS, N_SEGMENTS


class _Figure:
    """One skeleton's GL items."""

    def __init__(self, view: gl.GLViewWidget, colour: tuple[float, ...]) -> None:
        n = len(BONES) + 1
        self.colour = np.asarray(colour, dtype=float)
        self.segment_colours = np.tile(self.colour, (N_SEGMENTS, 1))
        self.bones = gl.GLLinePlotItem(pos=np.zeros((2 * n, 3)), mode="lines", width=5.0,
                                       color=np.tile(self.colour, (2 * n, 1)), antialias=True)
        self.joints = gl.GLScatterPlotItem(pos=np.zeros((N_SEGMENTS + len(CONTACTS), 3)), size=9.0,
                                           color=JOINT, pxMode=True)
        view.addItem(self.bones)
        view.addItem(self.joints)
        self.root = np.zeros(3)

    def show(self, joints: np.ndarray, rot: np.ndarray, contacts: np.ndarray, body: Body, offset: np.ndarray) -> None:
        j = np.asarray(joints, dtype=np.float64) + offset
        seg, owner = bone_segments(j, rot)
        self.bones.setData(pos=seg, color=np.repeat(self.segment_colours[owner], 2, axis=0))
        cps = contact_points(np.asarray(rot, np.float64), j, body)
        pts = np.concatenate([j, cps])
        col = np.tile(JOINT, (len(pts), 1))
        col[N_SEGMENTS:] = np.where(np.asarray(contacts, bool)[:, None], CONTACT_ON, CONTACT_OFF)
        self.joints.setData(pos=pts, color=col)
        self.root = j[0]

    def set_visible(self, on: bool) -> None:
        self.bones.setVisible(on)
        self.joints.setVisible(on)


class SkeletonView(gl.GLViewWidget):
    """``show_pose`` for each frame; ``set_segment_colours`` says what each segment is
    (measured, inferred, how sure); ``set_trail`` the root's path; ``set_view`` a preset."""

    is_gl = True

    def __init__(self, parent=None, figures: int = 1) -> None:
        super().__init__(parent)
        self.setBackgroundColor(pg.mkColor(24, 26, 30))
        self.setCameraPosition(distance=3.2, elevation=VIEWS["free"][0], azimuth=VIEWS["free"][1])
        grid = gl.GLGridItem(color=(255, 255, 255, 60))
        grid.setSize(16, 16)  # wider only draws a moire band at the horizon
        grid.setSpacing(0.5, 0.5)
        self.addItem(grid)
        self.grid = grid
        self._grid_at = (0.0, 0.0)
        self.trail = gl.GLLinePlotItem(pos=np.zeros((2, 3)), mode="line_strip", width=2.0, color=TRAIL,
                                       antialias=True)
        self.addItem(self.trail)
        self.figures = [_Figure(self, INFERRED) for _ in range(max(1, figures))]
        self.bones, self.joints = self.figures[0].bones, self.figures[0].joints
        self.follow = True
        self.follow_figure = 0
        self._trail = np.zeros((0, 3))

    def add_figure(self, colour: tuple[float, ...]) -> int:
        self.figures.append(_Figure(self, colour))
        return len(self.figures) - 1

    def set_segment_colours(self, colours: np.ndarray, figure: int = 0) -> None:
        self.figures[figure].segment_colours = np.asarray(colours, dtype=float)

    def show_pose(self, joints: np.ndarray, rot: np.ndarray, contacts: np.ndarray, body: Body, figure: int = 0,
                  offset: np.ndarray | tuple[float, float, float] = (0.0, 0.0, 0.0)) -> None:
        self.figures[figure].show(joints, rot, contacts, body, np.asarray(offset, dtype=float))
        if self.follow and figure == self.follow_figure:
            root = self.figures[figure].root
            self.opts["center"] = pg.Vector(float(root[0]), float(root[1]), 0.9)
            self._move_grid(root)
        self.update()

    def _move_grid(self, point: np.ndarray) -> None:
        """Keep the floor under the subject, in whole grid steps so its lines stay put."""
        at = (round(float(point[0]) / 2.0) * 2.0, round(float(point[1]) / 2.0) * 2.0)
        if at != self._grid_at:
            self.grid.resetTransform()
            self.grid.translate(at[0], at[1], 0.0)
            self._grid_at = at

    def set_figure_visible(self, figure: int, on: bool) -> None:
        self.figures[figure].set_visible(on)

    def set_trail(self, points: np.ndarray) -> None:
        """The root's path on the floor, oldest first (the last TRAIL_POINTS of it)."""
        p = np.asarray(points, dtype=float)[-TRAIL_POINTS:]
        if len(p) < 2:
            self.trail.setVisible(False)
            return
        q = p.copy()
        q[:, 2] = 0.005
        self.trail.setData(pos=q)
        self.trail.setVisible(True)

    def look_at(self, point: np.ndarray) -> None:
        """Centre the camera on ``point`` (the replay keeps two skeletons in view this way)."""
        self.opts["center"] = pg.Vector(float(point[0]), float(point[1]), float(point[2]))
        self._move_grid(point)
        self.update()

    def set_view(self, name: str) -> None:
        elevation, azimuth = VIEWS[name]
        self.setCameraPosition(elevation=elevation, azimuth=azimuth)
        self.update()
