"""The rendered-take benchmark's breakdown of the 3D error (benchmarks/bench_tracking_rendered.py)."""
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from benchmarks.bench_tracking_rendered import error_breakdown  # noqa: E402


def test_breakdown_by_blob_views_and_common_offset():
    rng = np.random.default_rng(0)
    offset = np.array([0.0, 0.03, 0.015])
    noise = {1: 0.3, 2: 0.25, 3: 0.15, 4: 0.05}
    counts = {1: 200, 2: 500, 3: 600, 4: 4000}
    err, views = [], []
    for v, n in counts.items():
        err.append(offset + rng.normal(0.0, noise[v] / np.sqrt(3), (n, 3)))
        views.append(np.full(n, v))
    err, views = np.concatenate(err), np.concatenate(views)
    out = error_breakdown(err, views)
    sq = (err ** 2).sum(1)
    for key, sel in (("<2", views < 2), ("2", views == 2), ("3", views == 3), ("4+", views >= 4)):
        assert out["rms_by_blob_views_mm"][key] == pytest.approx(np.sqrt(sq[sel].mean()), abs=1e-4)
        assert out["sq_share_by_blob_views"][key] == pytest.approx(sq[sel].sum() / sq.sum(), abs=1e-3)
    assert sum(out["sq_share_by_blob_views"].values()) == pytest.approx(1.0, abs=3e-3)
    # The offset every sample shares is found, and the RMS about it leaves it out.
    assert np.allclose(out["mean_error_mm"], offset, atol=0.01)
    about = err - err.mean(0)
    assert out["rms_about_mean_mm"] == pytest.approx(np.sqrt((about ** 2).sum(1).mean()), abs=1e-4)
    assert out["rms_about_mean_mm"] < np.sqrt(sq.mean())


def test_breakdown_leaves_out_empty_groups():
    out = error_breakdown(np.array([[0.1, 0.0, 0.0], [0.0, 0.2, 0.0]]), np.array([4, 4]))
    assert set(out["rms_by_blob_views_mm"]) == {"4+"}
    assert out["sq_share_by_blob_views"] == {"4+": 1.0}


def test_misses_counted_by_the_cameras_that_detected_the_marker():
    from benchmarks.bench_tracking_rendered import detected_views
    from carapost.core.detections import make_detections

    F, C, M = 3, 4, 2
    uv = np.zeros((F, C, M, 2))
    uv[..., 0] = 100.0 + 50.0 * np.arange(M)          # marker m at x = 100 + 50 m in every camera
    uv[..., 1] = 200.0
    visible = np.ones((F, C, M), bool)
    visible[2, 3, 1] = False                         # a detection where the marker is not seen does not count
    found = {(0, 1): [0], (1, 1): [0], (2, 1): [0, 1], (3, 2): [1]}    # (camera, frame) -> markers detected
    near = {(0, 2): [(1, 1.4)], (3, 2): [(1, 0.2)], (1, 2): [(1, 1.6)]}  # (camera, frame) -> (marker, px off)

    def records_of(c, f):
        xs = [uv[f, c, m, 0] for m in found.get((c, f), [])]
        xs += [uv[f, c, m, 0] + off for m, off in near.get((c, f), [])]
        return make_detections(np.array(xs, float), np.full(len(xs), 200.0))

    missed = np.zeros((F, M), bool)
    missed[0, 0] = True        # no camera
    missed[1, 0] = True        # cameras 0, 1, 2: three
    missed[2, 1] = True        # camera 0 (1.4 px) and camera 3 (not visible there): one; camera 1 is 1.6 px off
    missed[2, 0] = False
    out = detected_views(records_of, uv, missed, visible)
    assert out == {"0": 1, "1": 1, "2+": 1}
