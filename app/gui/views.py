"""Which skeleton view this machine gets: the GL one, or the QPainter one when OpenGL
cannot be imported or no GL context can be made.

Why a probe before creating the GL widget: a QOpenGLWidget on a machine without working
GL does not fail when it is made, it shows black (or aborts later), so the context is
tried first; ``IMUCAP_NO_GL=1`` forces the fallback (and lets a test see it).
"""

from __future__ import annotations

import os

from PySide6 import QtCore, QtGui, QtWidgets

_GL_OK: bool | None = None
GL_PROBLEM: str | None = None


def share_gl_contexts() -> None:
    """Call before the QApplication exists. pyqtgraph compiles some shader programs once
    per class, so every GL view (live and replay) must share one set of GL resources; on
    separate contexts the second view fails to draw its joints."""
    if QtCore.QCoreApplication.instance() is None:
        QtCore.QCoreApplication.setAttribute(QtCore.Qt.ApplicationAttribute.AA_ShareOpenGLContexts)


share_gl_contexts()


def gl_available() -> bool:
    global _GL_OK, GL_PROBLEM
    if _GL_OK is not None:
        return _GL_OK
    if os.environ.get("IMUCAP_NO_GL"):
        _GL_OK, GL_PROBLEM = False, "IMUCAP_NO_GL is set"
        return False
    try:
        import OpenGL.GL  # noqa: F401
        import pyqtgraph.opengl  # noqa: F401
    except Exception as exc:  # ImportError, or PyOpenGL failing to find a library
        _GL_OK, GL_PROBLEM = False, f"OpenGL cannot be imported ({exc})"
        return False
    if not QtCore.QCoreApplication.testAttribute(QtCore.Qt.ApplicationAttribute.AA_ShareOpenGLContexts):
        _GL_OK, GL_PROBLEM = False, "the application was made before GL context sharing was asked for"
        return False
    ctx = QtGui.QOpenGLContext()
    if not ctx.create() or not ctx.isValid():
        _GL_OK, GL_PROBLEM = False, "no OpenGL context can be created"
        return False
    _GL_OK = True
    return True


def make_skeleton_view(parent: QtWidgets.QWidget | None = None, figures: int = 1) -> QtWidgets.QWidget:
    """A SkeletonView, or a Skeleton2DView when GL is not there (``GL_PROBLEM`` says why)."""
    global _GL_OK, GL_PROBLEM
    if gl_available():
        try:
            from app.gui.skeleton_view import SkeletonView

            return SkeletonView(parent, figures=figures)
        except Exception as exc:  # the widget itself failed: fall back rather than lose the window
            _GL_OK, GL_PROBLEM = False, f"the 3D view failed ({exc})"
    from app.gui.view2d import Skeleton2DView

    return Skeleton2DView(parent, figures=figures)


class _AttachOnShow(QtCore.QObject):
    def __init__(self, panel: QtWidgets.QWidget, layout: QtWidgets.QBoxLayout, view: QtWidgets.QWidget,
                 stretch: int) -> None:
        super().__init__(panel)
        self.layout_, self.view, self.stretch = layout, view, stretch
        self.placeholder = QtWidgets.QWidget()
        layout.addWidget(self.placeholder, stretch)
        panel.installEventFilter(self)

    def eventFilter(self, obj: QtCore.QObject, event: QtCore.QEvent) -> bool:  # noqa: N802 (Qt's name)
        if event.type() == QtCore.QEvent.Type.Show and self.view is not None:
            # taken before it goes in: the first GL widget in a window makes Qt create the window again
            # for GL composition, and the panel's Show comes back from inside insertWidget. Answered
            # again, it put the view in a second time at the layout's end (index -1), where the two
            # items halved the panel's height between them and the live view showed the body cut off
            view, self.view = self.view, None
            obj.removeEventFilter(self)
            at = self.layout_.indexOf(self.placeholder)
            self.layout_.removeWidget(self.placeholder)
            self.placeholder.deleteLater()
            self.layout_.insertWidget(at, view, self.stretch)
        return False


def add_view(panel: QtWidgets.QWidget, layout: QtWidgets.QBoxLayout, view: QtWidgets.QWidget,
             stretch: int = 1) -> None:
    """Put a skeleton view (made without a parent) into a panel's layout; a GL one only when
    the panel is first shown.

    Why wait: from the moment a GL widget is in a window, Qt composes the whole window
    through OpenGL, every repaint of every label included. Under software GL (a laptop
    without a driver, Xvfb) that is most of the window's CPU, so a window used only on
    the outdoor view's flat skeleton must not carry the Live tab's hidden GL view. The
    view works before it is shown (its calls only store what it will draw)."""
    if getattr(view, "is_gl", False):
        _AttachOnShow(panel, layout, view, stretch)
    else:
        layout.addWidget(view, stretch)
