"""Every GL view of a window shares one set of GL resources; Qt only allows that when it
is asked for before the QApplication is made, which pytest-qt does at the first test."""

from app.gui.views import share_gl_contexts

share_gl_contexts()
