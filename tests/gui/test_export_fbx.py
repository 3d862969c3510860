"""File > Export FBX from the menu: a scripted save dialog, the file written off the GUI thread, read back by ufbx."""
from __future__ import annotations

import numpy as np
import pytest

from carapost.core.points import BRIM, ST_RECONSTRUCTED
from carapost.gui.demo_take import make_demo_take
from guihelpers import make_window
from test_fbx import _Read

pytestmark = pytest.mark.gui


def _tracked_take():
    """A demo take with its true markers as points: labelled, unlabelled, one with a gap, one brim point."""
    p, truth = make_demo_take(frames=12, markers=5, strays=0)
    for i in range(5):
        pt = p.new_point(kind=BRIM if i == 4 else "face", label="" if i == 3 else f"M{i}",
                         brim_index=0 if i == 4 else -1)
        pt.pos[:] = truth[:, i]
        pt.status[:] = ST_RECONSTRUCTED
        p.add_point(pt)
    gap = p.point_by_label("M1")
    gap.status[4:7] = 0
    gap.pos[4:7] = np.nan
    return p


def test_file_export_fbx_writes_every_point(qtbot, tmp_path):
    p = _tracked_take()
    win = make_window(qtbot, p)
    action = win.action("file.export_fbx")
    assert action.isEnabled() and action.text().replace("&", "") == "Export FBX"
    win.prompts.queue("save_file", str(tmp_path / "take"))        # the suffix is added
    action.trigger()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    out = tmp_path / "take.fbx"
    assert out.exists() and not win.prompts.errors
    r = _Read(out)
    assert r.fps == p.frame_rate
    assert sorted(r.tree["Face"]) == sorted(pt.name for pt in p.points.values() if pt.kind != BRIM)
    assert r.tree["Brim"] == ["M4"]
    for pt in p.points.values():
        frames = np.flatnonzero(pt.status != 0)
        assert r.frames(pt.name, p.frame_rate) == frames.tolist()
        np.testing.assert_allclose(r.keys[pt.name][1], pt.pos[frames], atol=1e-3)
    assert 5 not in r.frames("M1")
