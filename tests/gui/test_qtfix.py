"""The PySide6 6.12.0 / Python 3.11 reference-count workaround keeps long sessions alive."""
from __future__ import annotations

import subprocess
import sys

import pytest

pytestmark = pytest.mark.gui

CODE = """
from carapost.gui.app import ensure_app
app = ensure_app(offscreen=True)
from PySide6.QtCore import QObject, Signal
class O(QObject):
    s = Signal()
o = O()
for _ in range(300_000):     # far more void calls and emits than None/True have references
    o.setObjectName("x")
    o.s.emit()
print("alive")
"""


def test_many_qt_calls_do_not_exhaust_none_or_true():
    r = subprocess.run([sys.executable, "-c", CODE], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and "alive" in r.stdout, r.stderr[-500:]
