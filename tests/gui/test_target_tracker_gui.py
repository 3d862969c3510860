"""The Target Tracker through the window: Edit menu shortcuts, the Tracker pane's buttons, nudges, pause."""
from __future__ import annotations

import time

import numpy as np
import pytest
from PySide6.QtCore import Qt

from carapost.core.points import SRC_KEYFRAME, SRC_NONE, SRC_TARGET
from carapost.gui.target_actions import screen_to_raw
from guihelpers import click_raw, det_xy, drag_raw, key

CTRL, SHIFT = Qt.KeyboardModifier.ControlModifier, Qt.KeyboardModifier.ShiftModifier
pytestmark = pytest.mark.gui
MARKER = 1          # detection 1 of every frame is marker 1's projection


def _button(win, aid):
    return win.tracker.buttons[aid]


def _new_target_track(qtbot, win, p):
    """Shift+A, click marker 1 in view 0; Shift+E, click it in view 1; Shift+S."""
    v0, v1 = win.grid.views[0], win.grid.views[1]
    key(qtbot, win, Qt.Key.Key_A, SHIFT)
    assert win.session.click_mode == "add"
    click_raw(qtbot, v0, *det_xy(p, 0, 0, MARKER))
    (pid,) = win.session.selection.points
    key(qtbot, win, Qt.Key.Key_E, SHIFT)
    click_raw(qtbot, v1, *det_xy(p, 1, 0, MARKER))
    key(qtbot, win, Qt.Key.Key_S, SHIFT)
    assert win.session.click_mode == ""
    assert sorted(p.point(pid).keyframes) == [(0, 0), (0, 1)]
    _lower_break_threshold(win)
    return pid


def _lower_break_threshold(win):
    """The demo take's discs change size from frame to frame: a pattern matches them at ~0.7-0.9 only."""
    win.tracker.editors["tracker.break_threshold"].setValue(0.6)
    assert win.session.project.properties["tracker.break_threshold"] == 0.6


def _err(p, pid, f, s):
    """How far the track on ``f`` is from following the marker (the keyframe click on frame 0 is never exact)."""
    q = p.point(pid)
    off0 = q.uv[0, s] - det_xy(p, s, 0, MARKER)
    return float(np.linalg.norm(q.uv[f, s] - det_xy(p, s, f, MARKER) - off0))


