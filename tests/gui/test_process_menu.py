"""Process menu (and its View/Edit companions) through the window: calibration, Initialize 3D, bundle,
tracking, gap filling, point read-outs.  Each item is triggered through its QAction or shortcut, runs in the
background, changes the project as expected and undoes exactly with Ctrl+Z."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt

from carapost.core.points import BRIM, ST_INTERPOLATED, ST_NONE
from guihelpers import key, make_window

CTRL = Qt.KeyboardModifier.ControlModifier
pytestmark = pytest.mark.gui

QUIET = dict(jaw_mm=0.0, blinks=0, occlusion_rate=0.0, hidden_markers=0, slips=0)


def _wait(qtbot, win, timeout=30000):
    qtbot.waitUntil(lambda: not win.runner.running, timeout=timeout)


def _run(qtbot, win, action_id=None, shortcut=None):
    """Trigger an item (QAction or shortcut), wait for its background job; returns the digest before."""
    d0 = win.session.project.digest()
    n0 = win.session.doc.stack.index
    if shortcut is not None:
        key(qtbot, win, *shortcut)
    else:
        win.action(action_id).trigger()
    _wait(qtbot, win)
    assert not win.prompts.errors, win.prompts.errors
    assert win.session.doc.stack.index == n0 + 1 == len(win.session.doc.stack)
    return d0


def _undo_redo(qtbot, win, d0):
    """Ctrl+Z restores the project exactly; Ctrl+Y brings the result back."""
    p = win.session.project
    d1 = p.digest()
    assert d1 != d0
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.digest() == d0
    key(qtbot, win, Qt.Key.Key_Y, CTRL)
    assert p.digest() == d1


def _log(win) -> list[str]:
    return [m for _lvl, m in win.log_pane.lines]


# ------------------------------------------------------------------------------------------ calibration
@pytest.fixture
def scene():
    from carapost.core.calib.seeds import apply_seeds
    from carapost.core.calib.synthetic import make_scene

    sc = make_scene(markers=35, frames=3, seed=0)
    apply_seeds(sc.project, sc.seeds(0), parts=("brim",)).do(sc.project)    # the user's brim clicks
    return sc


def test_solve_brim_initialize_3d_bundle_and_point_readouts(qtbot, scene):
    from carapost.core.calib.seeds import apply_seeds

    p = scene.project
    win = make_window(qtbot, p)
    stack = win.session.doc.stack
    brim0 = len([q for q in p.points.values() if q.kind == BRIM])
    xcp0 = [c.position.copy() for c in p.rig.cameras]

    # Process > Solve Calibration Brim [Manual] (current frame 0)
    d0 = _run(qtbot, win, "process.solve_brim")
    assert stack.names()[-1] == "Solve Calibration Brim [Manual]"
    assert len([q for q in p.points.values() if q.kind == BRIM]) > brim0 + 5
    assert p.rig.solved[:, 0].all()
    truth = [c.position for c in scene.cameras[0]]
    assert max(np.linalg.norm(c.position - t) for c, t in zip(p.rig.cameras, truth)) < \
        min(np.linalg.norm(c - t) for c, t in zip(xcp0, truth))
    assert any(m.startswith("Solve Calibration Brim [Manual]: frame 0") for m in _log(win))
    _undo_redo(qtbot, win, d0)

    # Face seeds (Edit > Merge in the GUI), then Bundle Current Frame and Initialize 3D
    win.session.run(apply_seeds(p, scene.seeds(0), parts=("face",)))
    faces = len(list(p.face_points()))
    d0 = _run(qtbot, win, "process.bundle_frame")
    assert stack.names()[-1] == "Bundle Current Frame [Unconstrained]"
    assert any("Bundle Current Frame [Unconstrained]: frame 0" in m for m in _log(win))
    _undo_redo(qtbot, win, d0)

    d0 = _run(qtbot, win, "process.initialize_3d")
    assert stack.names()[-1] == "Initialize 3D"
    assert len(list(p.face_points())) > faces + 15
    assert all(q.status[0] != ST_NONE for q in list(p.face_points()))
    _undo_redo(qtbot, win, d0)

    # Bundle Sequence over the active range (frames 0-2; only frame 0 has points)
    d0 = _run(qtbot, win, "process.bundle_sequence")
    assert stack.names()[-1] == "Bundle Sequence [Unconstrained]"
    assert any("Bundle Sequence [Unconstrained]: 1 frames" in m for m in _log(win))
    _undo_redo(qtbot, win, d0)

    # A CaraError is reported (log + message box) and changes nothing
    win.navigate.set_frame(1)
    d0, n0 = p.digest(), len(stack)
    win.action("process.initialize_3d").trigger()
    _wait(qtbot, win)
    assert p.digest() == d0 and len(stack) == n0
    assert win.prompts.errors and "Initialize 3D" in win.prompts.errors[-1] and "seed points" in win.prompts.errors[-1]
    assert win.log_pane.lines[-1][0] >= 40              # logged as an error
    win.prompts.errors.clear()

    # View > Get Point Information / Distance Between Two Points: to the Log, the project unchanged
    win.navigate.set_frame(0)
    a, b = (q.id for q in list(p.face_points())[:2])
    win.session.select(points=[a])
    win.action("view.point_information").trigger()
    log = _log(win)
    i = max(k for k, m in enumerate(log) if m.startswith(f"Point {a} "))
    assert log[i + 1].startswith("  3D: (") and any("distance to the centroid of all cameras" in m for m in log[i:])
    win.session.select(points=[a, b])
    win.action("view.distance").trigger()
    want = np.linalg.norm(p.point(a).pos[0].astype(float) - p.point(b).pos[0].astype(float))
    assert _log(win)[-1].startswith(f"Distance between points {a} and {b}")
    assert f"{want:.3f} mm" in _log(win)[-1]
    win.navigate.set_frame(1)                            # no 3D data there: an error, not a number
    win.action("view.distance").trigger()
    assert "no 3D position on frame 1" in win.prompts.errors[-1]
    assert p.digest() == d0


# ------------------------------------------------------------------------------------------ tracking
@pytest.fixture
def moving():
    """A quiet 12-frame take initialised (brim solve + Initialize 3D) on its middle frame 5."""
    from carapost.core.tracking.synthetic_take import initialise, make_take

    sc = make_take(35, 12, seed=4, **QUIET)
    initialise(sc, 5)
    return sc


def test_tracking_single_frame_sequences_cancel_and_gaps(qtbot, moving, monkeypatch):
    p = moving.project
    win = make_window(qtbot, p)
    stack = win.session.doc.stack
    faces = list(p.face_points())
    tracked = lambda f: sum(q.status[f] != ST_NONE for q in faces)       # noqa: E731
    win.navigate.set_frame(5)

    # Ctrl+W: Track Forwards [Single Frame], then the current frame is the next one
    d0 = _run(qtbot, win, shortcut=(Qt.Key.Key_W, CTRL))
    assert stack.names()[-1] == "Track Forwards [Single Frame]" and win.session.frame == 6
    assert tracked(6) >= 0.6 * len(faces) and tracked(7) == 0
    _undo_redo(qtbot, win, d0)
    key(qtbot, win, Qt.Key.Key_Z, CTRL)

    # Track Backwards [Single Frame] from frame 5
    win.navigate.set_frame(5)
    d0 = _run(qtbot, win, "process.track_back_frame")
    assert win.session.frame == 4 and tracked(4) >= 0.6 * len(faces) and tracked(3) == 0
    _undo_redo(qtbot, win, d0)
    key(qtbot, win, Qt.Key.Key_Z, CTRL)

    # Track Forwards [Sequence], the selected points only, to the end of the active range
    win.navigate.set_frame(5)
    some = [q.id for q in faces[:10]]
    win.session.select(points=some)
    d0 = _run(qtbot, win, "process.track_fwd_seq")
    assert stack.names()[-1] == "Track Forwards [Sequence]" and win.session.frame == 5
    assert all(p.point(i).status[11] != ST_NONE for i in some)
    assert all(q.status[6] == ST_NONE for q in faces if q.id not in some)
    _undo_redo(qtbot, win, d0)
    key(qtbot, win, Qt.Key.Key_Z, CTRL)

    # Cancel keeps the frames done as one step; Ctrl+Z removes them all
    import carapost.core.tracking as tracking

    real = tracking.track

    def cancel_after_two(*a, progress=None, **kw):
        cb = progress._callback
        progress._callback = lambda d, t, m: (cb(d, t, m), d >= 2 and progress.cancel())
        return real(*a, progress=progress, **kw)

    monkeypatch.setattr(tracking, "track", cancel_after_two)
    win.session.select(points=[])
    d0 = _run(qtbot, win, "process.track_fwd_seq")
    assert "cancelled" in _log(win)[-1]
    assert tracked(7) > 0 and tracked(8) == 0
    _undo_redo(qtbot, win, d0)
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    monkeypatch.setattr(tracking, "track", real)

    # Both sequences over the whole take, every point
    d0 = _run(qtbot, win, "process.track_fwd_seq")
    assert tracked(11) >= 0.6 * len(faces)
    d1 = _run(qtbot, win, "process.track_back_seq")
    assert stack.names()[-1] == "Track Backwards [Sequence]"
    assert tracked(0) >= 0.6 * len(faces)
    _undo_redo(qtbot, win, d1)
    win.navigate.set_frame(0)                            # nothing before frame 0
    win.action("process.track_back_frame").trigger()
    assert "first frame" in win.prompts.errors[-1]
    win.prompts.errors.clear()

    # Interpolate Gaps fills a hole of the selected point; Remove Interpolated 3D Points takes it out
    q = next(q for q in faces if (q.status != ST_NONE).all())
    truth = q.pos[3:6].astype(float).copy()
    win.navigate.set_frame(3)
    win.session.select(points=[q.id])
    win.action("edit.clear_selected_frame").trigger()
    for f in (4, 5):
        win.navigate.set_frame(f)
        win.action("edit.clear_selected_frame").trigger()
    assert (q.status[3:6] == ST_NONE).all()
    d0 = _run(qtbot, win, "process.interpolate")
    assert stack.names()[-1] == "Interpolate Gaps"
    assert (q.status[3:6] == ST_INTERPOLATED).all()
    assert np.linalg.norm(q.pos[3:6] - truth, axis=1).max() < 2.0
    assert "Interpolate Gaps: 3 samples" in _log(win)[-1]
    _undo_redo(qtbot, win, d0)
    d0 = _run(qtbot, win, "edit.remove_interpolated")
    assert (q.status[3:6] == ST_NONE).all()
    _undo_redo(qtbot, win, d0)
    win.action("edit.remove_interpolated").trigger()      # nothing left to remove: said so, nothing changes
    assert "no interpolated samples" in win.prompts.errors[-1]
