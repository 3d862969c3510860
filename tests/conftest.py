"""Shared fixtures (helpers live in support.py)."""
import os
import sys
from pathlib import Path

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from support import make_project  # noqa: E402


@pytest.fixture
def project():
    return make_project()
