"""Fixtures of the GUI tests: isolated settings, a synthetic take, an offscreen main window on it."""
from __future__ import annotations

import os

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

pytest.importorskip("pytestqt", reason="the GUI tests need pytest-qt (pip install '.[test]')")

from PySide6.QtCore import QSettings  # noqa: E402

from carapost.gui import qtfix  # noqa: E402

qtfix.apply()        # before pytest-qt's QApplication makes its first calls
from carapost.gui.demo_take import make_demo_take  # noqa: E402
from guihelpers import make_window  # noqa: E402



@pytest.fixture(autouse=True)
def isolated_settings(tmp_path, monkeypatch):
    """QSettings and the autosave folder in a temporary directory."""
    QSettings.setDefaultFormat(QSettings.Format.IniFormat)
    QSettings.setPath(QSettings.Format.IniFormat, QSettings.Scope.UserScope, str(tmp_path / "settings"))
    monkeypatch.setenv("CARAPOST_DATA_DIR", str(tmp_path / "data"))
    yield tmp_path


@pytest.fixture
def take():
    """(project, truth): 12 frames, 12 markers, 4 rigged sensors, detections = projections + strays."""
    return make_demo_take(frames=12, markers=12, strays=2)


@pytest.fixture
def window(qtbot, take):
    return make_window(qtbot, take[0])
