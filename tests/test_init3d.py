"""Initialize 3D from seeds on synthetic takes (35 and 150 markers) and the headless pipeline."""
import numpy as np
import pytest

from carapost.core.calib.init3d import initialize_3d
from carapost.core.calib.synthetic import make_scene
from carapost.core.commands import UndoStack
from carapost.core.errors import CaraError
from carapost.core.pipeline import process_to_init3d


def evaluate(sc, pr, frame=0):
    """(fraction of 2+-view markers initialised, mismatched points, 3D RMS mm, camera centre error mm)."""
    F = sc.face_det[frame]
    inv = [{int(d): m for m, d in enumerate(F[s]) if d >= 0} for s in range(4)]
    vis2 = np.flatnonzero((F >= 0).sum(0) >= 2)
    got, mism, err = set(), 0, []
    for p in pr.face_points():
        ms = {inv[s].get(int(p.det[frame, s]), -1) for s in range(4) if p.src[frame, s] == 1}
        if len(ms) != 1 or -1 in ms:
            mism += 1
            continue
        m = ms.pop()
        got.add(m)
        err.append(np.linalg.norm(p.pos[frame] - sc.face[frame, m]))
    ce = max(np.linalg.norm(a.position - b.position) for a, b in zip(pr.rig.cameras_at(frame), sc.cameras[frame]))
    return len(got & set(vis2)) / len(vis2), mism, float(np.sqrt(np.mean(np.square(err)))), ce


@pytest.mark.parametrize("markers,depth,seed", [(35, 60.0, 0), (150, 16.0, 0), (150, 16.0, 3)])
def test_pipeline_initialises_face(markers, depth, seed):
    sc = make_scene(markers, seed=seed)
    pr = sc.project
    pr.properties.set("initialize_3d.max_allowed_depth", depth)
    stack = UndoStack(pr)
    d0 = pr.digest()
    lines = []
    cmds = process_to_init3d(pr, sc.seeds(n_face=8, n_brim=5, seed=seed), log=lines.append, stack=stack)
    assert len(cmds) == 5 and len(lines) == 5
    frac, mism, rms, ce = evaluate(sc, pr)
    assert frac >= 0.97 and mism == 0 and rms <= 0.08 and ce <= 0.3, (frac, mism, rms, ce)
    while stack.can_undo():
        stack.undo()
    assert pr.digest() == d0


def test_initialize_needs_seeds():
    sc = make_scene(35, seed=2)
    with pytest.raises(CaraError, match="seed points"):
        initialize_3d(sc.project, 0)
    sc.project.rig = None
    with pytest.raises(CaraError, match="intrinsics"):
        initialize_3d(sc.project, 0)


def test_rendered_sample_lips_are_not_cross_matched(tmp_path):
    """On a rendered sample take the lip markers sit one above the other, on the same epipolar lines.

    A wrong upper/lower lip match lands near the points grown so far while the right one is
    still beyond Max Allowed Depth; it used to be accepted as "unambiguous" (the right one was
    not yet a candidate), leaving 4-5 mismatched points on seed 0.
    """
    import json

    from carapost.core.blob_ops import detect_blobs_range
    from carapost.core.points import FACE, SRC_DETECTION, ST_NONE
    from carapost.io.brim_svg import read_brim_svg
    from carapost.io.imports import import_xcp
    from carapost.io.take import project_from_input
    from carapost.sample import write_sample

    write_sample(tmp_path, markers=35, frames=1, seed=0, workers=1)
    truth = np.load(tmp_path / "truth.npz")
    pr = project_from_input(str(tmp_path / "Sample_0.pico"), None)
    import_xcp(pr, tmp_path / "calibration.xcp", lambda s: None).do(pr)
    detect_blobs_range(pr, 0, 0, workers=1).do(pr)
    seeds = json.loads((tmp_path / "seeds.json").read_text())
    process_to_init3d(pr, seeds, read_brim_svg(tmp_path / "brim.svg"), log=lambda s: None)
    uv, vis = truth["uv"][0], truth["visible"][0]
    owner = []
    for s in range(4):
        rec = pr.detections[s].frame(0)
        d = np.linalg.norm(np.column_stack([rec["x"], rec["y"]])[:, None] - uv[s][None], axis=2)
        d = np.where(vis[s][None], d, np.inf)
        owner.append(np.where(d.min(1) < 1.5, d.argmin(1), -1))
    markers_of = [{int(owner[s][q.det[0, s]]) for s in range(4) if q.src[0, s] == SRC_DETECTION}
                  for q in pr.points.values() if q.kind == FACE and q.status[0] != ST_NONE]
    crossed = [m for m in markers_of if len(m - {-1}) > 1]
    assert not crossed
    lips = {i for i, lab in enumerate(truth["labels"]) if str(lab).startswith("Lip_")}
    assert lips <= set().union(*markers_of)
    for s in range(4):
        assert np.linalg.norm(np.asarray(pr.rig.camera(s, 0).position) - truth["cam_t"][0, s]) < 0.3


