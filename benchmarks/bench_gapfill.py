"""Interpolate Gaps accuracy on real marker trajectories.

Every C3D file in ``/work/shared/data/c3d/`` (real captures; sample 29 is a
facial capture, 38 markers, 3,000 frames at 100 Hz).  For each file and gap
length (5, 12, 30, 60, 120 frames) we cut the same frames out of 1 to 3
markers at once, chosen among the markers present on every frame of the
original, at random interior positions, fill them, and compare with the
original samples.  The figure is the RMS 3D error over every filled sample of
every trial.

Baselines measured in the same run, on the same gaps and seed:

* ``spline``: scipy ``CubicSpline`` through the point's own known samples.
* ``pca``: the method of Gløersen & Federolf (2016), "Predicting missing
  marker trajectories in human motion data using marker intercorrelations",
  PLoS ONE 11(3): e0152616, implemented from the paper's description (see
  :func:`pca_fill`) over the markers complete in the original file.

Targets: on the facial capture <= 0.5 mm for gaps up to 12 frames and <= 3 mm
up to 120; on every file lower than both baselines for every gap above 12
frames.  Points that are not marker positions (Nexus ANGLES, FORCES, MOMENTS,
POWERS) are left out of every method.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline

from carapost.core.gapfill import fill_gaps
from carapost.io.c3d import read_c3d

DATA = Path(__file__).resolve().parents[1].parent / "shared" / "data" / "c3d"
FACIAL = "c3dorg_sample29_Facial-Sing.c3d"
LENGTHS = (5, 12, 30, 60, 120)
NON_MARKER = ("ANGLES", "FORCES", "MOMENTS", "POWERS", "REACTIONS", "SCALARS")


def spline_fill(pos: np.ndarray, p: int, frames: np.ndarray) -> np.ndarray:
    """Cubic spline through point ``p``'s own known samples, evaluated on ``frames``."""
    known = np.flatnonzero(np.isfinite(pos[:, p, 0]))
    return CubicSpline(known, pos[known, p])(frames)


