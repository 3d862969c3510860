"""The tracker's compiled per-frame geometry against the array formulas they replaced (session 22).

Each kernel is checked against a plain numpy statement of its formula on a synthetic four-camera rig,
including the NaN cases the tracker feeds it (a point without a position, a view not seen).
"""
import numpy as np
import pytest

from carapost.core.tracking import elastic
from carapost.core.tracking.engine import DEPTH_PX, FUSE_GATE, fuse_depth
from carapost.core.tracking.finite import finite_rows
from carapost.core.tracking.geometry import (RigState, depth_uncertainty, information, refine_poses, rodrigues,
                                             triangulate)
from carapost.core.tracking.synthetic_take import make_take


@pytest.fixture(scope="module")
def rig():
    return RigState(make_take(20, 40, seed=3).project.rig.cameras_at(0))


def _face(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.normal(0.0, 25.0, (n, 3)) * [1.0, 1.0, 0.4]


# ------------------------------------------------------------------ pose refinement
def _array_refine(rig, X, uv_c, valid, iterations, huber=1.0, min_obs=6):
    """The Gauss-Newton of :func:`refine_poses` with numpy arrays (the pre-kernel version's formulas)."""
    R, C, K = rig.R.copy(), rig.C.copy(), rig.K
    good = (valid & np.all(np.isfinite(X), axis=1)[:, None]).T
    active = good.sum(1) >= min_obs
    X = np.where(np.isfinite(X), X, 0.0)
    for _ in range(iterations):
        xc = (X[None] - C[:, None]) @ R.transpose(0, 2, 1)
        z = xc[..., 2]
        u = K[:, None, 0, 0] * xc[..., 0] / z + K[:, None, 0, 1] * xc[..., 1] / z
        v = K[:, None, 1, 1] * xc[..., 1] / z
        r = np.stack([u + K[:, None, 0, 2], v + K[:, None, 1, 2]], -1) - uv_c.transpose(1, 0, 2)
        r = np.where(good[..., None], np.nan_to_num(r), 0.0)
        Jx = np.zeros(xc.shape[:2] + (2, 3))
        Jx[..., 0, 0] = K[:, None, 0, 0] / z
        Jx[..., 0, 1] = K[:, None, 0, 1] / z
        Jx[..., 0, 2] = -u / z
        Jx[..., 1, 1] = K[:, None, 1, 1] / z
        Jx[..., 1, 2] = -v / z
        w = np.where(good, np.sqrt(np.minimum(1.0, huber / np.maximum(np.linalg.norm(r, axis=2), 1e-12))), 0.0)
        Jrot = np.cross(xc[..., None, :], Jx)
        J = np.concatenate([Jrot, -(Jx @ R[:, None])], axis=3) * w[..., None, None]
        J = J.reshape(len(R), -1, 6)
        rw = (r * w[..., None]).reshape(len(R), -1)
        H = np.einsum("sni,snj->sij", J, J)
        g = np.einsum("sni,sn->si", J, rw)
        for s in np.flatnonzero(active):
            d = -np.linalg.solve(H[s] + 1e-9 * np.eye(6), g[s])
            R[s] = rodrigues(d[:3]) @ R[s]
            C[s] = C[s] + d[3:]
    return R, C


def test_refine_poses_is_the_array_gauss_newton(rig):
    rng = np.random.default_rng(1)
    X = _face(150)
    uv = rig.project(X) + rng.normal(0.0, 0.3, (150, rig.S, 2))
    valid = rng.random((150, rig.S)) > 0.2
    valid[:, 3] = np.arange(150) < 5          # camera 3 has too few views: kept as it is
    X[7] = np.nan                             # a point without a position counts nowhere
    start = rig.copy()
    start.R = rodrigues(rng.normal(0.0, 0.004, (rig.S, 3))) @ rig.R
    start.C = rig.C + rng.normal(0.0, 0.4, rig.C.shape)
    got = refine_poses(start, X, uv, valid, iterations=3)
    R, C = _array_refine(start, X, uv, valid, 3)
    assert np.allclose(got.R, R, rtol=0, atol=1e-12)
    assert np.allclose(got.C, C, rtol=0, atol=1e-9)
    assert np.array_equal(got.R[3], start.R[3]) and np.array_equal(got.C[3], start.C[3])
    assert np.array_equal(start.C, start.C) and not np.array_equal(got.C[:3], start.C[:3])   # a new state
    # It converges to the cameras that took the pictures (0.3 px noise, ~115 views a camera).
    assert np.max(np.abs(refine_poses(start, X, uv, valid, iterations=10).C[:3] - rig.C[:3])) < 0.15


def test_refine_poses_huber_keeps_a_wrong_view_from_dragging_a_camera(rig):
    X = _face(60, seed=2)
    uv = rig.project(X)
    valid = np.ones((60, rig.S), bool)
    uv[:3, 0] += 40.0                          # three far-off detections in camera 0
    start = rig.copy()
    start.C = rig.C + 0.3
    plain = _array_refine(start, X, uv, valid, 8, huber=1e9)[1]
    robust = refine_poses(start, X, uv, valid, iterations=8).C
    assert np.linalg.norm(robust[0] - rig.C[0]) < 0.5 * np.linalg.norm(plain[0] - rig.C[0])


# ------------------------------------------------------------------ triangulation
def test_triangulate_weights_views_by_inverse_depth(rig):
    rng = np.random.default_rng(4)
    X = _face(80, seed=4)
    uv = rig.project(X) + rng.normal(0.0, 0.2, (80, rig.S, 2))
    valid = rng.random((80, rig.S)) > 0.3
    weight = rng.uniform(0.3, 1.0, (80, rig.S))
    got = triangulate(rig, uv, valid, weight)
    # The second solve's weights: 100 / depth from the first, times each view's confidence.
    P = rig.P()
    for i in np.flatnonzero(valid.sum(1) >= 2)[:20]:
        def solve(w):
            rows = []
            for s in np.flatnonzero(valid[i]):
                rows += [(uv[i, s, 0] * P[s, 2] - P[s, 0]) * w[s], (uv[i, s, 1] * P[s, 2] - P[s, 1]) * w[s]]
            A = np.array(rows)
            return np.linalg.lstsq(A[:, :3], -A[:, 3], rcond=None)[0]
        X1 = solve(weight[i])
        depth = P[:, 2, :3] @ X1 + P[:, 2, 3]
        assert np.allclose(got[i], solve(100.0 / np.abs(depth) * weight[i]), rtol=0, atol=1e-9)
    assert np.all(np.isnan(got[valid.sum(1) < 2]))


# ------------------------------------------------------------------ depth, information and the average
def _array_depth_uncertainty(rig, X, valid):
    d = X[:, None, :] - rig.C[None]
    dist = np.linalg.norm(d, axis=2)
    with np.errstate(invalid="ignore", divide="ignore"):
        d = np.where(valid[..., None], d / dist[..., None], np.nan)
        cos = np.einsum("nsi,nti->nst", d, d)
        cos_min = np.nanmin(np.where(np.isnan(cos), np.inf, cos).reshape(len(X), -1), axis=1, initial=1.0)
        sin = np.sqrt(np.clip(1.0 - cos_min ** 2, 0.0, 1.0))
        n = valid.sum(1)
        scale = np.where(valid, dist / rig.K[:, 0, 0], 0.0).sum(1) / n
        mm = np.where((n >= 2) & (sin > 1e-9), scale / sin, np.inf)
        u = np.nansum(d, axis=1)
        u /= np.linalg.norm(u, axis=1, keepdims=True)
    return u, mm


def test_depth_uncertainty_matches_its_formula(rig):
    rng = np.random.default_rng(5)
    X = _face(100, seed=5)
    valid = rng.random((100, rig.S)) > 0.4
    valid[0] = [True, True, False, False]      # the two cameras of one side: a narrow pair
    valid[1] = [True, False, False, False]     # one view: no depth
    X[2] = np.nan
    u, mm = depth_uncertainty(rig, X, valid)
    ue, mme = _array_depth_uncertainty(rig, X, valid)
    ok = valid.sum(1) >= 1
    ok[2] = False
    assert np.allclose(u[ok], ue[ok], rtol=0, atol=1e-12)
    assert np.allclose(mm, mme, rtol=1e-12, atol=0) and np.isinf(mm[1]) and np.isinf(mm[2])
    assert np.all(np.isnan(u[valid.sum(1) == 0])) and np.all(np.isnan(u[2]))
    # A pair of cameras on one side fixes depth worse than a pair across the rig.
    both = np.zeros((1, rig.S), bool)
    both[0, [0, 3]] = True
    assert mm[0] > depth_uncertainty(rig, X[:1], both)[1][0]


def test_information_matches_its_formula(rig):
    rng = np.random.default_rng(6)
    X = _face(60, seed=6)
    valid = rng.random((60, rig.S)) > 0.3
    weight = rng.uniform(0.2, 1.0, (60, rig.S))
    X[3] = np.nan
    d = X[:, None, :] - rig.C[None]
    dist2 = np.einsum("nsi,nsi->ns", d, d)
    g = np.where(valid, rig.K[None, :, 0, 0] ** 2 / dist2 * weight ** 2, 0.0)
    r = np.where(valid[..., None], d / np.sqrt(dist2)[..., None], 0.0)
    want = np.einsum("ns,ij->nij", g, np.eye(3)) - np.einsum("ns,nsi,nsj->nij", g, r, r)
    got = information(rig, X, valid, weight)
    rows = np.arange(60) != 3
    assert np.allclose(got[rows], want[rows], rtol=1e-12, atol=1e-9)
    assert np.all(np.isnan(got[3])) == bool(valid[3].any())
    assert np.array_equal(information(rig, X, np.zeros_like(valid)), np.zeros((60, 3, 3)))


def test_fuse_depth_is_the_information_weighted_mean(rig):
    rng = np.random.default_rng(7)
    n = 200
    X = _face(n, seed=7)
    pred = X + rng.normal(0.0, 0.3, (n, 3))
    pred[::17] += 20.0                                  # beyond the gate: left as measured
    pred[5] = np.nan
    A = rng.normal(0.0, 1.0, (n, 3, 3))
    info = A @ A.transpose(0, 2, 1) * 50.0
    info[9] = np.nan
    rows = rng.random(n) > 0.1
    sd = rng.uniform(0.05, 0.5, n)
    post = np.empty(n)
    got = fuse_depth(X, info, pred, sd, rows, post)
    Jm = info / DEPTH_PX ** 2
    want = X.copy()
    want_post = np.full(n, np.inf)
    moved = 0
    for i in range(n):
        if not (rows[i] and np.all(np.isfinite(pred[i])) and np.all(np.isfinite(info[i]))):
            continue
        Jp = np.eye(3) / sd[i] ** 2
        dx = X[i] - pred[i]
        md2 = dx @ np.linalg.solve(np.linalg.inv(Jm[i]) + np.linalg.inv(Jp), dx)
        mean = np.linalg.solve(Jm[i] + Jp, Jm[i] @ X[i] + Jp @ pred[i])
        if md2 <= 3.0 * FUSE_GATE ** 2:
            want[i] = mean
            want_post[i] = np.max(np.diag(np.linalg.inv(Jm[i] + Jp)))
            moved += 1
    assert moved > 50
    assert np.allclose(got, want, rtol=0, atol=1e-9, equal_nan=True)
    assert np.allclose(post, want_post, rtol=1e-9, atol=0) and np.isinf(post[~rows]).all()
    assert np.array_equal(got[~rows], X[~rows]) and np.array_equal(got[[5, 9]], X[[5, 9]])


# ------------------------------------------------------------------ the neighbours' spread along a direction
def _neighbourhood(seed, N, K, off_mm):
    """Random points (one without a position), neighbours (-1: none), offsets and weights of their votes."""
    rng = np.random.default_rng(seed)
    X = rng.normal(0.0, 20.0, (N, 3))
    X[4] = np.nan                                        # an available neighbour without a position
    nb = rng.integers(-1, N, (N, K))
    off = rng.normal(0.0, off_mm, (N, K, 3))
    return rng, X, nb, off


def test_along_spread_is_the_weighted_median_deviation():
    rng, X, nb, off = _neighbourhood(8, 40, 6, 5.0)
    N, K = nb.shape
    off[2, 1] = np.nan
    w = rng.uniform(0.1, 2.0, (N, K))
    rows = np.arange(0, N, 2)
    pred = rng.normal(0.0, 20.0, (len(rows), 3))
    u = rng.normal(0.0, 1.0, (len(rows), 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    firm, voting = rng.random(N) > 0.3, rng.random(N) > 0.1
    use_firm = rng.random(len(rows)) > 0.5
    out = np.empty(len(rows))
    elastic.along_spread(X, nb, off, w, pred, u, rows, use_firm, firm, voting, out)
    for q, i in enumerate(rows):
        avail = firm if use_firm[q] else voting
        votes = [(abs(np.dot(X[j] + off[i, k] - pred[q], u[q])), w[i, k]) for k, j in enumerate(nb[i])
                 if j >= 0 and avail[j] and np.all(np.isfinite(off[i, k]))]
        votes.sort(key=lambda v: (np.isnan(v[0]), v[0]))
        total = sum(v[1] for v in votes)
        want = 0.0
        if votes and total > 0:
            heavy = max(v[1] for v in votes)
            capped = len(votes) > 1 and 2 * heavy >= total
            cap = total - heavy if capped else heavy
            total = 2 * cap if capped else total
            acc = 0.0
            for dev, wk in votes:
                acc += min(wk, cap)
                if (acc > 0.5 * total) if capped else (acc >= 0.5 * total):
                    want = 1.4826 * dev if np.isfinite(dev) else 0.0
                    break
        assert out[q] == pytest.approx(want, rel=1e-12, abs=1e-12)
    assert np.count_nonzero(out) > len(rows) // 2


def test_a_vote_of_half_the_weight_does_not_make_the_spread_zero():
    # Chin_R_6 of the white 100-marker seed-3 take, frame 37: three neighbours left, the one that moves with it
    # (weight 5.7) 3 mm off along the depth, the others (3.2 and 1.5) nearer the point.  The weighted median is
    # the heavy vote alone; the spread is the others' disagreement with it, not 0.
    X = np.zeros((4, 3))
    nb = np.array([[1, 2, 3, -1]])
    off = np.array([[[0.0, 0.0, 3.0], [0.0, 0.0, 0.5], [0.0, 0.0, 1.0], [np.nan] * 3]])
    w = np.array([[5.7, 3.2, 1.5, 1.0]])
    u = np.array([[0.0, 0.0, 1.0]])
    pred = np.array([[0.0, 0.0, 3.0]])                    # the heavy vote
    out = np.empty(1)
    every = np.ones(4, bool)
    elastic.along_spread(X, nb, off, w, pred, u, np.array([0]), np.array([False]), every, every, out)
    assert out[0] == pytest.approx(1.4826 * 2.0)           # the deviation of the vote 1 mm along: 2 mm
    # Equal weights: the median deviation.  A second vote agreeing with the heavy one: the spread is 0 again.
    w2 = np.array([[1.0, 1.0, 1.0, 1.0]])
    elastic.along_spread(X, nb, off, w2, pred, u, np.array([0]), np.array([False]), every, every, out)
    assert out[0] == pytest.approx(1.4826 * 2.0)
    off[0, 3] = (0.0, 0.0, 3.0)
    nb[0, 3] = 0
    elastic.along_spread(X, nb, off, w, pred, u, np.array([0]), np.array([False]), every, every, out)
    assert out[0] == 0.0


# ------------------------------------------------------------------ small helpers
@pytest.mark.parametrize("shape", [(7, 3), (5, 4, 2), (0, 3)])
def test_finite_rows_is_all_isfinite_over_the_last_axis(shape):
    a = np.random.default_rng(9).normal(size=shape)
    if a.size:
        a.flat[::5] = np.nan
        a.flat[3] = np.inf
    assert np.array_equal(finite_rows(a), np.all(np.isfinite(a), axis=-1))


def test_correct_all_is_each_cameras_correction(rig):
    rng = np.random.default_rng(10)
    sensor = rng.integers(0, rig.S, 300)
    raw = rng.uniform(0.0, 1280.0, (300, 2))
    got = rig.correct_all(sensor, raw)
    for s in range(rig.S):
        assert np.array_equal(got[sensor == s], rig.cameras[s].correct(raw[sensor == s]))
    assert rig.correct_all(sensor[:0], raw[:0]).shape == (0, 2)


@pytest.mark.parametrize("n", [1, 2, 7, 8, 151])
def test_median_is_numpys(n):
    from carapost.core.tracking.engine import _median
    a = np.random.default_rng(n).normal(size=n)
    assert _median(a) == np.median(a)
    a[n // 2] = np.nan
    assert np.isnan(_median(a))


def test_vote_support_sums_each_neighbours_nearest_agreement():
    from carapost.core.tracking.vote import AGREE_PX, _support
    rng = np.random.default_rng(11)
    g, C, K, T = 9, 4, 5, 3
    mine = rng.normal(0.0, 6.0, (g, C, 2))
    mine[0, 2] = np.nan                                  # a candidate that is not there
    theirs = rng.normal(0.0, 6.0, (g, K, T, 2))
    theirs[1, 3] = np.nan                                # a neighbour without displacements
    theirs[2, 0, 1] = np.nan
    w = rng.uniform(0.1, 1.0, (g, K))
    got = _support(mine, theirs, w)
    d2 = np.fmin.reduce(((mine[:, None, :, None, :] - theirs[:, :, None, :, :]) ** 2).sum(-1), axis=3)
    want = np.einsum("gkc,gk->gc", np.exp(-np.nan_to_num(d2, nan=np.inf) / (2.0 * AGREE_PX ** 2)), w)
    want[0, 2] = -np.inf
    assert np.allclose(got, want, rtol=1e-13, atol=0)


def test_elastic_prediction_is_the_weighted_median_of_the_votes():
    rng, X, nb, off = _neighbourhood(12, 60, 6, 3.0)
    N, K = nb.shape
    off[::7, 2] = np.nan
    w = rng.uniform(0.05, 3.0, (N, K))
    w[1::4] = 1.0                                        # even weights: the plain median
    available = rng.random(N) > 0.2
    pred, count = elastic.predict(X, available, nb, off, weight=w)
    plain, count0 = elastic.predict(X, available, nb, off)
    assert np.array_equal(count, count0)
    checked = 0
    for i in range(N):
        use = [k for k, j in enumerate(nb[i]) if j >= 0 and available[j] and np.all(np.isfinite(off[i, k]))]
        assert count[i] == len(use)
        if len(use) < elastic.MIN_NEIGHBOURS:
            assert np.all(np.isnan(pred[i]))
            continue
        v = X[nb[i, use]] + off[i, use]
        ww = w[i, use]
        if np.max(ww) > elastic.UNEVEN * np.min(ww):
            for c in range(3):
                cost = np.abs(v[:, c, None] - v[None, :, c]) @ ww
                if np.all(np.isfinite(cost)):
                    least = cost.min()
                    assert pred[i, c] == pytest.approx(v[cost <= least + 1e-9 * (1 + least), c].mean(), rel=1e-12)
                    checked += 1
                else:
                    assert np.isnan(pred[i, c])
        else:
            assert np.array_equal(pred[i], plain[i], equal_nan=True)
            srt = np.sort(v, axis=0)                     # NaN votes last, as the kernel sorts them
            c = len(v)
            assert np.allclose(plain[i], 0.5 * (srt[(c - 1) // 2] + srt[c // 2]), equal_nan=True)
    assert checked > 30
