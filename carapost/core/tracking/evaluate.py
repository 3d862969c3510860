"""Score a tracked synthetic take against its truth (coverage, swaps, 3D error)."""
from __future__ import annotations

import numpy as np

from ..points import SRC_DETECTION, ST_NONE, ST_RECONSTRUCTED


def identify(scene, frame: int) -> dict[int, int]:
    """Face point id -> marker index, from the point's detections on ``frame``."""
    fd = scene.face_det[frame]
    inv = [{int(d): m for m, d in enumerate(fd[s]) if d >= 0} for s in range(fd.shape[0])]
    out = {}
    for p in scene.project.face_points():
        ms = {inv[s].get(int(p.det[frame, s]), -1) for s in range(fd.shape[0]) if p.src[frame, s] == SRC_DETECTION}
        if len(ms) == 1 and -1 not in ms:
            out[p.id] = ms.pop()
    return out


def evaluate(scene, start: int, frames) -> dict:
    """Quality of tracking over ``frames`` for the points identified on ``start``.

    Returns
    -------
    dict
        ``coverage``: fraction of marker-frames visible in 2+ cameras that have a
        correct measured 3D point (reconstructed or single-sensor); ``swaps``:
        points that on some frame carry a detection of another marker or sit
        > 3 mm from their marker; ``wrong_samples`` (other markers' blobs);
        ``stray_samples``: false detections attached where the marker itself is
        hidden (within the 2D tolerance, so indistinguishable from it);
        ``rms_mm``: 3D error of reconstructed samples; ``rms_single_mm``;
        ``initialised``: fraction of markers with a point on ``start``;
        ``reacquired``: fraction of whole-marker occlusions after which the point was picked up again.
    """
    frames = list(frames)
    ident = identify(scene, start)
    pr = scene.project
    S = pr.sensor_count
    M = scene.face.shape[1]
    wrong = 0
    stray = 0
    swapped = set()
    errs, errs1 = [], []
    covered = 0
    need = 0
    for f in frames:
        fd = scene.face_det[f]
        vis2 = (fd >= 0).sum(axis=0) >= 2
        inv = [{int(d): m for m, d in enumerate(fd[s]) if d >= 0} for s in range(S)]
        for pid, m in ident.items():
            p = pr.points[pid]
            st = p.status[f]
            ok = st != ST_NONE
            for s in range(S):
                if p.src[f, s] == SRC_DETECTION:
                    got = inv[s].get(int(p.det[f, s]), -1)
                    if got >= 0 and got != m:
                        wrong += 1          # another marker's blob: a swap
                        swapped.add(pid)
                        ok = False
                    elif got < 0:
                        stray += 1          # a false detection where the marker is hidden
            if st != ST_NONE:
                e = float(np.linalg.norm(p.pos[f] - scene.face[f, m]))
                if e > 3.0:
                    swapped.add(pid)
                    ok = False
                (errs if st == ST_RECONSTRUCTED else errs1).append(e)
            if vis2[m]:
                need += 1
                covered += bool(ok)
    # Re-acquisition after whole-marker occlusions.
    hidden = scene.extras.get("hidden")
    back = total = 0
    if hidden is not None:
        allh = np.all(hidden, axis=1)                       # (F, M)
        by_m = {m: pid for pid, m in ident.items()}
        fs = np.array(frames)
        for m, pid in by_m.items():
            h = allh[fs, m]
            ends = np.flatnonzero(h[:-1] & ~h[1:]) + 1
            for e in ends:
                # The marker is back on frames fs[e:]; count it picked up within 5 frames of being seen in 2 cameras.
                later = [k for k in range(e, min(len(fs), e + 10)) if (scene.face_det[fs[k], :, m] >= 0).sum() >= 2]
                if not later:
                    continue
                total += 1
                k0 = later[0]
                back += any(pr.points[pid].status[fs[k]] != ST_NONE for k in range(k0, min(len(fs), k0 + 5)))
    rms = float(np.sqrt(np.mean(np.square(errs)))) if errs else float("nan")
    rms1 = float(np.sqrt(np.mean(np.square(errs1)))) if errs1 else float("nan")
    return {"coverage": covered / max(1, need), "swaps": len(swapped), "wrong_samples": wrong, "stray_samples": stray, "rms_mm": rms,
            "rms_single_mm": rms1, "single_samples": len(errs1), "initialised": len(set(ident.values())) / M,
            "reacquired": back / total if total else float("nan"), "occlusions": total}
