"""Update Timeline / 2D View Every Frame: a running track is shown frame by frame, read-only.

Track Forwards [Sequence] (Process menu) and the Target Tracker's > run in the
background; their frames appear in the Selected Point pane, the Continuity chart
and the camera views while the project itself is untouched until the job ends.
The tracker is held at a gate after a few frames so that what is on screen
mid-run can be checked deterministically.
"""
from __future__ import annotations

import threading

import numpy as np
import pytest

from carapost.core import continuity as C
from carapost.core.edits import SetProperties
from carapost.core.points import SRC_NONE, SRC_TARGET, ST_NONE
from carapost.gui import live_preview
from guihelpers import det_xy, make_window

pytestmark = pytest.mark.gui

QUIET = dict(jaw_mm=0.0, blinks=0, occlusion_rate=0.0, hidden_markers=0, slips=0)
START, FRAMES, SHOWN = 2, 14, 4          # track from frame 2 to 13; hold the tracker after 4 frames
TIMELINE, VIEWS = "tracker.update_timeline_every_frame", "tracker.update_2d_view_every_frame"


class Gate:
    """Blocks the worker once ``after`` frames are done, until :meth:`release` (or 20 s)."""

    def __init__(self, after: int):
        self.after, self.calls = after, 0
        self.reached, self.go = threading.Event(), threading.Event()

    def wait(self) -> None:
        self.calls += 1
        if self.calls == self.after + 1:
            self.reached.set()
            self.go.wait(20)

    def release(self) -> None:
        self.go.set()


@pytest.fixture
def take():
    """A quiet 14-frame take initialised (brim solve + Initialize 3D) on frame 2, nothing tracked yet."""
    from carapost.core.tracking.synthetic_take import initialise, make_take

    sc = make_take(35, FRAMES, seed=4, **QUIET)
    initialise(sc, START)
    return sc.project


@pytest.fixture
def gate(monkeypatch):
    """Hold Track Forwards [Sequence] before its frame START + SHOWN + 1."""
    from carapost.core.tracking import engine

    g = Gate(SHOWN)
    real = engine.FrameTracker.step

    def step(self, frame, recs):
        g.wait()
        return real(self, frame, recs)

    monkeypatch.setattr(engine.FrameTracker, "step", step)
    yield g
    g.release()


def _set(win, **props):
    win.session.run(SetProperties({f"tracker.{k}": v for k, v in props.items()}))


def _start_track(qtbot, win, gate):
    """Track Forwards [Sequence] from START through its menu action; returns once the gate holds it."""
    win.navigate.set_frame(START)
    win.action("process.track_fwd_seq").trigger()
    assert win.runner.running
    assert gate.reached.wait(20), "the tracker never reached the gate"


def _pane_colors(win, frames):
    """What the Selected Point pane shows: ``frame -> (bar, channel 0..S-1)`` RGBA."""
    pane, S = win.selected_point, win.session.project.sensor_count
    return {f: tuple(pane.color_at(f, ch) for ch in range(-1, S)) for f in frames}


def _project_colors(p, pid, frames):
    """The colours the project's own data gives the point at ``frames`` (bar, then channels)."""
    q = p.point(pid)
    bar, chans = C.point_rgba(q), C.channel_rgba(q)
    return {f: (tuple(int(v) for v in bar[f]),) + tuple(tuple(int(v) for v in chans[s, f])
                                                        for s in range(p.sensor_count)) for f in frames}


GAP = tuple(C.COLORS["gap"])


