"""Bundle adjustment: one frame and a sequence, gauge by the brim, undo."""
import numpy as np

from carapost.core.calib.bundle import bundle_cameras, bundle_current_frame, bundle_sequence
from carapost.core.calib.synthetic import make_scene
from carapost.core.points import SRC_DETECTION, ST_RECONSTRUCTED
from carapost.core.progress import Progress


def _problem(sc, f, rng, noise=0.05):
    cams = sc.cameras[f]
    X = sc.face[f]
    uv = np.stack([c.project(X) for c in cams], axis=1) + rng.normal(0, noise, (len(X), 4, 2))
    B = sc.brim.markers
    buv = np.stack([c.project(B) for c in cams], axis=1) + rng.normal(0, noise, (len(B), 4, 2))
    return np.concatenate([B, X]), np.concatenate([buv, uv]), np.r_[np.ones(len(B), bool), np.zeros(len(X), bool)]


def test_bundle_recovers_cameras_and_points_with_outlier():
    rng = np.random.default_rng(1)
    sc = make_scene(60, seed=1)
    X, uv, fixed = _problem(sc, 0, rng)
    uv[30, 1] += 15.0                                   # a mismatched detection: robust loss
    start = [c.with_pose(c.rotation, c.position + rng.normal(0, 1.0, 3)) for c in sc.cameras[0]]
    X0 = X + np.where(fixed[:, None], 0, rng.normal(0, 1.0, X.shape))
    cams, Xo, err = bundle_cameras(start, X0, fixed, uv)
    ce = [np.linalg.norm(a.position - b.position) for a, b in zip(cams, sc.cameras[0])]
    assert max(ce) < 0.1
    e3 = np.linalg.norm(Xo - X, axis=1)
    e3[30] = np.nan                                     # the point with the outlier (3 good views left)
    assert np.sqrt(np.nanmean(e3[~fixed] ** 2)) < 0.08
    assert np.allclose(Xo[fixed], X[fixed])
    assert err[30, 1] > 10 and np.nanmedian(err) < 0.1


def _attach_truth(sc):
    pr = sc.project
    F = pr.frame_count
    for m in range(sc.face.shape[1]):
        p = pr.new_point(point_id=m)
        for s in range(4):
            d = sc.face_det[:, s, m]
            for f in range(F):
                if d[f] >= 0:
                    rec = pr.detections[s].frame(f)[d[f]]
                    p.src[f, s], p.det[f, s], p.uv[f, s] = SRC_DETECTION, d[f], (rec["x"], rec["y"])
        p.pos[:] = sc.face[:, m] + 0.5
        p.status[:] = ST_RECONSTRUCTED
        pr.add_point(p)
    for b in range(len(sc.brim)):
        p = pr.new_point("brim", brim_index=b)
        for s in range(4):
            for f in range(F):
                d = sc.brim_det[f, s, b]
                if d >= 0:
                    rec = pr.detections[s].frame(f)[d]
                    p.src[f, s], p.det[f, s], p.uv[f, s] = SRC_DETECTION, d, (rec["x"], rec["y"])
        pr.add_point(p)
    return pr


def test_bundle_frame_and_sequence_commands_undo():
    sc = make_scene(40, frames=6, seed=2)
    pr = _attach_truth(sc)
    d0 = pr.digest()
    cmd, rep = bundle_current_frame(pr, 3)
    assert pr.digest() == d0
    cmd.do(pr)
    assert rep["rms_px"] < 0.1
    ce = max(np.linalg.norm(a.position - b.position) for a, b in zip(pr.rig.cameras_at(3), sc.cameras[3]))
    assert ce < 0.2
    cmd.undo(pr)
    assert pr.digest() == d0
    seen = []
    cmd, rep = bundle_sequence(pr, progress=Progress(callback=lambda d, t, m: seen.append(d)))
    cmd.do(pr)
    assert rep["frames"] == 6 and rep["rms_px"] < 0.1 and seen[-1] == 6
    for f in range(6):
        ce = max(np.linalg.norm(a.position - b.position) for a, b in zip(pr.rig.cameras_at(f), sc.cameras[f]))
        assert ce < 0.2
        err = np.linalg.norm(np.stack([pr.points[m].pos[f] for m in range(40)]) - sc.face[f], axis=1)
        assert np.sqrt(np.mean(err ** 2)) < 0.08
    cmd.undo(pr)
    assert pr.digest() == d0
