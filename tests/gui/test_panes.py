"""Panes: Labelling, History, Log, Selection, docks; labelling shortcuts (L, K, J, Ctrl+U, Ctrl+H)."""
from __future__ import annotations

import logging

import pytest
from PySide6.QtCore import QModelIndex, Qt

from carapost.core.edits import SetLabels
from carapost.gui.panes.labelling import STATE_COLORS
from guihelpers import click_raw, det_xy, key, point_at

CTRL, SHIFT = Qt.KeyboardModifier.ControlModifier, Qt.KeyboardModifier.ShiftModifier
pytestmark = pytest.mark.gui


def _merge_marker(qtbot, win, p, marker, sensors=(0, 1)):
    frame = win.session.frame
    views = {v.sensor: v for v in win.grid.visible_views()}
    for k, s in enumerate(sensors):
        click_raw(qtbot, views[s], *det_xy(p, s, frame, marker), mods=CTRL if k else Qt.KeyboardModifier.NoModifier)
    key(qtbot, win, Qt.Key.Key_M)
    return point_at(p, frame, sensors[0], marker)


def test_labelling_colours_merge_and_select_next_label(qtbot, window, take):
    p, _ = take
    win = window
    win.session.run(SetLabels(["Nose", "Chin", "Brow"]))
    lab = win.labelling
    assert [lab.list.item(i).text() for i in range(3)] == ["Nose", "Chin", "Brow"]
    assert lab.list.item(0).foreground().color() == STATE_COLORS["unassigned"]
    key(qtbot, win, Qt.Key.Key_K)                      # Select Next Label
    assert win.session.current_label == "Nose" and lab.list.currentItem().text() == "Nose"
    # click two detections and press L: the point gets the label, the next missing label is selected
    views = {v.sensor: v for v in win.grid.visible_views()}
    click_raw(qtbot, views[0], *det_xy(p, 0, 0, 2))
    click_raw(qtbot, views[1], *det_xy(p, 1, 0, 2), mods=CTRL)
    key(qtbot, win, Qt.Key.Key_L)
    pt = point_at(p, 0, 0, 2)
    assert pt.label == "Nose" and win.session.current_label == "Chin"
    assert lab.state_of("Nose") == "assigned"
    assert lab.list.item(0).foreground().color() == STATE_COLORS["assigned"]
    key(qtbot, win, Qt.Key.Key_Right)                 # the point has no 3D on frame 1: yellow
    assert lab.list.item(0).foreground().color() == STATE_COLORS["absent"]
    key(qtbot, win, Qt.Key.Key_J)                      # Select Previous Label: Nose is missing on frame 1
    assert win.session.current_label == "Nose"
    key(qtbot, win, Qt.Key.Key_Left)
    win.session.select(points=[pt.id])
    key(qtbot, win, Qt.Key.Key_U, CTRL)                # Unlabel Selected Points
    assert pt.label == ""


def test_labelling_rename_reorder_add_delete(qtbot, window):
    win, p = window, window.session.project
    win.session.run(SetLabels(["A", "B", "C"]))
    lab = win.labelling
    win.prompts.queue("get_text", "Apex")
    lab.rename_item(lab.list.item(0))                  # what a double-click does
    assert p.labels == ["Apex", "B", "C"]
    assert lab.list.model().moveRow(QModelIndex(), 2, QModelIndex(), 0)    # drag C to the top
    assert p.labels == ["C", "Apex", "B"]
    assert win.session.doc.stack.names()[-1] == "Reorder Labels"
    qtbot.keyClicks(lab.add, "Lip Jaw")
    qtbot.keyClick(lab.add, Qt.Key.Key_Return)
    assert p.labels == ["C", "Apex", "B", "Lip", "Jaw"]
    lab.list.item(1).setSelected(True)
    lab.list.item(2).setSelected(True)
    win.action("edit.delete_selected_labels").trigger()
    assert p.labels == ["C", "Lip", "Jaw"]
    win.action("edit.clear_all_labels").trigger()
    assert p.labels == [] and lab.list.count() == 0


def test_history_pane_memory_and_clear(qtbot, window, take):
    p, _ = take
    _merge_marker(qtbot, window, p, 4)
    hist = window.history
    assert hist.entries() == [("Merge", False)]
    assert "history memory" in hist.memory.text()
    window.action("edit.clear_history").trigger()
    assert hist.entries() == [] and not window.action("edit.undo").isEnabled()


def test_log_pane_colours(qtbot, window):
    log = logging.getLogger("carapost")
    log.info("an info line")
    log.warning("a warning line")
    log.error("an error line")
    html = window.log_pane.text.document().toHtml()
    assert "#ffffff" in html and "#ffd84a" in html and "#ff5a5a" in html
    levels = {m: lvl for lvl, m in window.log_pane.lines}
    assert levels["a warning line"] == logging.WARNING


def test_detach_uses_the_active_view_or_the_selection_pane_channels(qtbot, window, take):
    p, _ = take
    pt = _merge_marker(qtbot, window, p, 5, sensors=(0, 1, 2))
    assert list(pt.src[0, :3]) == [1, 1, 1]
    # the last view clicked (channel 2) is the active one
    key(qtbot, window, Qt.Key.Key_H, CTRL)
    assert list(pt.src[0, :3]) == [1, 1, 0]
    window.selection_pane.boxes[0].click()
    assert p.channel_selection == [0]
    key(qtbot, window, Qt.Key.Key_H, CTRL | SHIFT)     # [Active Range]: the selected channel 0
    assert list(pt.src[0, :3]) == [0, 1, 0]


def test_docks_panels_menu_and_full_screen(qtbot, window):
    docks = window.docks
    assert all(d.isVisible() for d in docks.values())
    key(qtbot, window, Qt.Key.Key_F, CTRL)              # Toggle Dock Widget Visibility
    assert not any(d.isVisible() for d in docks.values())
    key(qtbot, window, Qt.Key.Key_F, CTRL)
    assert all(d.isVisible() for d in docks.values())
    panels = window.actionset.panels_menu
    log_toggle = next(a for a in panels.actions() if a.text() == "Log")
    log_toggle.trigger()
    assert not docks["log"].isVisible()
    # right-click on the menu bar lists the panes, to show a hidden one
    popup = window.createPopupMenu()
    entry = next(a for a in popup.actions() if a.text() == "Log")
    entry.trigger()
    assert docks["log"].isVisible()
    assert window.menuBar().contextMenuPolicy() == Qt.ContextMenuPolicy.CustomContextMenu
    key(qtbot, window, Qt.Key.Key_F)
    assert window.isFullScreen() and window.action("view.full_screen").isChecked()
    key(qtbot, window, Qt.Key.Key_F)
    assert not window.isFullScreen()


def test_select_point_fewest_gaps_information_distance(qtbot, window, take):
    p, _ = take
    a = _merge_marker(qtbot, window, p, 6)
    b = _merge_marker(qtbot, window, p, 7)
    window.prompts.queue("get_text", str(a.id))
    key(qtbot, window, Qt.Key.Key_P, CTRL)
    assert window.session.selection.points == [a.id]
    window.session.select(points=[a.id, b.id])
    window.action("view.distance").trigger()
    assert "Distance between points" in window.log_pane.lines[-1][1]
    window.session.select(points=[a.id])
    window.action("view.point_information").trigger()
    assert any(f"Point {a.id}" in m for _l, m in window.log_pane.lines)
    key(qtbot, window, Qt.Key.Key_A, CTRL)             # no point has gaps in this take
    assert "no point has a gap" in window.log_pane.lines[-1][1]