def test_track_sequence_is_shown_live_then_the_project_holds_it(qtbot, take, gate):
    p = take
    win = make_window(qtbot, p)
    win.grid.set_slot_kind(3, "continuity")
    chart = win.grid.slot_widget(3)
    live = live_preview.of(win.session)
    d0, n0 = p.digest(), len(win.session.doc.stack)
    pid = next(q.id for q in p.face_points() if q.status[START] != ST_NONE)
    done = range(START + 1, START + SHOWN + 1)
    todo = range(START + SHOWN + 1, FRAMES)
    assert all(p.point(pid).status[f] == ST_NONE for f in list(done) + list(todo))

    _start_track(qtbot, win, gate)               # every point is tracked: none was selected
    win.session.select(points=[pid])             # the pane shows one of them
    qtbot.waitUntil(lambda: len(live.frames) == SHOWN, timeout=5000)
    qtbot.waitUntil(lambda: win.selected_point.color_at(START + SHOWN) != GAP, timeout=5000)
    # the frames tracked so far are coloured, the others not yet, and the project is untouched
    seen = _pane_colors(win, list(done) + list(todo))
    assert all(seen[f][0] in (tuple(C.COLORS["dark_green"]), tuple(C.COLORS["light_green"])) for f in done)
    assert all(tuple(C.COLORS["blob"]) in seen[f][1:] for f in done)
    assert all(seen[f] == (GAP,) * len(seen[f]) for f in todo)
    rows = chart.rows
    shown = sum(chart.color_at(q, f) != GAP for q, ch in rows if ch < 0 for f in done)
    assert shown >= 0.6 * len([r for r in rows if r[1] < 0]) * SHOWN
    assert all(chart.color_at(q, f) == GAP for q, ch in rows if ch < 0 for f in todo)
    assert chart.color_at(pid, START + 1) == seen[START + 1][0]
    assert p.digest() == d0 and len(win.session.doc.stack) == n0
    assert win.session.frame == START                   # Update 2D View Every Frame is off by default

    gate.release()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=30000)
    assert not live.active and win.session.doc.stack.names()[-1] == "Track Forwards [Sequence]"
    # the pane now reads the project, and shows what it showed live for the frames done then
    after = _pane_colors(win, range(START, FRAMES))
    assert after == _project_colors(p, pid, range(START, FRAMES))
    assert all(after[f] == seen[f] for f in done)
    assert all(after[f][0] != GAP for f in todo)


def test_cancel_drops_the_overlay(qtbot, take, gate):
    p = take
    win = make_window(qtbot, p)
    live = live_preview.of(win.session)
    d0, n0 = p.digest(), len(win.session.doc.stack)
    pid = next(q.id for q in p.face_points() if q.status[START] != ST_NONE)
    win.session.select(points=[pid])
    _start_track(qtbot, win, gate)
    qtbot.waitUntil(lambda: win.selected_point.color_at(START + SHOWN) != GAP, timeout=5000)
    assert p.digest() == d0

    win.runner.cancel()
    gate.release()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=30000)
    assert not live.active and not live.frames
    # Track [Sequence] keeps the frames done when cancelled (one undo step, as before); the
    # overlay never wrote to the project: undoing that step gives back the project exactly
    last = START + SHOWN + 1
    assert p.point(pid).status[last] != ST_NONE and p.point(pid).status[last + 1] == ST_NONE
    assert _pane_colors(win, [last + 1])[last + 1] == (GAP,) * (p.sensor_count + 1)
    assert len(win.session.doc.stack) == n0 + 1
    win.session.doc.undo()
    assert p.digest() == d0
    assert all(c == GAP for f in range(START + 1, FRAMES) for c in _pane_colors(win, [f])[f])


def test_settings_off_nothing_is_shown_live(qtbot, take, gate):
    p = take
    win = make_window(qtbot, p)
    _set(win, update_timeline_every_frame=False, update_2d_view_every_frame=False)
    pid = next(q.id for q in p.face_points() if q.status[START] != ST_NONE)
    win.session.select(points=[pid])
    _start_track(qtbot, win, gate)
    assert not win.runner._job[1].publishing          # nobody listens: the engine builds no payload
    qtbot.wait(200)                                    # four flush periods
    assert all(c == GAP for f in range(START + 1, FRAMES) for c in _pane_colors(win, [f])[f])
    assert win.session.frame == START
    gate.release()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=30000)
    assert _pane_colors(win, [START + 1]) == _project_colors(p, pid, [START + 1])


