"""Tracking on rendered sample takes, scored against their truth (issue 7's criteria on real images).

A ``carapost sample`` take (four 1280x720 cameras, fast jaw motion, blinks, lip
curl, rig slip) goes through what ``carapost process`` does before gap filling:
Detect Blobs on every frame, the ``seeds.json`` clicks, Solve Calibration Brim,
Initialize 3D on frame 0, then Track Forwards [Sequence]; and again from the
clicks a person makes on the last frame, Initialize 3D there and Track
Backwards [Sequence].  Scored per marker (a point is the marker it is within
1 mm of on the frame Initialize 3D ran on, or, for a point tracking made for a
marker no point followed, on its sample nearest that frame; every other frame is
scored):

- **coverage**: marker-frames visible in >= 2 cameras that have a
  3D point within 3 mm of the truth.  Visibility leaves out, per camera, the
  markers faint on frame 0 (black paint on a black brow, see
  :func:`carapost.core.blobs.synth.sample_frames`); ``coverage_initialised``
  counts only the markers Initialize 3D found;
- **swaps**: points ever more than 3 mm off their marker, and such samples (stricter than the issue's "a
  point that jumps onto another marker": ``onto_another_marker`` lists the swapped points that were, on
  some frame, nearer another marker than their own); ``duplicated_markers``: markers that two points
  followed on the same frame;
- **rms_mm**: 3D error of the reconstructed samples within 3 mm (median too), and where it is
  (:func:`error_breakdown`): by the samples' number of blob views, and the mean error vector that every
  point shares;
- **misses_by_detected_views**: the marker-frames coverage lacks, by how many cameras detected the marker
  (within 1.5 px): with none the tracker cannot measure it;
- **tracking fps**: tracking alone (images decoded on demand for patches).

Targets (issue 7): coverage >= 0.995, 0 swaps, RMS <= 0.1 mm.  Run:
``.venv/bin/python benchmarks/bench_tracking_rendered.py [--quick]``.
"""
from __future__ import annotations

import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from carapost.core.points import SRC_DETECTION, ST_NONE, ST_RECONSTRUCTED  # noqa: E402
from carapost.core.tracking import track  # noqa: E402
from carapost.io.frames import TakeFrames  # noqa: E402
from carapost.sample import write_sample  # noqa: E402
from carapost.sample.trial import faint_by_camera, initialise_from_seeds, open_sample_take, seen  # noqa: E402

SWAP_MM = 3.0


def error_breakdown(err: np.ndarray, views: np.ndarray) -> dict:
    """Where a take's 3D error is: by how many blob views each sample had, and what all samples share.

    Parameters
    ----------
    err : ndarray (n, 3)
        Error vectors (mm) of the scored samples.
    views : ndarray (n,)
        Each sample's number of views on a blob (patch views and single-sensor samples have fewer than 2).

    Returns
    -------
    dict
        ``rms_by_blob_views_mm`` and ``sq_share_by_blob_views`` (keys ``"<2"``, ``"2"``, ``"3"``, ``"4+"``; a
        group's share of the summed squared error), ``mean_error_mm`` (the mean error vector: an offset
        common to every point, as the cameras solved from a biased brim give) and ``rms_about_mean_mm``.
    """
    sq = np.einsum("ni,ni->n", err, err)
    total = float(sq.sum())
    groups = {"<2": views < 2, "2": views == 2, "3": views == 3, "4+": views >= 4}
    rms = {k: round(float(np.sqrt(sq[g].mean())), 4) for k, g in groups.items() if g.any()}
    share = {k: round(float(sq[g].sum()) / total, 3) if total > 0 else 0.0 for k, g in groups.items() if g.any()}
    mean = err.mean(axis=0) if len(err) else np.zeros(3)
    about = err - mean
    spread = round(float(np.sqrt(np.einsum("ni,ni->n", about, about).mean())), 4) if len(err) else float("nan")
    return {"rms_by_blob_views_mm": rms, "sq_share_by_blob_views": share,
            "mean_error_mm": [round(float(v), 4) for v in mean], "rms_about_mean_mm": spread}


