"""Shared fixtures (helpers live in support.py)."""
import os
import sys
from pathlib import Path

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from support import make_project  # noqa: E402


def pytest_sessionstart(session):
    """Compile the blob and tracking kernels once, first: in a fresh clone that takes ~25 s and ~11 s,
    which must not fall inside a test's own time limit (a GUI test waits 20 s for Detect Blobs)."""
    from carapost.core.blobs import warm_up
    from carapost.core.tracking import warm_up as warm_up_tracking

    warm_up()
    warm_up_tracking()


@pytest.fixture
def project():
    return make_project()


@pytest.fixture
def steps_1_to_8():
    """Detections without step 9 (the learned centre correction, whose own tests are test_blob_centre_net.py):
    the tests of steps 1-8 look at what their own step does to the centres.  (Not through ``monkeypatch``: those
    tests undo their own patches midway.)"""
    from carapost.core.blobs import detector

    before = detector.LEARNED_CENTRES
    detector.LEARNED_CENTRES = False
    yield
    detector.LEARNED_CENTRES = before