def test_update_2d_view_moves_the_frame_and_draws_the_tracked_points(qtbot, take, gate):
    p = take
    win = make_window(qtbot, p)
    _set(win, update_timeline_every_frame=False, update_2d_view_every_frame=True)
    live = live_preview.of(win.session)
    d0 = p.digest()
    pid = next(q.id for q in p.face_points() if q.status[START] != ST_NONE)
    faces = list(p.face_points())
    _start_track(qtbot, win, gate)
    win.session.select(points=[pid])
    # the current frame follows the track; the views draw the tracked points there
    qtbot.waitUntil(lambda: win.session.frame == START + SHOWN, timeout=5000)
    f = START + SHOWN
    assert all(np.all(q.src[f] == SRC_NONE) for q in faces) and p.digest() == d0
    fd = win.session.frame_data()
    rows = [fd.row_of(q.id) for q in faces]
    assert np.count_nonzero(fd.has3d[rows]) >= 0.6 * len(faces)
    view = win.grid.views[0]
    s = view.sensor
    on = [r for r in rows if fd.src[r, s] != SRC_NONE]
    assert len(on) >= 0.6 * len(faces) and view.items["rings"].count() > 0
    # projections use the cameras the track solved: they land on the tracked 2D samples
    err = np.linalg.norm(fd.proj[on, s] - fd.uv[on, s], axis=1)
    assert np.median(err) < 1.0
    # the timeline setting is off: the pane shows nothing live
    assert win.selected_point.color_at(START + 1) == GAP
    gate.release()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=30000)
    assert not live.active
    assert win.session.frame == FRAMES - 1                 # the last frame tracked
    fd = win.session.frame_data()
    q = p.point(pid)
    assert np.array_equal(fd.src[fd.row_of(pid)], q.src[FRAMES - 1])


def test_target_tracker_live_then_cancel_leaves_the_project_untouched(qtbot, monkeypatch):
    from carapost.core.editing import add_target_track, edit_target_track
    from carapost.gui.demo_take import make_demo_take

    p, _truth = make_demo_take(frames=12, markers=12, strays=2)
    win = make_window(qtbot, p)
    s = win.session
    s.run(add_target_track(p, 0, 0, det_xy(p, 0, 0, 1)))
    (pid,) = s.selection.points
    s.run(edit_target_track(p, pid, 1, 0, det_xy(p, 1, 0, 1)))
    s.run(SetProperties({"tracker.break_threshold": 0.6, VIEWS: True}))
    g = Gate(0)                       # held on its first call: the image of frame SHOWN + 1
    fast = win.target._images

    def gated_images():
        img = fast()

        def image(sensor, frame):
            if frame == SHOWN + 1 and sensor == 0:
                g.wait()
            return img(sensor, frame)
        return image

    monkeypatch.setattr(win.target, "_images", gated_images)
    d0 = p.digest()
    win.action("tracker.forward_to_end").trigger()
    assert g.reached.wait(20)
    live = live_preview.of(s)
    qtbot.waitUntil(lambda: s.frame == SHOWN, timeout=5000)         # Update 2D View Every Frame
    for f in range(1, SHOWN + 1):
        bar, ch0, ch1 = (win.selected_point.color_at(f, c) for c in (-1, 0, 1))
        assert ch0[3] == ch1[3] == 255 and ch0 not in (tuple(C.COLORS["blob"]), tuple(C.COLORS["key"]))
        assert bar == tuple(C.COLORS["yellow"])                    # 3D from the two target-tracked channels
    assert win.selected_point.color_at(SHOWN + 1, 0) == GAP
    fd = s.frame_data()
    assert list(fd.src[fd.row_of(pid), :2]) == [SRC_TARGET, SRC_TARGET]
    assert p.digest() == d0

    win.runner.cancel()
    g.release()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    assert not live.active and p.digest() == d0            # the Target Tracker's Cancel discards the run
    assert win.selected_point.color_at(1, 0) == GAP
    fd = s.frame_data()
    assert np.all(fd.src[fd.row_of(pid)] == SRC_NONE)