def _pcs(data: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Principal vectors (columns) and square-rooted eigenvalues of centred ``data``, descending."""
    cov = data.T @ data / max(len(data) - 1, 1)       # eigh of the small covariance: fast, same vectors
    ev, vec = np.linalg.eigh(cov)
    order = np.argsort(ev)[::-1]
    return vec[:, order], np.sqrt(np.clip(ev[order], 0, None))


def pca_fill(pos: np.ndarray, missing_pts: list[int], frames: np.ndarray, weight_scale: float = 200.0,
             mm_weight: float = 0.02, min_cum_sv: float = 0.99, iters: int = 100) -> np.ndarray:
    """Gløersen & Federolf (2016) PCA reconstruction of ``missing_pts`` on ``frames``.

    As the paper describes: subtract the mean marker position of each frame (a
    coordinate system moving with the subject), normalise every coordinate to
    unit variance over the complete frames, weight each marker by
    ``exp(-d^2 / (2 sigma^2))`` of its mean distance ``d`` to the missing
    markers (sigma 200 mm; the missing markers themselves 0.02), take the PCA
    of the complete frames and of the same frames with the missing columns
    zeroed (principal vectors up to 99 % of the summed singular values), map
    the incomplete frames through the zeroed basis into the complete one
    (Federolf 2013, equation 1), then refine iteratively: put the
    reconstruction into the gaps, project onto the complete basis, repeat.

    Parameters
    ----------
    pos : ndarray (F, P, 3)
        Markers complete except ``missing_pts`` on ``frames`` (NaN).

    Returns
    -------
    ndarray (len(frames), len(missing_pts), 3)
    """
    n_f, n_p, _ = pos.shape
    others = np.setdiff1d(np.arange(n_p), missing_pts)
    mean_traj = pos[:, others].mean(axis=1, keepdims=True)           # (F, 1, 3)
    x = (pos - mean_traj).reshape(n_f, 3 * n_p)
    gap_cols = np.flatnonzero(~np.isfinite(x).all(axis=0))
    complete = np.isfinite(x).all(axis=1)
    d = np.nanmean(np.linalg.norm(pos[:, :, None, :] - pos[:, None, missing_pts, :], axis=-1), axis=0).min(axis=1)
    w = np.exp(-d ** 2 / (2 * weight_scale ** 2))
    w[missing_pts] = mm_weight
    wv = np.repeat(w, 3)
    n_full = x[complete]
    mu, sd = n_full.mean(0), n_full.std(0)
    sd[sd == 0] = 1.0
    n_zero = n_full.copy()
    n_zero[:, gap_cols] = 0.0
    mu_zero = n_zero.mean(0)
    a = (n_full - mu) / sd * wv
    b = (n_zero - mu_zero) / sd * wv
    v_full, sv_full = _pcs(a)
    v_zero, sv_zero = _pcs(b)
    k = max(int(np.searchsorted(np.cumsum(sv) / np.sum(sv), min_cum_sv) + 1) for sv in (sv_full, sv_zero))
    v_full, v_zero = v_full[:, :k], v_zero[:, :k]
    m = x[frames].copy()
    miss = ~np.isfinite(m)
    mz = m.copy()
    mz[:, gap_cols] = 0.0
    mz = (mz - mu_zero) / sd * wv
    rec = mz @ v_zero @ (v_full.T @ v_zero).T @ v_full.T            # equation 1
    cur = (np.where(miss, 0.0, m) - mu) / sd * wv
    cur[miss] = rec[miss]
    for _ in range(iters):
        nxt = (cur @ v_full) @ v_full.T
        change = np.max(np.abs(nxt[miss] - cur[miss]))
        cur[miss] = nxt[miss]
        if change < 1e-6:
            break
    out = (cur / wv * sd + mu).reshape(len(frames), n_p, 3) + mean_traj[frames]
    return out[:, missing_pts]


def _marker_columns(d) -> np.ndarray:
    skip = set()
    for g in NON_MARKER:
        v = d.parameters.get("POINT", {}).get(g)
        if isinstance(v, list):
            skip.update(x for x in v if isinstance(x, str))
        elif isinstance(v, str):
            skip.add(v)
    return np.array([i for i, lab in enumerate(d.labels) if lab.strip() not in skip], int)


def evaluate_file(path: Path, lengths=LENGTHS, trials: int = 30, seed: int = 0, **fill_kw) -> list[dict]:
    """RMS errors of ours, spline and PCA for each gap length on one file."""
    d = read_c3d(path)
    cols = _marker_columns(d)
    pos = d.positions[:, cols]
    n_f = len(pos)
    complete = np.flatnonzero(np.isfinite(pos).all(axis=(0, 2)))
    rng = np.random.default_rng(seed)
    rows = []
    for length in lengths:
        if n_f - length - 2 < 1 or len(complete) < 4:
            rows.append({"file": path.name, "gap": length, "trials": 0,
                         "note": f"gap of {length} does not fit in {n_f} frames" if len(complete) >= 4
                         else "fewer than 4 complete markers"})
            continue
        err = {"ours": [], "spline": [], "pca": []}
        t_ours = 0.0
        for _ in range(trials):
            n = int(rng.integers(1, 4))
            pts = rng.choice(complete, size=min(n, len(complete) - 3), replace=False)
            s = int(rng.integers(1, n_f - length))                 # interior: frames s..s+L-1
            frames = np.arange(s, s + length)
            cut = pos.copy()
            cut[s:s + length, pts] = np.nan
            truth = pos[s:s + length][:, pts]
            t = time.perf_counter()
            ours, _m = fill_gaps(cut, targets=pts, **fill_kw)
            t_ours += time.perf_counter() - t
            err["ours"].append(ours[s:s + length][:, pts] - truth)
            err["spline"].append(np.stack([spline_fill(cut, p, frames) for p in pts], axis=1) - truth)
            sub = cut[:, complete]
            idx = [int(np.flatnonzero(complete == p)[0]) for p in pts]
            err["pca"].append(pca_fill(sub, idx, frames) - truth)
        rms = {k: float(np.sqrt(np.mean(np.concatenate([e.reshape(-1, 3) for e in v]) ** 2 * 3)))
               for k, v in err.items()}
        rows.append({"file": path.name, "gap": length, "trials": trials, **rms,
                     "ms_per_fill": 1000 * t_ours / trials})
    return rows


def run(quick: bool = False, seed: int = 0) -> list[dict]:
    """Benchmark rows: one per file x gap length (figures, not assertions).

    ``seed`` picks the random gaps; check a change on two seeds before
    believing it (one seed's 30 trials can hinge on one odd stretch of data).
    """
    if not DATA.is_dir():
        return [{"benchmark": "gapfill", "error": f"{DATA} not found (shared data absent)"}]
    files = sorted(DATA.glob("*.c3d"))
    if quick:
        files = [f for f in files if f.name == FACIAL]
    trials = 5 if quick else 30
    out = []
    for f in files:
        for r in evaluate_file(f, trials=trials, seed=seed):
            row = {"benchmark": f"gapfill {r['file']} gap {r['gap']}", "unit": "mm RMS", "seed": seed, **r}
            if r["trials"] == 0:
                row.update(value=None, target=None, **{"pass": None})
                out.append(row)
                continue
            row["value"] = r["ours"]
            if f.name == FACIAL:
                row["target"] = 0.5 if r["gap"] <= 12 else 3.0
                ok = r["ours"] <= row["target"]
            else:
                row["target"] = "< spline and pca" if r["gap"] > 12 else "report"
                ok = True
            if r["gap"] > 12:
                row["target"] = f"{row['target']} and < spline, pca" if f.name == FACIAL else row["target"]
                ok = ok and r["ours"] < r["spline"] and r["ours"] < r["pca"]
            row["pass"] = bool(ok)
            out.append(row)
    return out


if __name__ == "__main__":
    import sys
    quick = "--quick" in sys.argv
    seed = int(sys.argv[sys.argv.index("--seed") + 1]) if "--seed" in sys.argv else 0
    for r in run(quick=quick, seed=seed):
        if r.get("trials"):
            print(f"{r['file'][:40]:40s} gap {r['gap']:4d}  ours {r['ours']:8.3f}  spline {r['spline']:8.3f}  "
                  f"pca {r['pca']:8.3f}  {r['ms_per_fill']:.1f} ms  pass={r['pass']}")
        else:
            print(r.get("benchmark"), r.get("note") or r.get("error"))
