"""The guide's editing workflow driven through real shortcuts and mouse clicks on the views."""
from __future__ import annotations

import pytest
from PySide6.QtCore import QTimer, Qt
from PySide6.QtWidgets import QApplication, QDoubleSpinBox, QInputDialog

from guihelpers import assert_close, click_raw, det_xy, key, point_at

CTRL = Qt.KeyboardModifier.ControlModifier
SHIFT = Qt.KeyboardModifier.ShiftModifier
pytestmark = pytest.mark.gui


def test_click_merge_rename_delete_undo_redo(qtbot, window, take):
    p, truth = take
    win, ses = window, window.session
    v0, v1 = win.grid.views[0], win.grid.views[1]
    click_raw(qtbot, v0, *det_xy(p, 0, 0, 3))
    assert ses.selection.detections == [(0, 0, 3)]
    click_raw(qtbot, v1, *det_xy(p, 1, 0, 3), mods=CTRL)
    assert ses.selection.detections == [(0, 0, 3), (1, 0, 3)]

    key(qtbot, win, Qt.Key.Key_M)
    pt = point_at(p, 0, 0, 3)
    assert pt is not None and pt.det[0, 1] == 3
    assert_close(pt.pos[0], truth[0, 3])                    # triangulated from the two clicks
    assert ses.selection.points == [pt.id] and ses.selection.detections == []

    win.prompts.queue("get_text", "Nose")
    key(qtbot, win, Qt.Key.Key_R, CTRL)
    assert pt.label == "Nose" and "Nose" in p.labels

    key(qtbot, win, Qt.Key.Key_D, CTRL)
    assert pt.id not in p.points

    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.point(pt.id).label == "Nose"
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.point(pt.id).label == ""
    key(qtbot, win, Qt.Key.Key_Y, CTRL)
    assert p.point(pt.id).label == "Nose"
    assert win.history.entries() == [("Merge", False), ("Rename Point", False), ("Delete Selected", True)]
    # clicking the first History entry goes back to the state after the merge
    hist = win.history.list
    qtbot.mouseClick(hist.viewport(), Qt.MouseButton.LeftButton, pos=hist.visualItemRect(hist.item(1)).center())
    assert p.point(pt.id).label == "" and [u for _n, u in win.history.entries()] == [False, True, True]


def test_merge_two_detections_in_one_sensor_is_refused(qtbot, window, take):
    p, _ = take
    v0 = window.grid.views[0]
    click_raw(qtbot, v0, *det_xy(p, 0, 0, 1))
    click_raw(qtbot, v0, *det_xy(p, 0, 0, 2), mods=CTRL)
    n = len(p.points)
    key(qtbot, window, Qt.Key.Key_M)
    assert len(p.points) == n
    assert "two selected detections are in sensor 0" in window.prompts.errors[-1]
    assert any("sensor 0" in m and lvl >= 40 for lvl, m in window.log_pane.lines)   # red in the Log


def test_frame_keys_ranges_and_go_to(qtbot, window):
    win, ses, p = window, window.session, window.session.project
    key(qtbot, win, Qt.Key.Key_Right)
    key(qtbot, win, Qt.Key.Key_Right)
    assert ses.frame == 2
    key(qtbot, win, Qt.Key.Key_Left)
    assert ses.frame == 1
    key(qtbot, win, Qt.Key.Key_End)
    assert ses.frame == p.frame_count - 1
    key(qtbot, win, Qt.Key.Key_Home)
    assert ses.frame == 0

    win.prompts.queue("get_int", 3)
    key(qtbot, win, Qt.Key.Key_G, CTRL)
    assert ses.frame == 3
    key(qtbot, win, Qt.Key.Key_1, CTRL)
    assert p.active_range == (3, p.frame_count - 1)
    win.prompts.queue("get_int", 8)
    key(qtbot, win, Qt.Key.Key_G, CTRL)
    key(qtbot, win, Qt.Key.Key_2, CTRL)
    assert p.active_range == (3, 8)
    assert win.time.ranges.text().startswith("Active 3-8")
    key(qtbot, win, Qt.Key.Key_3, CTRL)
    assert p.active_range == (0, p.frame_count - 1)
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.active_range == (3, 8)


def test_go_to_frame_with_the_real_dialog(qtbot, take):
    from guihelpers import make_window
    from carapost.gui.prompts import Prompts

    win = make_window(qtbot, take[0])
    win.prompts = Prompts(win)

    def answer():
        dlg = QApplication.activeModalWidget()
        assert isinstance(dlg, QInputDialog)
        dlg.setIntValue(7)
        dlg.accept()

    QTimer.singleShot(50, answer)
    key(qtbot, win, Qt.Key.Key_G, CTRL)
    assert win.session.frame == 7
    assert win.time.spin.value() == 7


def test_play_space_plays_and_stops(qtbot, window):
    win = window
    key(qtbot, win, Qt.Key.Key_Space)
    assert win.navigate.playing and win.time.buttons["view.play"].text() == "Stop"
    qtbot.waitUntil(lambda: win.session.frame >= 3, timeout=3000)
    key(qtbot, win, Qt.Key.Key_Space)
    assert not win.navigate.playing and win.time.buttons["view.play"].text() == "Play"


def test_properties_pane_edits_are_commands(qtbot, window):
    win, p = window, window.session.project
    spin = win.properties.editor("tracking.patch_match_threshold")
    assert isinstance(spin, QDoubleSpinBox) and spin.value() == pytest.approx(0.8)
    win.properties.tree.scrollToItem(win.properties.groups["tracking"])
    spin.setFocus()
    spin.selectAll()
    qtbot.keyClicks(spin, "0.7")
    qtbot.keyClick(spin, Qt.Key.Key_Return)
    assert p.properties["tracking.patch_match_threshold"] == pytest.approx(0.7)
    assert window.session.doc.stack.names()[-1] == "Set Patch Match Threshold"
    box = win.properties.editor("display.point_labels_all")
    box.click()
    assert p.properties["display.point_labels_all"] is True
    win.action("edit.undo").trigger()
    win.action("edit.undo").trigger()
    assert spin.value() == pytest.approx(0.8) and not box.isChecked()
    # a tracker setting from the Tracker pane
    win.tracker.editors["tracker.stop_on_next_keyframe"].click()
    assert p.properties["tracker.stop_on_next_keyframe"] is False
    # Restore Properties To Defaults is one command
    win.action("edit.restore_defaults").trigger()
    assert p.properties["tracker.stop_on_next_keyframe"] is True