def test_a_view_pulled_off_its_dot_is_left_out():
    """Leave-one-out: one view 1 px off (a detection pulled by a shadow beside the dot) is detached;
    views within blob noise, and 2-view points, are kept."""
    from carapost.core.calib.init3d import odd_views_out

    sc = make_scene(35, seed=2)
    cams = sc.cameras[0]
    rng = np.random.default_rng(0)
    X = sc.face[0][:20]
    uv = np.stack([c.project(X) for c in cams], axis=1) + rng.normal(0, 0.05, (20, 4, 2))
    uv[5, 2] += (0.8, -0.6)                 # 1 px off in camera 2
    uv[9, 0] += (1.0, 0.0)                  # 1 px off, but the point has only 2 views
    uv[9, 1:3] = np.nan
    bad = odd_views_out(cams, uv)
    assert bad[5, 2] and bad.sum() == 1, np.argwhere(bad)


def test_growth_goes_on_past_sparse_markers_with_the_other_caddys_support():
    """Markers sparser than Max Allowed Depth (an eye socket or a nostril on a 100-marker face with the
    dense set's 16 mm) stall the growth; matches the other caddy confirms carry it on, and none is wrong."""
    sc = make_scene(35, seed=0)
    pr = sc.project
    pr.properties.set("initialize_3d.max_allowed_depth", 12.0)
    process_to_init3d(pr, sc.seeds(n_face=8, n_brim=5, seed=0), log=lambda s: None, stack=UndoStack(pr))
    frac, mism, rms, _ce = evaluate(sc, pr)
    assert frac >= 0.97 and mism == 0 and rms <= 0.08, (frac, mism, rms)


def test_a_caddy_match_pulled_along_its_epipolar_line_is_made_again_across_the_caddies():
    """A nose tip's blob merged with the nostrils' shadow in one camera of a caddy, and not found at all in
    a camera of the other: the caddy's pair still matches (the error runs along its epipolar line) and
    the point lands millimetres deep, where the other caddy sees nothing.  It is made again from the
    good detection and the other caddy's."""
    from carapost.core.camera import epipolar_line

    sc = make_scene(35, seed=1)
    pr = sc.project
    F = sc.face_det[0]
    cams = sc.cameras[0]
    (a, b), (c, _d) = pr.caddies()
    m = max(m for m in range(35) if (F[:, m] >= 0).all())
    ra = pr.detections[a].frame(0)
    line = np.asarray(epipolar_line(cams[a], cams[b], np.array([ra["x"][F[a, m]], ra["y"][F[a, m]]])), float)
    along = np.array([line[1], -line[0]]) / np.hypot(line[0], line[1])
    rb = pr.detections[b].frame(0).copy()
    rb["x"][F[b, m]] += 6.0 * along[0]           # camera b's blob slides 6 px along camera a's epipolar line
    rb["y"][F[b, m]] += 6.0 * along[1]
    pr.detections[b].set_frame(0, rb)
    rc = pr.detections[c].frame(0).copy()
    rc["x"][F[c, m]] += 400.0                    # and camera c does not find the dot
    pr.detections[c].set_frame(0, rc)
    process_to_init3d(pr, sc.seeds(n_face=8, n_brim=5, seed=1), log=lambda s: None, stack=UndoStack(pr))
    dist = [np.linalg.norm(q.pos[0] - sc.face[0, m]) for q in pr.face_points() if q.status[0]]
    assert min(dist) < 0.3, min(dist)
