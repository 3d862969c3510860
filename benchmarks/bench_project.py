"""Project file and undo at the scale of a ten-minute take.

A tracked take of 36,000 frames x 200 points x 4 sensors (200 detections per
sensor and frame, every point attached in every sensor): save, load, memory of
the loaded project, and undo of an edit touching one point over the whole take.
Baseline in the same run: ``numpy.savez`` / ``numpy.load`` of the same arrays.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from carapost.core.detections import DET_DTYPE, DetectionTable
from carapost.core.document import Document
from carapost.core.edits import ClearPointRange
from carapost.core.points import SRC_DETECTION, ST_RECONSTRUCTED
from carapost.core.project import Project
from carapost.io.cara import load_project, save_project


def build_take(frames: int, points: int, sensors: int = 4, seed: int = 0, detections: int | None = None) -> Project:
    """A synthetic tracked take (content is random; sizes are what matter).

    ``detections`` per sensor and frame (default: one per point).
    """
    rng = np.random.default_rng(seed)
    dets = points if detections is None else detections
    p = Project(frames, sensors, 60.0, name="bench")
    for s in range(sensors):
        rec = np.zeros(frames * dets, DET_DTYPE)
        rec["x"] = rng.uniform(0, 1280, len(rec))
        rec["y"] = rng.uniform(0, 720, len(rec))
        rec["major"] = 9.0
        rec["minor"] = 7.0
        rec["score"] = 0.9
        table = DetectionTable(frames, rec, np.arange(frames + 1, dtype=np.int64) * dets)
        table.detected[:] = True
        p.detections[s] = table
    base = rng.normal(0, 40, (points, 3))
    t = np.arange(frames)[:, None]
    for i in range(points):
        pt = p.new_point(label=f"M{i:03d}")
        pt.pos[:] = base[i] + np.sin(t / 50.0 + i)
        pt.status[:] = ST_RECONSTRUCTED
        pt.residual[:] = 0.2
        pt.src[:] = SRC_DETECTION
        pt.det[:] = i
        pt.uv[:] = rng.uniform(0, 700, 2).astype(np.float32)
        pt.score[:] = 1.0
        p.add_point(pt)
    p.labels = [f"M{i:03d}" for i in range(points)]
    return p


_LOAD_SCRIPT = r"""
import json, sys, time
import numpy as np
from carapost.io.cara import load_project
def rss_kb():
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
base = rss_kb()
t = time.perf_counter()
p = load_project(sys.argv[1])
dt = time.perf_counter() - t
# what a user does next: look at some frames (current-frame data of every point and sensor)
rng = np.random.default_rng(1)
for f in rng.integers(0, p.frame_count, 200):
    for pt in p.points.values():
        pt.pos[f]; pt.uv[f]
    for d in p.detections:
        d.frame(int(f))
print(json.dumps({"load_s": dt, "rss_mb": (rss_kb() - base) / 1024.0}))
"""


def run(quick: bool = False) -> list[dict]:
    frames, points = (3600, 200) if quick else (36_000, 200)
    out: list[dict] = []
    tag = f"{frames}f x {points}p x 4s"
    project = build_take(frames, points)
    with tempfile.TemporaryDirectory(dir=os.environ.get("CARAPOST_BENCH_DIR")) as d:
        path = Path(d) / "take.cara"
        os.sync()  # start from a clean page cache: earlier runs' writeback is not this save's cost
        t = time.perf_counter()
        save_project(project, path)
        save_s = time.perf_counter() - t
        size_mb = path.stat().st_size / 1e6

        # baseline: numpy's own container with the same arrays
        arrays = {f"p{pid}_{k}": a for pid, pt in project.points.items() for k, a in pt.arrays.items()}
        for s, table in enumerate(project.detections):
            offs, chunks = table.write_chunks()
            arrays[f"d{s}"] = chunks[0]
        t = time.perf_counter()
        np.savez(Path(d) / "baseline.npz", **arrays)
        npz_save_s = time.perf_counter() - t
        del arrays
        t = time.perf_counter()
        z = np.load(Path(d) / "baseline.npz")
        _ = [z[k] for k in z.files]
        npz_load_s = time.perf_counter() - t
        del z, _
        (Path(d) / "baseline.npz").unlink()

        res = subprocess.run([sys.executable, "-c", _LOAD_SCRIPT, str(path)], capture_output=True, text=True,
                             check=True)
        loaded = json.loads(res.stdout)

        q = load_project(path)
        doc = Document(q)
        pid = next(iter(q.points))
        doc.run(ClearPointRange([pid], 0, frames - 1, name="Clear Selected [Active Range]"))
        t = time.perf_counter()
        doc.undo()
        undo_ms = (time.perf_counter() - t) * 1e3
        t = time.perf_counter()
        doc.redo()
        redo_ms = (time.perf_counter() - t) * 1e3
        history_mb = doc.stack.memory_bytes() / 1e6
        del q, doc

    out.append({"benchmark": "cara_save", "take": tag, "value": round(save_s, 3), "unit": "s", "target": "< 2",
                "pass": save_s < 2, "file_mb": round(size_mb, 1), "baseline_np_savez_s": round(npz_save_s, 3)})
    out.append({"benchmark": "cara_load", "take": tag, "value": round(loaded["load_s"], 4), "unit": "s",
                "target": "< 1", "pass": loaded["load_s"] < 1, "baseline_np_load_s": round(npz_load_s, 3)})
    out.append({"benchmark": "cara_loaded_memory", "take": tag, "value": round(loaded["rss_mb"], 1), "unit": "MB",
                "target": "< 1000", "pass": loaded["rss_mb"] < 1000,
                "note": "RSS increase after loading and reading 200 random frames of every point and sensor"})
    out.append({"benchmark": "undo_one_point_whole_take", "take": tag, "value": round(undo_ms, 2), "unit": "ms",
                "target": "< 50", "pass": undo_ms < 50, "redo_ms": round(redo_ms, 2),
                "history_mb": round(history_mb, 2)})
    return out


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(json.dumps(r))
