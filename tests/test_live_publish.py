"""Progress.publish: the trackers hand out each frame as they finish it (the GUI's live display).

What is published for a frame must be exactly what the finished command writes
there, and publishing must change nothing about the result.
"""
from __future__ import annotations

import numpy as np
import pytest

from carapost.core import editing, target_ops
from carapost.core.document import Document
from carapost.core.edits import SetPointData, SetProperties
from carapost.core.progress import Progress, frame_payload
from carapost.core.tracking import track

QUIET = dict(jaw_mm=0.0, blinks=0, occlusion_rate=0.0, hidden_markers=0, slips=0)
FIELDS = ("pos", "status", "residual", "src", "det", "uv", "score")


def _point_data(cmd) -> dict[int, tuple[int, dict]]:
    """``pid -> (first frame, arrays)`` of the command's SetPointData."""
    (spd,) = [c for c in getattr(cmd, "commands", [cmd]) if isinstance(c, SetPointData)]
    return {pid: (lo, v) for pid, lo, v in spd.updates}


def _check_published(got: dict, data: dict) -> None:
    """Every frame of every point in ``data`` was published with the same values."""
    for pid, (lo, v) in data.items():
        for t in range(len(v["status"])):
            pl = got[lo + t]
            j = int(np.flatnonzero(pl["ids"] == pid)[0])
            for k in FIELDS:
                assert np.array_equal(np.asarray(pl[k][j]).astype(v[k].dtype), v[k][t], equal_nan=True), \
                    (pid, lo + t, k)


def test_progress_publish_reaches_the_listener_only():
    pr = Progress()
    assert not pr.publishing
    pr.publish(3, {"ids": np.zeros(0)})             # nobody listens: nothing happens
    got = []
    pr.listen(lambda f, pl: got.append((f, pl)))
    assert pr.publishing
    pl = frame_payload(np.array([7]), np.zeros(1, np.uint8), np.zeros((1, 4), np.uint8), np.zeros((1, 4, 2)),
                       np.zeros((1, 4)))
    pr.publish(3, pl)
    assert got == [(3, pl)] and set(pl) == {"ids", "status", "src", "uv", "score"}


def test_track_publishes_every_frame_as_the_command_writes_it():
    from carapost.core.tracking.synthetic_take import initialise, make_take

    sc = make_take(35, 12, seed=4, **QUIET)
    initialise(sc, 5)
    p = sc.project
    got: dict[int, dict] = {}
    cmd = track(p, 5, +1, progress=Progress(listener=lambda f, pl: got.__setitem__(f, pl)))
    assert sorted(got) == list(range(6, 12))
    data = _point_data(cmd)
    brim = [q.id for q in p.points.values() if q.kind == "brim"]
    assert brim and set(brim) <= set(data)             # brim points are published too
    _check_published(got, data)
    # the frame's cameras are published as the command stores them
    quiet = track(p, 5, +1, progress=Progress())
    assert _point_data(quiet).keys() == data.keys()
    for pid, (lo, v) in _point_data(quiet).items():
        assert all(np.array_equal(v[k], data[pid][1][k], equal_nan=True) for k in FIELDS)
    R, C = got[11]["cameras"]
    doc = Document(p)
    doc.run(cmd)
    cam = p.rig.camera(0, 11)
    assert np.allclose(cam.rotation, R[0], atol=1e-6) and np.allclose(cam.position, C[0], atol=1e-4)


@pytest.fixture(scope="module")
def clip():
    from carapost.sample.clip import render_clip

    return render_clip(markers=40, frames=8, seed=1, channels=(0, 1))


def test_target_tracker_publishes_every_frame_as_the_command_writes_it(clip):
    p = clip.project()
    doc = Document(p)
    doc.run(SetProperties({"tracker.break_threshold": 0.75}))
    i = clip.marker("Eyelid_L_Upper")
    pid = doc.run(editing.add_target_track(p, 0, 0, clip.uv[0, 0, i])).select_after[0]
    doc.run(editing.edit_target_track(p, pid, 1, 0, clip.uv[0, 1, i]))
    images = clip.image
    got: dict[int, dict] = {}
    cmd = target_ops.track_targets(p, 0, "forward_to_end", images, [pid],
                                   progress=Progress(listener=lambda f, pl: got.__setitem__(f, pl)))
    data = _point_data(cmd)
    lo, v = data[pid]
    assert cmd.report["frames"] >= 4 and sorted(got) == list(range(1, cmd.report["last"] + 1))
    assert lo == 1 and np.all(v["status"] != 0)      # the 3D was rebuilt on every frame published
    _check_published(got, data)
    quiet = target_ops.track_targets(p, 0, "forward_to_end", images, [pid])
    assert all(np.array_equal(_point_data(quiet)[pid][1][k], v[k], equal_nan=True) for k in FIELDS)
