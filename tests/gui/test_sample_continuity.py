"""Continuity chart and Selected Point pane on a tracked `carapost sample` take with a known gap (issue 10)."""
from __future__ import annotations

import numpy as np
import pytest

from carapost.core import continuity as C
from carapost.core.points import ST_INTERPOLATED, ST_NONE
from guihelpers import make_window
from test_continuity import _switch

pytestmark = pytest.mark.gui


@pytest.fixture(scope="module")
def tracked_sample(tmp_path_factory):
    """A rendered 35-marker, 6-frame sample take through the headless pipeline and tracking."""
    from carapost.api import CaraProcess
    from carapost.sample import write_sample

    d = tmp_path_factory.mktemp("sample")
    write_sample(d, markers=35, frames=6, seed=1, workers=1)
    p = CaraProcess(d / "Sample_0.pico")
    p.import_xcp(d / "calibration.xcp")
    p.set_brim(d / "brim.svg")
    p.detect_blobs()
    p.initialize_from_seeds(d / "seeds.json")
    p.track(frame=0)
    return p.project


def test_bars_of_a_point_with_a_known_gap(qtbot, tracked_sample):
    from carapost.core.edits import ClearPointRange

    project = tracked_sample
    win = make_window(qtbot, project)
    pt = next(q for q in project.face_points() if q.label and np.all(q.status != ST_NONE))
    win.session.run(ClearPointRange([pt.id], 2, 3))          # the known gap: frames 2-3
    win.session.select(points=[pt.id])
    pane = win.selected_point
    assert pane.label() == pt.label
    assert pane.color_at(2) == C.COLORS["gap"] and pane.color_at(3) == C.COLORS["gap"]
    for f in (0, 1, 4, 5):
        # The guide's colours: dark green 4 channels, light green 3, yellow 2, orange 1.
        n = int(np.count_nonzero(project.point(pt.id).src[f] != 0))
        assert pane.color_at(f) == C.COLORS[{4: "dark_green", 3: "light_green", 2: "yellow", 1: "orange"}[n]]
        for s in range(project.sensor_count):
            blob = project.point(pt.id).src[f, s] == 1
            assert (pane.color_at(f, s) == C.COLORS["blob"]) == blob
    chart = _switch(win.grid, 1, "Continuity")              # a view slot switched through its context menu
    chart.render()
    for f in range(project.frame_count):
        assert chart.color_at(pt.id, f) == pane.color_at(f)
    # Interpolate Gaps through the menu: the gap turns red (interpolated) in the pane.
    win.action("process.interpolate").trigger()
    qtbot.waitUntil(lambda: project.point(pt.id).status[2] == ST_INTERPOLATED, timeout=20000)
    qtbot.waitUntil(lambda: pane.color_at(2) == C.COLORS["red"], timeout=5000)
