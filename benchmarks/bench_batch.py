"""``carapost batch``: wall time of a batch of 8 sample takes with 2 worker processes beside 1.

One sample take is rendered and copied under eight take names; the batch runs
Detect Blobs on every frame and saves a project per take (the step whose cost
grows with the take; the rest of the pipeline is a fraction of it).  Both runs
use the same plan with ``force`` so neither skips anything, after a one-take warm-up.  The speed-up is
bounded by the cores the machine really has free: the load average before the
runs is reported, and so are the CPU seconds of the worker processes (on a
busy machine the wall times grow, the CPU time does not).
"""
from __future__ import annotations

import json
import os
import tempfile
import time
from pathlib import Path

TAKES, FRAMES, SIZE = 8, 8, (1280, 720)
QUICK_TAKES, QUICK_FRAMES, QUICK_SIZE = 4, 3, (640, 360)


def _cpu_children() -> float:
    import resource

    r = resource.getrusage(resource.RUSAGE_CHILDREN)
    return r.ru_utime + r.ru_stime


def _make_batch(root: Path, takes: int, frames: int, size: tuple[int, int]) -> Path:
    import shutil

    from carapost.sample import write_sample

    src = root / "rendered"
    write_sample(src, markers=35, frames=frames, seed=1, width=size[0], height=size[1], workers=1)
    for i in range(takes):
        folder = root / f"Take{i}"
        folder.mkdir()
        for c in range(4):
            shutil.copy(src / f"Sample_{c}.pico", folder / f"Take{i}_{c}.pico")
    shutil.rmtree(src)
    pipeline = root / "pipeline.json"
    pipeline.write_text(json.dumps({"steps": ["detect_blobs"], "outputs": {"cara": "{take}_b.cara"}}))
    return pipeline


def run(quick: bool = False) -> list[dict]:
    """Time the batch with 1 and 2 workers (4 small takes when ``quick``)."""
    from carapost.api.batch import find_takes, load_pipeline, plan_batch, run_batch

    takes, frames, size = (QUICK_TAKES, QUICK_FRAMES, QUICK_SIZE) if quick else (TAKES, FRAMES, SIZE)
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="carapost-bench-batch-") as d:
        root = Path(d)
        pipeline = _make_batch(root, takes, frames, size)
        jobs = plan_batch(find_takes([root]), load_pipeline(pipeline))
        run_batch(jobs[:1], workers=1, force=True)     # warm-up: the first spawn reads every module from disk
        wall, cpu = {}, {}
        for workers in (1, 2):
            c, t = _cpu_children(), time.perf_counter()
            summary = run_batch(jobs, workers=workers, force=True)
            wall[workers], cpu[workers] = time.perf_counter() - t, _cpu_children() - c
            if not summary.ok:
                raise RuntimeError(f"batch failed: {summary.failed[0].input}: {summary.failed[0].error}")
    speedup = wall[1] / wall[2]
    name = f"batch_{takes}_takes" + ("_quick" if quick else "")
    common = {"takes": takes, "frames": frames, "size": f"{size[0]}x{size[1]}", "cpus": os.cpu_count(),
              "load_average_before": round(load, 2)}
    return [
        dict(benchmark=f"{name}_1_worker", value=round(wall[1], 2), unit="s", cpu_seconds=round(cpu[1], 1),
             **common),
        dict(benchmark=f"{name}_2_workers", value=round(wall[2], 2), unit="s", cpu_seconds=round(cpu[2], 1),
             **common),
        # On two free cores two workers should nearly halve the time; worker start-up (spawned
        # interpreters importing numpy, OpenCV) is the part that does not shrink.
        dict(benchmark=f"{name}_speedup_2_vs_1", value=round(speedup, 2), unit="x", target=">= 1.5 on 2 idle cores",
             **{"pass": bool(speedup >= 1.5) if (os.cpu_count() or 1) >= 2 else None}, **common),
    ]


if __name__ == "__main__":
    import sys

    for r in run(quick="--quick" in sys.argv):
        print(json.dumps(r))
