"""The sample take: time to write a 120-frame, 1280x720, four-channel take with 100 markers.

Everything ``carapost sample`` does is timed: building the scene, rendering
480 images, lossless H.264 encoding into four ``.pico`` files, and the truth
files.  Also reported: the rendering alone per image (one process), and the
encoding alone (x264 lossless of the rendered images) as a baseline, and the
CPU seconds the take used (all processes): on a busy machine the wall time
grows, the CPU time does not; CPU seconds / cores is the wall time on an idle one.
"""
from __future__ import annotations

import os
import tempfile
import time


def _cpu() -> float:
    """CPU seconds of this process and of its finished children (the worker processes)."""
    import resource

    a, b = resource.getrusage(resource.RUSAGE_SELF), resource.getrusage(resource.RUSAGE_CHILDREN)
    return a.ru_utime + a.ru_stime + b.ru_utime + b.ru_stime


def _load() -> float:
    try:
        return os.getloadavg()[0]
    except OSError:
        return float("nan")


def _take(frames: int, markers: int, width: int, height: int) -> tuple[float, float]:
    """Wall and CPU seconds of one ``write_sample``."""
    from carapost.sample import write_sample

    with tempfile.TemporaryDirectory(prefix="carapost-bench-sample-") as d:
        c, t = _cpu(), time.perf_counter()
        write_sample(d, markers=markers, frames=frames, seed=0, width=width, height=height)
        return time.perf_counter() - t, _cpu() - c


def _render_only(frames: int, markers: int, width: int, height: int):
    """Seconds per image rendering in this process, and the images (for the encoding baseline)."""
    from carapost.sample.render import leds_of, render_view
    from carapost.sample.scene import build_scene, frame_geometry, true_cameras

    scene = build_scene(markers=markers, frames=frames, seed=0, width=width, height=height)
    imgs = []
    t = time.perf_counter()
    for f in range(frames):
        g = frame_geometry(scene, f)
        cams = true_cameras(scene, f)
        img, _ = render_view(scene, g, cams[0], 0, f, leds=leds_of(cams))
        imgs.append(img)
    return (time.perf_counter() - t) / frames, imgs


def _encode_only(imgs) -> float:
    from carapost.io.pico import write_pico

    with tempfile.TemporaryDirectory(prefix="carapost-bench-sample-") as d:
        t = time.perf_counter()
        write_pico(os.path.join(d, "x_0.pico"), imgs, lossless=True, preset="ultrafast")
        return (time.perf_counter() - t) / len(imgs)


def run(quick: bool = False) -> list[dict]:
    """Time ``write_sample`` at the default size (a 12-frame 640x360 take when ``quick``)."""
    frames, w, h = (12, 640, 360) if quick else (120, 1280, 720)
    load = _load()
    secs, cpu = _take(frames, 100, w, h)
    per_img, imgs = _render_only(min(frames, 24), 100, w, h)
    enc = _encode_only(imgs)
    name = "sample_take_120f" if not quick else "sample_take_12f_quick"
    # The quick take is a smoke test: start-up (worker processes, imports) dominates it.
    target = 10.0 if quick else 30.0
    return [
        {"benchmark": name, "value": round(secs, 2), "unit": "s", "target": f"< {target:g}",
         "pass": bool(secs < target), "frames": frames, "size": f"{w}x{h}", "markers": 100,
         "cpus": os.cpu_count(), "cpu_seconds": round(cpu, 1), "load_average_before": round(load, 2),
         "render_ms_per_image": round(1000 * per_img, 1),
         "baseline_encode_ms_per_image": round(1000 * enc, 1)},
    ]


if __name__ == "__main__":
    import json
    import sys

    for r in run(quick="--quick" in sys.argv):
        print(json.dumps(r))
