"""C3D export and import at the size of a one-minute facial take.

3,600 frames x 200 points (10 % missing samples, residuals and camera masks),
float format.  Baseline in the same run: ezc3d writing (and reading) the same
data, including the conversion to its (4, P, F) / (7, P, F) layout that an
exporter using it has to do.
"""
from __future__ import annotations

import os
import tempfile
import time
from pathlib import Path

import numpy as np

from carapost.io.c3d import read_c3d, write_c3d

FRAMES, POINTS = 3600, 200
TARGET_WRITE_S = 2.0
TARGET_READ_S = 2.0


def make_take(frames: int = FRAMES, points: int = POINTS, seed: int = 0):
    """Positions (mm, NaN missing), residuals, camera masks and labels of a synthetic take."""
    rng = np.random.default_rng(seed)
    t = np.arange(frames)[:, None, None]
    pos = rng.normal(0, 80, (1, points, 3)) + 5 * np.sin(t / 30.0 + rng.uniform(0, 6, (1, points, 3)))
    pos[rng.random((frames, points)) < 0.1] = np.nan
    res = rng.uniform(0, 1.5, (frames, points))
    masks = rng.integers(0, 16, (frames, points)).astype(np.uint8)
    return pos, res, masks, [f"M{i:03d}" for i in range(points)]


def _best(fn, repeats: int) -> float:
    best = float("inf")
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t)
    return best


def _ezc3d_write(path: Path, pos, res, masks, labels, rate: float) -> None:
    import ezc3d

    c = ezc3d.c3d()
    c["parameters"]["POINT"]["RATE"]["value"] = [rate]
    c["parameters"]["POINT"]["LABELS"]["value"] = labels
    pts = np.ones((4, pos.shape[1], pos.shape[0]))
    pts[:3] = np.transpose(pos, (2, 1, 0))
    c["data"]["points"] = pts
    cam = ((masks[None] >> np.arange(7)[:, None, None]) & 1).astype(bool)      # (7, F, P)
    c["data"]["meta_points"] = {"residuals": np.transpose(res, (1, 0))[None],
                                "camera_masks": np.transpose(cam, (0, 2, 1))}
    c.write(str(path))


def run(quick: bool = False) -> list[dict]:
    """Time our C3D export (and import) beside ezc3d on the same data; figures, not assertions."""
    repeats = 1 if quick else 3
    pos, res, masks, labels = make_take()
    tag = f"{FRAMES}f x {POINTS}p"
    out: list[dict] = []
    with tempfile.TemporaryDirectory(dir=os.environ.get("CARAPOST_BENCH_DIR")) as d:
        ours = Path(d) / "ours.c3d"
        theirs = Path(d) / "ezc3d.c3d"
        write_s = _best(lambda: write_c3d(ours, pos, labels, 60.0, res, masks), repeats)
        read_s = _best(lambda: read_c3d(ours), repeats)
        try:
            import ezc3d

            ez_write = _best(lambda: _ezc3d_write(theirs, pos, res, masks, labels, 60.0), repeats)
            ez_read = _best(lambda: ezc3d.c3d(str(theirs)), repeats)
        except ImportError:
            ez_write = ez_read = None
        size_mb = ours.stat().st_size / 1e6
    out.append({"benchmark": f"c3d export {tag}", "value": round(write_s, 4), "unit": "s",
                "target": TARGET_WRITE_S, "pass": write_s < TARGET_WRITE_S,
                "baseline_ezc3d_s": None if ez_write is None else round(ez_write, 4), "file_mb": round(size_mb, 2)})
    out.append({"benchmark": f"c3d import {tag}", "value": round(read_s, 4), "unit": "s",
                "target": TARGET_READ_S, "pass": read_s < TARGET_READ_S,
                "baseline_ezc3d_s": None if ez_read is None else round(ez_read, 4)})
    return out


if __name__ == "__main__":
    import json

    for r in run():
        print(json.dumps(r))