def test_track_buttons_keyframes_and_undo(qtbot, window, take):
    p, _ = take
    win = window
    pid = _new_target_track(qtbot, win, p)
    names = win.session.doc.stack.names
    assert all(_button(win, aid).isEnabled() for aid in win.tracker.buttons)
    # >| tracks one frame in both keyed channels and steps the current frame with it
    qtbot.mouseClick(_button(win, "tracker.forward_one"), Qt.MouseButton.LeftButton)
    assert win.session.frame == 1 and names()[-1] == "Track Forward One Frame"
    assert list(p.point(pid).src[1, :2]) == [SRC_TARGET, SRC_TARGET]
    assert _err(p, pid, 1, 0) < 0.5 and _err(p, pid, 1, 1) < 0.5
    # > runs in the background to the end of the active range, as one undo step
    n = len(names())
    qtbot.mouseClick(_button(win, "tracker.forward_to_end"), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    assert len(names()) == n + 1 and names()[-1] == "Track Forward To End"
    last = p.frame_count - 1
    assert win.session.frame == last
    assert np.all(p.point(pid).src[1:, :2] == SRC_TARGET)
    assert max(_err(p, pid, f, s) for f in range(1, last + 1) for s in (0, 1)) < 0.6
    assert _button(win, "tracker.forward_to_end").text() == ">"
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert np.all(p.point(pid).src[2:, :2] == SRC_NONE)
    # a keyframe on frame 1, then > from there
    win.navigate.set_frame(1)
    qtbot.mouseClick(_button(win, "tracker.add_keyframe"), Qt.MouseButton.LeftButton)
    assert names()[-1] == "Add Keyframe To Current Frame"
    assert list(p.point(pid).src[1, :2]) == [SRC_KEYFRAME, SRC_KEYFRAME] and (1, 1) in p.point(pid).keyframes
    qtbot.mouseClick(_button(win, "tracker.forward_to_end"), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    # |< over tracked frames: refused until Overwrite Existing Tracks is ticked in the pane
    win.navigate.set_frame(last)
    qtbot.mouseClick(_button(win, "tracker.back_one"), Qt.MouseButton.LeftButton)
    assert win.session.frame == last and "reached existing 2D data" in win.prompts.errors[-1]
    win.tracker.editors["tracker.overwrite_existing_tracks"].setChecked(True)
    qtbot.mouseClick(_button(win, "tracker.back_one"), Qt.MouseButton.LeftButton)
    assert win.session.frame == last - 1 and names()[-1] == "Track Back One Frame"
    # Clear Tracked Points: the selected point's target data and keyframes in the active range
    qtbot.mouseClick(_button(win, "tracker.clear"), Qt.MouseButton.LeftButton)
    assert names()[-1] == "Clear Tracked Points"
    assert np.all(p.point(pid).src == SRC_NONE) and not p.point(pid).keyframes


def test_nudge_shortcuts_move_the_keyframe_in_the_active_view(qtbot, window, take):
    p, _ = take
    win = window
    pid = _new_target_track(qtbot, win, p)
    uv = p.point(pid).uv[0].copy()
    assert win.session.active_sensor == 1                 # the view clicked last
    key(qtbot, win, Qt.Key.Key_Right, CTRL | SHIFT)
    key(qtbot, win, Qt.Key.Key_Up, CTRL | SHIFT)
    q = p.point(pid)
    np.testing.assert_allclose(q.uv[0, 1], uv[1] + (1, -1), atol=1e-4)
    np.testing.assert_allclose(q.uv[0, 0], uv[0])
    assert win.session.doc.stack.names()[-2:] == ["Nudge Keyframe", "Nudge Keyframe"]
    assert win.session.frame == 0                         # the arrows did not step frames
    # nudges follow a rotated view: on screen "right" in a view turned a quarter clockwise is raw "up"
    assert screen_to_raw(1, 0, 1) == (0.0, -1.0) and screen_to_raw(0, 1, 2) == (0.0, -1.0)
    p.sensors[1].rotation = 1
    key(qtbot, win, Qt.Key.Key_Right, CTRL | SHIFT)
    np.testing.assert_allclose(q.uv[0, 1], uv[1] + (1, -2), atol=1e-4)
    # the Tracker pane's keyframe box edits that keyframe's pattern and region
    box = win.tracker.box_editors
    assert [e.value() for e in box] == [8, 8, 16, 16]
    box[2].setValue(20)
    assert q.keyframes[(0, 1)] == (8.0, 8.0, 20.0, 16.0)
    assert win.session.doc.stack.names()[-1] == "Edit Keyframe Box"


def test_gaps_to_keys_from_the_edit_menu(qtbot, window, take):
    p, _ = take
    win = window
    pid = _new_target_track(qtbot, win, p)
    assert win.action("edit.gaps_to_keys").isEnabled()
    win.action("edit.gaps_to_keys").trigger()               # no gaps yet: an error, nothing changes
    assert win.prompts.errors and "no gaps" in win.prompts.errors[-1]
    # track to the end, then clear frames 6-8: a gap between tracked frames 5 and 9
    qtbot.mouseClick(_button(win, "tracker.forward_to_end"), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    for f in (6, 7, 8):
        win.navigate.set_frame(f)
        win.action("edit.clear_selected_frame").trigger()
    q = p.point(pid)
    assert np.all(q.src[6:9] == SRC_NONE) and np.all(q.src[[5, 9], :2] == SRC_TARGET)
    win.action("edit.gaps_to_keys").trigger()
    assert win.session.doc.stack.names()[-1] == "Gaps To Keys"
    assert sorted(q.keyframes) == [(0, 0), (0, 1), (5, 0), (5, 1), (9, 0), (9, 1)]
    assert np.all(q.src[[5, 9], :2] == SRC_KEYFRAME)
    # the keys bracket the gap: Track back from 9 fills it and stops before the keyframe on 5
    win.navigate.set_frame(9)
    qtbot.mouseClick(_button(win, "tracker.back_to_start"), Qt.MouseButton.LeftButton)
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    assert np.all(q.src[6:9, :2] == SRC_TARGET) and win.session.frame == 6
    assert max(_err(p, pid, f, s) for f in range(6, 9) for s in (0, 1)) < 0.6


def test_the_running_button_pauses_and_keeps_the_frames_done(qtbot, window, take, monkeypatch):
    p, _ = take
    win = window
    pid = _new_target_track(qtbot, win, p)
    fast = win.target._images

    def slow_images():
        img = fast()
        return lambda s, f: (time.sleep(0.05), img(s, f))[1]
    monkeypatch.setattr(win.target, "_images", slow_images)
    b = _button(win, "tracker.forward_to_end")
    qtbot.mouseClick(b, Qt.MouseButton.LeftButton)
    assert b.text() == "||" and b.isEnabled() and not _button(win, "tracker.add_keyframe").isEnabled()
    qtbot.waitUntil(lambda: np.any(p.point(pid).src[:, 0] == SRC_TARGET) or win.runner.running, timeout=2000)
    qtbot.wait(150)
    qtbot.mouseClick(b, Qt.MouseButton.LeftButton)          # Pause
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    assert b.text() == ">"
    tracked = np.flatnonzero(p.point(pid).src[:, 0] == SRC_TARGET)
    assert 0 < len(tracked) < p.frame_count - 1
    assert tracked.tolist() == list(range(1, len(tracked) + 1))
    assert win.session.doc.stack.names()[-1] == "Track Forward To End"
    # the progress panel's Cancel instead discards the run
    before = p.digest()
    win.navigate.set_frame(int(tracked[-1]))
    qtbot.mouseClick(b, Qt.MouseButton.LeftButton)
    qtbot.wait(100)
    win.runner.cancel()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    assert p.digest() == before and b.text() == ">"


def test_dragging_the_keyframe_handles_resizes_pattern_and_region(qtbot, window, take):
    """The guide's white handles: a pattern corner sets both pattern half sizes, a cross's arm end one region
    half size; the region keeps the pattern inside it; each drag is one undoable Edit Keyframe Box."""
    from carapost.gui import keyframe_handles as kh

    p, _ = take
    win = window
    pid = _new_target_track(qtbot, win, p)
    v1 = win.grid.views[1]
    q = p.point(pid)
    x, y = (float(v) for v in q.uv[0, 1])
    v1.frame_on([(x, y)], margin=30.0)           # a few screen pixels a raw pixel: handles well apart
    # One move a drag: pyqtgraph drops moves that follow each other within milliseconds, and takes a
    # press as a drag only once the mouse is 5 screen pixels away from it.
    names = win.session.doc.stack.names
    assert q.keyframes[(0, 1)] == (8.0, 8.0, 16.0, 16.0)
    assert v1.key_handle_at(x + 8, y + 8) == kh.PATTERN and v1.key_handle_at(x + 16, y) == kh.REGION_W
    assert v1.key_handle_at(x + 3, y + 3) is None
    # the pattern's corner: both half sizes, whole pixels
    drag_raw(qtbot, v1, (x + 8, y + 8), (x + 11.2, y + 5.8), steps=1)
    assert q.keyframes[(0, 1)] == (11.0, 6.0, 16.0, 16.0)
    assert names()[-1] == "Edit Keyframe Box"
    assert q.keyframes[(0, 0)] == (8.0, 8.0, 16.0, 16.0)        # the other view's keyframe is its own
    assert [e.value() for e in win.tracker.box_editors] == [11, 6, 16, 16]
    # the cross's arm ends: one region half size each (never inside the pattern)
    drag_raw(qtbot, v1, (x - 16, y), (x - 24.9, y + 2), steps=1)
    drag_raw(qtbot, v1, (x, y + 16), (x + 1, y + 2), steps=1)
    assert q.keyframes[(0, 1)] == (11.0, 6.0, 25.0, 6.0)
    # a pattern dragged past the region takes the region along
    drag_raw(qtbot, v1, (x + 11, y - 6), (x + 28, y - 9), steps=1)
    assert q.keyframes[(0, 1)] == (28.0, 9.0, 28.0, 9.0)
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert q.keyframes[(0, 1)] == (11.0, 6.0, 25.0, 6.0)
    key(qtbot, win, Qt.Key.Key_Y, CTRL)
    assert q.keyframes[(0, 1)] == (28.0, 9.0, 28.0, 9.0)
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    # a drag away from the handles selects as before, and leaves the box alone
    drag_raw(qtbot, v1, (x - 4, y - 3), (x + 4, y + 3), steps=1)
    assert q.keyframes[(0, 1)] == (11.0, 6.0, 25.0, 6.0)
    assert win.session.selection.points == [pid]
    # no selected point: no handles
    win.session.select(points=())
    assert v1.key_handle_at(x + 11, y + 6) is None
