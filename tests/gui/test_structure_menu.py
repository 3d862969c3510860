"""Labels and structure through the window (issue 8, item 4): the items the other GUI tests do not drive.

Go To Next Gap, Select Point With Fewest Gaps (Ctrl+A), Navigate Missing Labels
Only on Select Next Label (K), Rename Point (Ctrl+R) and Create Stick Mesh.
"""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt

from carapost.core.edits import SetLabels
from carapost.core.points import SRC_NONE, ST_NONE
from guihelpers import click_raw, det_xy, key, point_at

CTRL = Qt.KeyboardModifier.ControlModifier
pytestmark = pytest.mark.gui


def _merge_marker(qtbot, win, p, marker, frame=0):
    views = {v.sensor: v for v in win.grid.visible_views()}
    for k, s in enumerate((0, 1)):
        click_raw(qtbot, views[s], *det_xy(p, s, frame, marker), mods=CTRL if k else Qt.KeyboardModifier.NoModifier)
    key(qtbot, win, Qt.Key.Key_M)
    return point_at(p, frame, 0, marker)


def test_next_gap_fewest_gaps_and_missing_labels(qtbot, window, take):
    p, _ = take
    win = window
    a = _merge_marker(qtbot, win, p, 3)
    b = _merge_marker(qtbot, win, p, 4)
    # Give both points data on frames 0-5, then cut a gap into a (frames 2-3) and two into b.
    for q in (a, b):
        q.status[:6] = q.status[0]
        q.pos[:6] = q.pos[0]
    a.status[2:4] = ST_NONE
    b.status[[1, 3]] = ST_NONE
    win.session.select(points=[a.id])
    win.action("view.next_gap").trigger()
    assert win.session.frame == 1                    # the frame before a's first gap
    win.navigate.set_frame(0)
    key(qtbot, win, Qt.Key.Key_A, CTRL)              # Select Point With Fewest Gaps
    assert win.session.selection.points == [a.id]
    # Navigate Missing Labels Only: K skips a label whose point is present on this frame.
    win.session.run(SetLabels(["Nose", "Chin", "Brow"]))
    win.session.select(points=[a.id])
    win.prompts.queue("get_text", "Nose")
    key(qtbot, win, Qt.Key.Key_R, CTRL)              # Rename Point
    assert a.label == "Nose" and win.session.doc.stack.names()[-1].startswith("Rename")
    win.session.current_label = None
    p.properties.set("labelling.navigate_missing_labels_only", True)
    key(qtbot, win, Qt.Key.Key_K)
    assert win.session.current_label == "Chin"       # Nose is assigned on frame 0
    win.session.current_label = None
    p.properties.set("labelling.navigate_missing_labels_only", False)
    key(qtbot, win, Qt.Key.Key_K)
    assert win.session.current_label == "Nose"


def test_create_stick_mesh_through_the_menu(qtbot, window, take):
    p, _ = take
    win = window
    pts = [_merge_marker(qtbot, win, p, m) for m in range(6)]
    assert all(q.status[0] != ST_NONE for q in pts)
    win.action("edit.create_stick_mesh").trigger()
    assert win.session.doc.stack.names()[-1] == "Create Stick Mesh"
    ends = {frozenset((s.a, s.b)) for s in p.sticks}
    assert len(ends) == len(p.sticks) >= 2 * len(pts) - 3      # a triangulation of 6 points has >= 9 edges
    assert all(e <= {q.id for q in pts} for e in ends)
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.sticks == []
    assert np.all([q.src[0, 0] != SRC_NONE for q in pts])
