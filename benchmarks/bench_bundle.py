"""Bundle adjustment speed: Bundle Current Frame (4 cameras, 160 points) and Bundle Sequence.

Scenes from :mod:`carapost.core.calib.synthetic` (truth projections + 0.05 px
noise), cameras and points perturbed from the truth as a tracker leaves them.
``run(quick=False)`` returns one dict per measurement.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from carapost.core.calib.bundle import bundle_batch, bundle_cameras, whiten, _intrinsics  # noqa: E402
from carapost.core.calib.synthetic import make_scene  # noqa: E402

POINTS = 160


def _frame_problem(scene, rng, frame=0):
    cams = scene.cameras[frame]
    X = scene.face[frame]
    uv = np.stack([c.project(X) for c in cams], axis=1) + rng.normal(0, 0.05, (len(X), 4, 2))
    uv[scene.face_det[frame].T < 0] = np.nan
    B = scene.brim.markers
    buv = np.stack([c.project(B) for c in cams], axis=1) + rng.normal(0, 0.05, (len(B), 4, 2))
    Xall = np.concatenate([B, X + rng.normal(0, 0.3, X.shape)])
    uvall = np.concatenate([buv, uv])
    fixed = np.r_[np.ones(len(B), bool), np.zeros(len(X), bool)]
    start = [c.with_pose(c.rotation, c.position + rng.normal(0, 0.3, 3)) for c in cams]
    return start, Xall, fixed, uvall


def run(quick: bool = False) -> list[dict]:
    rng = np.random.default_rng(0)
    scene = make_scene(POINTS - 20, seed=0)      # 140 face + 20 brim points = 160
    cams, X, fixed, uv = _frame_problem(scene, rng)
    bundle_cameras(cams, X, fixed, uv)           # warm-up
    times = []
    for _ in range(5 if quick else 21):
        t = time.perf_counter()
        _, _, err = bundle_cameras(cams, X, fixed, uv)
        times.append((time.perf_counter() - t) * 1e3)
    ms = float(np.median(times))
    rms = float(np.sqrt(np.nanmean(err ** 2)))
    out = [{"benchmark": "bundle_current_frame_ms", "name": "Bundle Current Frame (4 cameras, 160 points)",
            "value": round(ms, 2), "unit": "ms", "target": 17.0, "pass": ms <= 17.0, "rms_px": round(rms, 4)}]
    # Sequence: the same problem repeated with fresh noise per frame.
    frames = 360 if quick else 3600
    probs = [_frame_problem(scene, rng) for _ in range(64)]
    t = time.perf_counter()
    sq, n = 0.0, 0
    from carapost.core.calib.bundle import SEQUENCE_BLOCK
    base = scene.cameras[0]
    intr = _intrinsics(base)
    for b0 in range(0, frames, SEQUENCE_BLOCK):
        b = min(SEQUENCE_BLOCK, frames - b0)
        sel = [probs[(b0 + i) % len(probs)] for i in range(b)]
        R = np.stack([[c.rotation for c in p[0]] for p in sel])
        C = np.stack([[c.position for c in p[0]] for p in sel])
        Xb = np.stack([p[1] for p in sel])
        uvb = np.stack([p[3] for p in sel])
        uv_c, W, valid = whiten(base, uvb)
        free = np.broadcast_to(~fixed, (b, len(fixed)))
        _, _, _, err = bundle_batch(R, C, intr, Xb, free, uv_c, W, valid)
        sq += float(np.nansum(err ** 2))
        n += int(np.count_nonzero(np.isfinite(err)))
    sec = time.perf_counter() - t
    full = sec * (3600 / frames)
    out.append({"benchmark": "bundle_sequence_s", "name": f"Bundle Sequence, 3600 frames x {POINTS} points"
                + (f" (extrapolated from {frames})" if quick else ""),
                "value": round(full, 2), "unit": "s", "target": 60.0, "pass": full <= 60.0,
                "rms_px": round(float(np.sqrt(sq / n)), 4), "frames_run": frames})
    return out


if __name__ == "__main__":
    import json
    for r in run(quick="--quick" in sys.argv):
        print(json.dumps(r))