def detected_views(records_of, uv: np.ndarray, missed: np.ndarray, visible: np.ndarray, tol: float = 1.5) -> dict:
    """How many cameras had a detection on each missed marker-frame: whose fault a miss is.

    Parameters
    ----------
    records_of : callable
        ``records_of(camera, frame)`` -> that image's detections (``x``, ``y`` fields).
    uv : ndarray (F, C, M, 2)
        The markers' true image positions.
    missed : ndarray (F, M) bool
        The marker-frames the tracking lacks.
    visible : ndarray (F, C, M) bool
        Where each marker counts as seen.
    tol : float
        A detection within this many px of the marker is its.

    Returns
    -------
    dict
        ``{"0": n, "1": n, "2+": n}``: missed marker-frames by the number of cameras with a detection of
        the marker.  Those with none the tracker cannot measure; those with two or more it could.
    """
    counts = {"0": 0, "1": 0, "2+": 0}
    for f, m in zip(*np.nonzero(missed)):
        n = 0
        for c in np.flatnonzero(visible[f, :, m]):
            rec = records_of(int(c), int(f))
            if len(rec) and np.min(np.hypot(rec["x"] - uv[f, c, m, 0], rec["y"] - uv[f, c, m, 1])) <= tol:
                n += 1
        counts["0" if n == 0 else "1" if n == 1 else "2+"] += 1
    return counts


def score(project, truth: dict, faint: list[set], markers: int, frame: int = 0) -> dict:
    """Coverage, swaps and accuracy of the tracked face points against the truth (module docstring).

    Points are identified on ``frame`` (the frame Initialize 3D ran on); every other frame is scored.
    ``coverage_initialised`` leaves out the markers Initialize 3D did not find (a blob problem, not tracking's).
    """
    labels = [str(v) for v in truth["labels"]]
    face, vis = truth["face_xyz"], seen(truth["visible"], labels, faint)          # (F, M, 3), (F, 4, M+B)
    F = face.shape[0]
    pts = list(project.face_points())
    pos = np.array([np.where((q.status[:F] != ST_NONE)[:, None], q.pos[:F], np.nan) for q in pts])
    st = np.array([q.status[:F] for q in pts])
    # A point is identified on ``frame``, or, made while tracking (a marker no point followed), on its sample
    # nearest that frame.
    have = np.all(np.isfinite(pos), axis=2)                                      # (P, F)
    at = np.array([frame if h[frame] or not h.any() else int(np.flatnonzero(h)[np.argmin(np.abs(
        np.flatnonzero(h) - frame))]) for h in have], int)
    d0 = np.linalg.norm(pos[np.arange(len(pts)), at][:, None] - face[at], axis=2) if len(pts) else np.zeros((0, 1))
    d0 = np.where(np.isnan(d0), np.inf, d0)
    ident = {i: int(d0[i].argmin()) for i in range(len(pts)) if d0[i].min() < 1.0}
    need = vis[:, :, :markers].sum(1) >= 2                                        # (F, M)
    covered = np.zeros_like(need)
    errs, swapped, bad, per, jumped = [], [], 0, {}, []
    vecs, nviews = [], []
    for i, m in ident.items():
        e = np.linalg.norm(pos[i] - face[:, m], axis=1)
        ok = np.isfinite(e) & (e <= SWAP_MM)
        covered[:, m] |= ok
        off = np.isfinite(e) & (e > SWAP_MM)
        if off.any():
            swapped.append(f"{labels[m]}@{int(np.flatnonzero(off)[0])}")
            bad += int(off.sum())
            # The issue's own sense of a swap: on some frame nearer another marker than its own.
            fo = np.flatnonzero(off)
            near = np.linalg.norm(pos[i, fo, None] - face[fo], axis=2).argmin(1)
            if np.any(near != m):
                jumped.append(f"{labels[m]}@{int(fo[np.flatnonzero(near != m)[0]])}")
        keep = (st[i] == ST_RECONSTRUCTED) & ok
        errs.append(e[keep])
        vecs.append((pos[i] - face[:, m])[keep])
        nviews.append((pts[i].src[:F] == SRC_DETECTION).sum(axis=1)[keep])
        if len(errs[-1]):
            per[labels[m]] = float(np.sqrt(np.mean(errs[-1] ** 2)))
    errs = np.concatenate(errs) if errs else np.zeros(0)
    scored = np.arange(F) != frame
    need, covered = need[scored], covered[scored]
    miss = (need & ~covered).sum(0)
    worst = np.argsort(-miss)[:6]
    # Two points on one marker at once: a marker given a second point (by Initialize 3D, or while tracking).
    twice = []
    for m in set(ident.values()):
        rows = [i for i, mm in ident.items() if mm == m]
        if len(rows) > 1:
            near = np.linalg.norm(pos[rows] - face[None, :, m], axis=2) <= SWAP_MM     # (r, F)
            if np.any(near.sum(0) > 1):
                twice.append(labels[m])
    init = np.zeros(need.shape[1], bool)
    init[list(set(ident.values()))] = True
    breakdown = error_breakdown(np.concatenate(vecs) if vecs else np.zeros((0, 3)),
                                np.concatenate(nviews) if nviews else np.zeros(0, int))
    lacking = np.zeros((F, need.shape[1]), bool)                                 # (F, M), frame of ``frame`` not
    lacking[scored] = need & ~covered                                             # scored
    misses = detected_views(lambda c, f: project.detections[c].frame(f), truth["uv"][:, :, :markers], lacking,
                            vis[:, :, :markers])
    return {**breakdown, "misses_by_detected_views": misses, "coverage": float(covered[need].mean()),
            "coverage_initialised": float(covered[:, init][need[:, init]].mean()),
            "swapped_points": len(swapped), "duplicated_markers": len(twice), "swapped_samples": bad,
            "swapped": swapped[:10],
            "onto_another_marker": jumped[:10], "two_points_on_one_marker": twice[:10],
            "rms_mm": float(np.sqrt(np.mean(errs ** 2))) if len(errs) else float("nan"),
            "median_mm": float(np.median(errs)) if len(errs) else float("nan"),
            "worst_rms_mm": {k: round(v, 3) for k, v in sorted(per.items(), key=lambda kv: -kv[1])[:5]},
            "initialised": int(init.sum()), "not_initialised": [labels[m] for m in np.flatnonzero(~init)][:10],
            "most_missed": {labels[m]: int(miss[m]) for m in worst if miss[m]}}


