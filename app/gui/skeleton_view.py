"""The 3D skeleton: one GL item for the bones, one for the joints and contact points, on
a floor grid, the camera following the root. Shared by every window that shows a body."""

from __future__ import annotations

import numpy as np
import pyqtgraph as pg
import pyqtgraph.opengl as gl

from inference.body.body import Body, contact_points
from inference.body.skeleton import CONTACTS, PARENTS

BONES = np.array([(i, PARENTS[i]) for i in range(1, len(PARENTS))], dtype=int)


class SkeletonView(gl.GLViewWidget):
    def __init__(self, parent=None) -> None:
        super().__init__(parent)
        self.setBackgroundColor(pg.mkColor(24, 26, 30))
        self.setCameraPosition(distance=3.2, elevation=10, azimuth=-70)
        grid = gl.GLGridItem(color=(255, 255, 255, 60))
        grid.setSize(40, 40)
        grid.setSpacing(0.5, 0.5)
        self.addItem(grid)
        n = len(BONES)
        self.bones = gl.GLLinePlotItem(pos=np.zeros((2 * n, 3)), mode="lines", width=4.0,
                                       color=(0.85, 0.9, 1.0, 1.0), antialias=True)
        self.joints = gl.GLScatterPlotItem(pos=np.zeros((24 + len(CONTACTS), 3)), size=9.0,
                                           color=(1.0, 0.75, 0.3, 1.0), pxMode=True)
        self.addItem(self.bones)
        self.addItem(self.joints)
        self.follow = True

    def show_pose(self, joints: np.ndarray, rot: np.ndarray, contacts: np.ndarray, body: Body) -> None:
        j = np.asarray(joints, dtype=np.float64)
        seg = np.empty((2 * len(BONES), 3))
        seg[0::2] = j[BONES[:, 0]]
        seg[1::2] = j[BONES[:, 1]]
        self.bones.setData(pos=seg)
        cps = contact_points(np.asarray(rot, np.float64), j, body)
        pts = np.concatenate([j, cps])
        col = np.tile([1.0, 0.75, 0.3, 1.0], (len(pts), 1))
        col[24:] = np.where(np.asarray(contacts)[:, None], [0.2, 1.0, 0.3, 1.0], [0.5, 0.5, 0.5, 1.0])
        self.joints.setData(pos=pts, color=col)
        if self.follow:
            root = j[0]
            self.opts["center"] = pg.Vector(float(root[0]), float(root[1]), 0.9)
        self.update()
