"""Interpolate Gaps: the array engine, the project commands and ``carapost fill-gaps``."""
import argparse
from pathlib import Path

import numpy as np
import pytest

from carapost.core.gapfill import fill_gaps, find_gaps, project_to_ray
from carapost.core.points import (SRC_DETECTION, SRC_NONE, SRC_PATCH, SRC_TARGET, ST_INTERPOLATED, ST_NONE,
                                  ST_RECONSTRUCTED, ST_SINGLE)

SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "data"
FACIAL = SHARED / "c3d" / "c3dorg_sample29_Facial-Sing.c3d"


def _rot(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def rigid_take(frames=200, points=8, seed=0):
    """Markers on one rigid body that turns and travels."""
    rng = np.random.default_rng(seed)
    body = rng.normal(0, 60, (points, 3))
    t = np.arange(frames)
    out = np.empty((frames, points, 3))
    for f in t:
        r = _rot([0.3, 1, 0.2], 0.6 * np.sin(f / 25.0))
        out[f] = body @ r.T + [f * 1.5, 20 * np.sin(f / 15.0), 5.0]
    return out


def test_find_gaps():
    assert find_gaps(np.array([0, 1, 1, 0, 1], bool)) == [(1, 2), (4, 4)]
    assert find_gaps(np.zeros(4, bool)) == []


def test_rigid_motion_filled_exactly():
    truth = rigid_take()
    cut = truth.copy()
    cut[40:100, 2] = np.nan
    cut[60:70, 5] = np.nan
    filled, mask = fill_gaps(cut)
    assert mask[40:100, 2].all() and mask[60:70, 5].all() and mask.sum() == 70
    np.testing.assert_allclose(filled, truth, atol=1e-6)


def test_one_sided_gaps_at_start_and_end():
    truth = rigid_take()
    cut = truth.copy()
    cut[:30, 1] = np.nan
    cut[170:, 4] = np.nan
    filled, mask = fill_gaps(cut)
    assert mask[:30, 1].all() and mask[170:, 4].all()
    np.testing.assert_allclose(filled, truth, atol=1e-6)


def test_direction_switches():
    # Point 0 drifts relative to the others: forwards keeps its relative
    # position from before the gap, backwards the one after it.
    truth = rigid_take()
    truth[:, 0] += np.linspace(0, 30, len(truth))[:, None] * [1, 0, 0]
    cut = truth.copy()
    cut[80:120, 0] = np.nan
    both, _ = fill_gaps(cut)
    fwd, _ = fill_gaps(cut, backwards=False)
    bwd, _ = fill_gaps(cut, forwards=False)
    assert not np.allclose(fwd[80:120, 0], bwd[80:120, 0])
    # Forwards-only joins the sample before the gap, backwards-only the one after.
    assert np.linalg.norm(fwd[80, 0] - truth[79, 0]) < np.linalg.norm(bwd[80, 0] - truth[79, 0])
    assert np.linalg.norm(bwd[119, 0] - truth[120, 0]) < np.linalg.norm(fwd[119, 0] - truth[120, 0])
    # The blend is better than either side alone.
    err = {k: np.abs(v[80:120, 0] - truth[80:120, 0]).max() for k, v in (("b", both), ("f", fwd), ("w", bwd))}
    assert err["b"] < min(err["f"], err["w"])
    # Neither side: a start gap cannot be filled forwards.
    cut2 = truth.copy()
    cut2[:10, 3] = np.nan
    _, m = fill_gaps(cut2, backwards=False)
    assert not m[:10, 3].any()
    _, m = fill_gaps(cut, forwards=False, backwards=False)
    assert not m.any()


def test_max_gap_and_targets():
    cut = rigid_take()
    cut[10:20, 1] = np.nan
    cut[50:100, 2] = np.nan
    _, m = fill_gaps(cut, max_gap=20)
    assert m[10:20, 1].all() and not m[:, 2].any()
    _, m = fill_gaps(cut, targets=[2])
    assert m[50:100, 2].all() and not m[:, 1].any()


def test_single_sensor_ray():
    truth = rigid_take()
    cut = truth.copy()
    cut[50:60, 3] = np.nan
    org = np.full(truth.shape, np.nan)
    dirn = np.full(truth.shape, np.nan)
    org[50:60, 3] = [0, 0, -1000]
    dirn[50:60, 3] = truth[50:60, 3] - org[50:60, 3] + [3, -2, 0]   # rays slightly off the truth
    filled, mask = fill_gaps(cut, rays=(org, dirn))
    x = filled[50:60, 3]
    np.testing.assert_allclose(project_to_ray(x, org[50:60, 3], dirn[50:60, 3]), x, atol=1e-9)


def test_weak_samples_beside_a_gap_are_kept_but_do_not_predict_it():
    """A lagging sample next to a gap is carried across the whole gap unless it is marked weak."""
    truth = rigid_take()
    cut = truth.copy()
    cut[40:60, 2] = np.nan
    cut[39, 2] += [1.5, -1.0, 0.5]                # a patch track lagging as the point was lost
    weak = np.zeros(len(truth), bool)
    weak[39] = True
    plain, _ = fill_gaps(cut)
    filled, mask = fill_gaps(cut, weak={2: weak})
    assert np.abs(plain[40:60, 2] - truth[40:60, 2]).max() > 0.3
    np.testing.assert_allclose(filled[40:60, 2], truth[40:60, 2], atol=1e-6)
    np.testing.assert_array_equal(filled[39, 2], cut[39, 2])      # kept as measured, not written over
    assert mask[40:60, 2].all() and mask.sum() == 20
    # Weak samples that border no gap change nothing: with no gap, nor as another gap's context.
    again, mask = fill_gaps(truth, weak={2: weak})
    assert mask.sum() == 0 and np.array_equal(again, truth)
    far = np.zeros(len(truth), bool)
    far[[10, 120]] = True
    cut[39, 2] = truth[39, 2]
    np.testing.assert_array_equal(fill_gaps(cut, weak={2: far})[0], fill_gaps(cut)[0])


def test_which_samples_are_weak():
    from carapost.core.gapfill_ops import weak_samples
    from carapost.core.points import Point

    p = Point(0, 6, 3)
    p.status[:] = [ST_RECONSTRUCTED, ST_RECONSTRUCTED, ST_RECONSTRUCTED, ST_SINGLE, ST_INTERPOLATED,
                   ST_RECONSTRUCTED]
    p.src[0] = [SRC_DETECTION, SRC_DETECTION, SRC_PATCH]       # two blobs: firm
    p.src[1] = [SRC_DETECTION, SRC_PATCH, SRC_PATCH]           # depth from patches: weak
    p.src[2] = [SRC_PATCH, SRC_NONE, SRC_PATCH]                # patches only: weak
    p.src[3] = [SRC_DETECTION, SRC_NONE, SRC_NONE]             # single-sensor: weak
    p.src[4] = SRC_NONE                                        # an earlier fill: not the tracker's
    p.src[5] = SRC_NONE                                        # no 2D samples (a C3D's, or placed by hand)
    assert weak_samples(p).tolist() == [False, True, True, True, False, False]
    p.src[1] = [SRC_DETECTION, SRC_TARGET, SRC_NONE]           # Target Tracker samples count as blobs
    assert not weak_samples(p)[1]


# ---------------------------------------------------------------- project
def _project(with_rig=False):
    from carapost.core.project import Project
    truth = rigid_take(frames=60, points=6)
    pr = Project(60, 2, 60.0, name="gaps")
    for i in range(6):
        pt = pr.new_point(label=f"M{i}")
        pt.pos[:] = truth[:, i]
        pt.status[:] = ST_RECONSTRUCTED
        pr.add_point(pt)
    return pr, truth


def test_interpolate_gaps_command_and_undo():
    from carapost.core.gapfill_ops import interpolate_gaps, remove_interpolated
    pr, truth = _project()
    p = pr.points[2]
    p.pos[20:30] = np.nan
    p.status[20:30] = ST_NONE
    d0 = pr.digest()
    cmd = interpolate_gaps(pr)
    assert pr.digest() == d0                      # computing changes nothing
    cmd.do(pr)
    assert (p.status[20:30] == ST_INTERPOLATED).all()
    np.testing.assert_allclose(p.pos[20:30], truth[20:30, 2], atol=1e-3)
    d1 = pr.digest()
    rm = remove_interpolated(pr)
    rm.do(pr)
    assert (p.status[20:30] == ST_NONE).all() and np.isnan(p.pos[20:30]).all()
    rm.undo(pr)
    assert pr.digest() == d1
    cmd.undo(pr)
    assert pr.digest() == d0


def test_interpolate_gaps_range_and_selection():
    from carapost.core.gapfill_ops import interpolate_gaps
    pr, _ = _project()
    for pid in (1, 2):
        pr.points[pid].pos[20:30] = np.nan
        pr.points[pid].status[20:30] = ST_NONE
    interpolate_gaps(pr, point_ids=[2], start=0, end=24).do(pr)
    assert (pr.points[2].status[20:25] == ST_INTERPOLATED).all()
    assert (pr.points[2].status[25:30] == ST_NONE).all()
    assert (pr.points[1].status[20:30] == ST_NONE).all()


def test_overwrite_flag():
    from carapost.core.edits import SetProperties
    from carapost.core.gapfill_ops import interpolate_gaps
    pr, truth = _project()
    p = pr.points[3]
    p.pos[10:15] = truth[10:15, 3] + 50.0         # a bad earlier fill
    p.status[10:15] = ST_INTERPOLATED
    cmd = interpolate_gaps(pr)
    assert cmd.updates == []                      # default: existing fills are kept
    SetProperties({"gap_filling.overwrite_existing_filled_gaps": True}).do(pr)
    interpolate_gaps(pr).do(pr)
    np.testing.assert_allclose(p.pos[10:15], truth[10:15, 3], atol=1e-3)


def test_interpolate_gaps_does_not_predict_from_patch_samples():
    from carapost.core.gapfill_ops import interpolate_gaps
    pr, truth = _project()
    for p in pr.points.values():
        p.src[:] = SRC_DETECTION
    p = pr.points[2]
    p.pos[20:30] = np.nan
    p.status[20:30] = ST_NONE
    p.src[20:30] = SRC_NONE
    p.pos[19] += np.float32(2.0)                  # the frame before the gap seen by patches only, lagging
    p.src[19] = SRC_PATCH
    before = p.pos[19].copy()
    interpolate_gaps(pr).do(pr)
    assert (p.status[20:30] == ST_INTERPOLATED).all() and p.status[19] == ST_RECONSTRUCTED
    np.testing.assert_array_equal(p.pos[19], before)
    np.testing.assert_allclose(p.pos[20:30], truth[20:30, 2], atol=1e-3)


def test_single_sensor_gap_filling_in_project():
    from carapost.core.gapfill_ops import interpolate_gaps
    from support import make_project
    pr = make_project(frames=30, sensors=4, points=4, with_rig=True)
    assert pr.rig is not None
    truth = rigid_take(frames=30, points=len(pr.points))
    truth = truth - truth.mean(axis=(0, 1)) + [0, 0, 0]
    for i, p in enumerate(pr.points.values()):
        p.pos[:] = truth[:, i]
        p.status[:] = ST_RECONSTRUCTED
        p.src[:] = 0
    p = list(pr.points.values())[1]
    p.pos[10:14] = np.nan
    p.status[10:14] = ST_NONE
    cam = pr.rig.camera(0, 12)
    uv = cam.project(truth[12, 1][None])[0] + [2.0, -1.0]
    p.src[12, 0] = SRC_DETECTION
    p.uv[12, 0] = uv
    interpolate_gaps(pr).do(pr)
    assert p.status[12] == ST_SINGLE and p.status[11] == ST_INTERPOLATED
    o, d = cam.ray(uv)
    x = p.pos[12].astype(float)
    d = np.reshape(d, 3)
    off = (x - o) - np.dot(x - o, d) / np.dot(d, d) * d
    assert np.linalg.norm(off) < 1e-3               # on the ray (float32 storage)


# ---------------------------------------------------------------- real data
def _parser():
    from carapost.fillgaps_cli import add_fill_gaps_command
    ap = argparse.ArgumentParser()
    add_fill_gaps_command(ap.add_subparsers())
    return ap


def test_cli_on_real_c3d(tmp_path):
    from carapost.io.c3d import read_c3d
    src = SHARED / "c3d" / "c3dorg_sample01_Eb015pr.c3d"
    if not src.exists():
        pytest.skip(f"{src} is absent: ../shared is not beside this clone")
    out = tmp_path / "out.c3d"
    a = _parser().parse_args(["fill-gaps", str(src), str(out)])
    assert a.func(a) == 0
    i, o = read_c3d(src), read_c3d(out)
    v = i.valid
    np.testing.assert_array_equal(o.positions[v], i.positions[v])
    np.testing.assert_allclose(o.residuals[v], i.residuals[v], atol=1e-6)
    np.testing.assert_array_equal(o.camera_masks[v], i.camera_masks[v])
    new = o.valid & ~v
    assert new.any()
    assert (o.residuals[new] == 0).all() and (o.camera_masks[new] == 0).all()


def test_cli_missing_file_exit_2(tmp_path, capsys):
    from carapost.core.errors import CaraError
    a = _parser().parse_args(["fill-gaps", str(tmp_path / "none.c3d"), str(tmp_path / "o.c3d")])
    with pytest.raises(CaraError):
        a.func(a)
    try:
        from carapost.cli import main
        if "fill-gaps" in str(main.__globals__.get("build_parser")().format_help()):
            assert main(["fill-gaps", str(tmp_path / "none.c3d"), str(tmp_path / "o.c3d")]) == 2
            assert len(capsys.readouterr().err.strip().splitlines()) == 1
    except ImportError:
        pass


def test_real_facial_12_frame_gaps_beat_spline():
    if not FACIAL.exists():
        pytest.skip(f"{FACIAL} is absent: ../shared is not beside this clone")
    from scipy.interpolate import CubicSpline
    from carapost.io.c3d import read_c3d
    pos = read_c3d(FACIAL).positions
    complete = np.flatnonzero(np.isfinite(pos).all(axis=(0, 2)))
    rng = np.random.default_rng(1)
    e_ours, e_spl = [], []
    for _ in range(6):
        p = int(rng.choice(complete))
        s = int(rng.integers(100, len(pos) - 112))
        cut = pos.copy()
        cut[s:s + 12, p] = np.nan
        filled, _ = fill_gaps(cut, targets=[p])
        known = np.flatnonzero(np.isfinite(cut[:, p, 0]))
        spl = CubicSpline(known, cut[known, p])(np.arange(s, s + 12))
        e_ours.append(filled[s:s + 12, p] - pos[s:s + 12, p])
        e_spl.append(spl - pos[s:s + 12, p])
    rms = lambda e: float(np.sqrt(np.mean(np.sum(np.concatenate(e) ** 2, axis=1))))
    assert rms(e_ours) < rms(e_spl)
    assert rms(e_ours) < 0.5


def _bench():
    """benchmarks/bench_gapfill.py (its baselines: cubic spline and Gløersen & Federolf's PCA)."""
    import importlib.util
    path = Path(__file__).resolve().parents[1] / "benchmarks" / "bench_gapfill.py"
    spec = importlib.util.spec_from_file_location("bench_gapfill", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("name", ["c3dorg_sample29_Facial-Sing.c3d", "c3dorg_sample00_Vicon_pyCGM2_Walking01.c3d"])
def test_real_60_frame_gaps_beat_spline_and_pca(name):
    # Gaps of 60 frames cut from 1-3 markers at once: lower RMS error than
    # both baselines of the benchmark on the same gaps.
    from support import shared_file
    path = shared_file("c3d", name)
    (row,) = _bench().evaluate_file(path, lengths=(60,), trials=4, seed=2)
    assert row["trials"] == 4
    assert row["ours"] < row["spline"] and row["ours"] < row["pca"], row
