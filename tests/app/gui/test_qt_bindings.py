"""The Qt bindings keep None's reference count: PySide6 6.12.0 dropped one on every call of
a method that returns nothing, and on Python 3.11 (whose None is not immortal) the live
window, which makes hundreds of such calls a second, aborted with "Fatal Python error:
none_dealloc" after about four minutes. A release that does it again fails here instead."""

from __future__ import annotations

import sys

import pytest

pytest.importorskip("pytestqt")

from PySide6 import QtWidgets  # noqa: E402


@pytest.mark.parametrize("call", ["setText", "update", "resize"])
def test_void_methods_keep_nones_reference_count(qtbot, call):
    label = QtWidgets.QLabel("x")
    qtbot.addWidget(label)
    do = {"setText": lambda: label.setText("abc"), "update": label.update,
          "resize": lambda: label.resize(100, 40)}[call]
    do()
    before = sys.getrefcount(None)
    for _ in range(2000):
        do()
    assert abs(sys.getrefcount(None) - before) < 50, "the Qt bindings leak references to None"