def one(markers: int, seed: int, frames: int, directions=(+1, -1), white: bool = False) -> dict:
    """Render and detect one take, then per direction initialise, track and score it.

    Direction +1: Initialize 3D on frame 0 and Track Forwards [Sequence]; -1: Initialize 3D on the
    last frame (the clicks a person makes there) and Track Backwards [Sequence].  Between the two the
    undo stack is taken back to the detected take.

    Returns
    -------
    dict
        direction -> score and timings.
    """
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        t0 = time.perf_counter()
        write_sample(d, markers=markers, frames=frames, seed=seed, white=white)
        t1 = time.perf_counter()
        project, doc, truth = open_sample_take(d, markers, 0, frames - 1)
        t2 = time.perf_counter()
        images = TakeFrames(project)
        faint = faint_by_camera(markers, seed, white, frames=frames)
        detected = doc.stack.index
        for direction in directions:
            doc.stack.set_index(detected)
            start = 0 if direction > 0 else frames - 1
            initialise_from_seeds(d, project, doc, frame=start)
            t3 = time.perf_counter()
            doc.run(track(project, start, direction, images=images))
            t4 = time.perf_counter()
            r = score(project, truth, faint, markers, start)
            r.update(render_s=round(t1 - t0, 1), detect_s=round(t2 - t1, 1),
                     tracking_fps=round((frames - 1) / (t4 - t3), 1))
            out[direction] = r
    return out


#: Takes of the full run that no constant of the tracker was chosen on (docs/tracking.md: "held out").
HELD_OUT = [(100, 3, 300, False), (100, 3, 300, True), (156, 1, 300, True)]


def run(quick: bool = False) -> list[dict]:
    """One row per take and direction (quick: 35 markers, seed 1, 60 frames, both directions; full: 35/seed 1,
    100/seed 2 and 156/seed 0, black and white, black 100/seed 0 and the three :data:`HELD_OUT` takes, 300
    frames, forwards from frame 0 and backwards from the last frame: the 20 runs docs/tracking.md reports)."""
    takes = [(35, 1, 60, False)] if quick else [(35, 1, 300, False), (35, 1, 300, True), (100, 2, 300, False),
                                                (100, 2, 300, True), (156, 0, 300, False), (156, 0, 300, True),
                                                (100, 0, 300, False), *HELD_OUT]
    rows = []
    for markers, seed, frames, white in takes:
        for direction, r in one(markers, seed, frames, white=white).items():
            ok = r["coverage"] >= 0.995 and r["swapped_points"] == 0 and r["rms_mm"] <= 0.1
            way = "forwards" if direction > 0 else "backwards"
            colour = "_white" if white else ""
            rows.append({"benchmark": f"tracking_rendered_{markers}m{colour}_seed{seed}_{frames}f_{way}",
                         "held_out": (markers, seed, frames, white) in HELD_OUT,
                         "value": round(r["coverage"], 4), "unit": "coverage",
                         "target": ">= 0.995, 0 swaps, <= 0.1 mm", "pass": bool(ok),
                         **{k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()
                            if k != "coverage"}})
    return rows


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        print(json.dumps(row))
