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
