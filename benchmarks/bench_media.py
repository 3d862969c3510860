"""Benchmarks of the media layer: opening, decoding and caching ``.pico`` takes.

A ten-minute take at 60 fps has 36,000 frames per channel.  Encoding four
such channels would take far longer than the benchmark itself, so ONE channel
file is generated (1280x720, a synthetic face with marker dots and sensor
noise, H.264 at ~15 Mbit/s, 24-frame GOPs) by encoding two GOPs and writing
them over and over with fresh frame headers and time stamps; it is cached in
``~/.cache/carapost/bench/`` and the four "channels" are four readers of that
file.  Page-cache effects: the file has just been written or read, so the
figures are for a warm disk cache.

``run(quick=False)`` returns one dict per measurement::

    {"benchmark": name, "value": v, "unit": u, "target": t, "pass": bool, ...}
"""
from __future__ import annotations

import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from carapost.io.framecache import FrameCache  # noqa: E402
from carapost.io.media import PicoSource  # noqa: E402
from carapost.io.pico import H264Encoder, PicoReader, PicoWriter  # noqa: E402

CACHE_DIR = Path(os.environ.get("CARAPOST_BENCH_DIR", Path.home() / ".cache" / "carapost" / "bench"))
WIDTH, HEIGHT, FPS, GOP = 1280, 720, 60.0, 24
FORMAT_VERSION = 1            # bump when the generated content or the writer changes


def face_frames(n: int, width: int = WIDTH, height: int = HEIGHT, seed: int = 0) -> list[np.ndarray]:
    """Synthetic head-camera images: a lit face-like ellipse with ~80 bright marker dots and noise.

    Parameters
    ----------
    n : int
        Number of frames; the dots move a little from frame to frame.
    """
    import cv2

    rng = np.random.default_rng(seed)
    yy, xx = np.mgrid[0:height, 0:width].astype(np.float32)
    cx, cy, ax, ay = width / 2, height / 2, width * 0.33, height * 0.55
    r2 = ((xx - cx) / ax) ** 2 + ((yy - cy) / ay) ** 2
    base = np.where(r2 < 1, 70 + 60 * (1 - r2), 12).astype(np.float32)
    base += 10 * np.sin(xx / 37.0) * (r2 < 1)
    ang = rng.uniform(0, 2 * np.pi, 80)
    rad = np.sqrt(rng.uniform(0.02, 0.8, 80))
    dots = np.stack([cx + ax * rad * np.cos(ang), cy + ay * rad * np.sin(ang)], 1)
    out = []
    for i in range(n):
        img = base.copy()
        moved = dots + 6 * np.stack([np.sin(i / 9.0 + dots[:, 1] / 50), np.cos(i / 11.0 + dots[:, 0] / 60)], 1)
        for x, y in moved:
            cv2.circle(img, (int(round(x * 16)), int(round(y * 16))), 5 * 16, 235.0, -1, cv2.LINE_AA, 4)
        img += rng.normal(0, 2.0, img.shape).astype(np.float32)
        out.append(np.clip(img, 0, 255).astype(np.uint8))
    return out


def long_take(frames: int, path: Path | None = None, log=print) -> Path:
    """A cached 1280x720 ``.pico`` of ``frames`` frames (generated once, reused)."""
    path = path or CACHE_DIR / f"bench_face_{WIDTH}x{HEIGHT}_{frames}_v{FORMAT_VERSION}_fastdecode_0.pico"
    if path.exists():
        try:
            with PicoReader(path) as r:
                if r.frame_count == frames and not r.warnings:
                    return path
        except Exception:  # noqa: BLE001 — a bad cached file is simply made again
            pass
    path.parent.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    unique = 2 * GOP
    enc = H264Encoder(WIDTH, HEIGHT, frame_rate=FPS, gop=GOP, lossless=False, bitrate=15_000_000)
    aus = []
    for img in face_frames(unique):
        aus += enc.encode(img)
    aus += enc.encode(None)
    assert len(aus) == unique and aus[0][1] == 1 and aus[GOP][1] == 1
    with PicoWriter(path, WIDTH, HEIGHT, frame_rate=FPS, bitrate=15_000_000,
                    capture_name=path.stem.rsplit("_", 1)[0]) as w:
        for i in range(frames):
            au, kind = aus[i % unique]
            w.write_access_unit(au, kind)
    log(f"generated {path} ({path.stat().st_size / 1e6:.0f} MB) in {time.perf_counter() - t0:.1f} s")
    return path


def _rss_mb(kind: str = "RssAnon") -> float:
    """Resident memory in MB: ``RssAnon`` (heap: frames, decoders) or ``VmRSS`` (also mapped file pages)."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(kind + ":"):
                    return int(line.split()[1]) / 1024
    except OSError:
        pass
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _result(name, value, unit, target, ok, **extra) -> dict:
    d = {"benchmark": name, "value": round(float(value), 3), "unit": unit, "target": target, "pass": bool(ok)}
    d.update(extra)
    return d


def run(quick: bool = False, log=None) -> list[dict]:
    """Run the media benchmarks.

    Parameters
    ----------
    quick : bool
        A 1,200-frame file and fewer repetitions (a smoke test; not the targets' conditions).

    Returns
    -------
    list of dict
        ``benchmark``, ``value``, ``unit``, ``target``, ``pass`` and details.
    """
    log = log or (lambda *a: print(*a, file=sys.stderr))
    frames = 1200 if quick else 36_000
    channels = 4
    path = long_take(frames, log=log)
    results = []
    tag = f"{WIDTH}x{HEIGHT}, {frames} frames/channel"

    # Open four channels (header, metadata and frame index).
    times = []
    for _ in range(3):
        t = time.perf_counter()
        readers = [PicoReader(path) for _ in range(channels)]
        times.append(time.perf_counter() - t)
        for r in readers:
            r.close()
    results.append(_result("media.open_4_channels", min(times), "s", "< 1", min(times) < 1.0,
                           detail=f"{tag}; best of 3, warm disk cache"))

    # Sequential decode, one thread per channel.
    per = 120 if quick else 1200
    sources = [PicoSource(path) for _ in range(channels)]
    counts = [0] * channels

    def work(c):
        start = (c * 7919) % (frames - per)
        start -= start % GOP
        for _ in sources[c].read_range(start, start + per):
            counts[c] += 1

    t, cpu = time.perf_counter(), time.process_time()
    threads = [threading.Thread(target=work, args=(c,)) for c in range(channels)]
    for th in threads:
        th.start()
    for th in threads:
        th.join()
    dt, cpu = time.perf_counter() - t, time.process_time() - cpu
    fps = sum(counts) / dt
    cpu_ms = cpu / sum(counts) * 1000
    results.append(_result("media.sequential_decode_4_channels", fps, "frames/s", ">= 240", fps >= 240,
                           cpu_ms_per_frame=round(cpu_ms, 2), cpu_utilisation=round(cpu / dt, 2),
                           bytes_per_frame=int(path.stat().st_size / frames),
                           detail=f"{tag}; {per} frames per channel, {channels} threads, {os.cpu_count()} CPUs; "
                                  f"CPU-bound: at most {os.cpu_count()} x 1000 / cpu_ms_per_frame frames/s"))

    # Random access: any frame (decode from its I-frame).
    rng = np.random.default_rng(1)
    src = sources[0]
    lat, dist = [], []
    cpu = time.process_time()
    for k in rng.integers(0, frames, 20 if quick else 100):
        src.reader._decoder = None             # no help from a live decoder: a true seek
        t = time.perf_counter()
        src.read(int(k))
        lat.append((time.perf_counter() - t) * 1000)
        dist.append(int(k) - src.gop_start(int(k)) + 1)
    cpu = time.process_time() - cpu
    lat = np.asarray(lat)
    results.append(_result("media.random_access", lat.mean(), "ms", "< 40", float(lat.max()) < 40,
                           p95_ms=round(float(np.percentile(lat, 95)), 2), max_ms=round(float(lat.max()), 2),
                           cpu_ms_mean=round(cpu * 1000 / len(lat), 2),
                           frames_decoded_mean=round(float(np.mean(dist)), 1),
                           detail=f"{tag}; mean of {len(lat)} random frames, each decoded from its I-frame "
                                  f"(GOP {GOP}); pass = slowest under target"))

    # Stepping back one frame once its GOP is cached.
    cache = FrameCache(max_mb=256)
    back = []
    for k in rng.integers(GOP, frames, 10 if quick else 30):
        cache.get(src, int(k))                 # decodes the GOP run up to k
        t = time.perf_counter()
        cache.get(src, int(k) - 1)
        back.append((time.perf_counter() - t) * 1000)
    back = np.asarray(back)
    results.append(_result("media.step_back_cached", back.mean(), "ms", "< 5", back.max() < 5,
                           max_ms=round(float(back.max()), 4), detail="FrameCache.get(k-1) after get(k)"))

    # Memory bounded by the cache: play 4 channels through a 256 MB cache.
    cache.clear()
    rss0, anon0 = _rss_mb("VmRSS"), _rss_mb()
    peak_cache = peak_anon = 0
    play = 240 if quick else 1500
    t = time.perf_counter()
    futs = []
    for c, s in enumerate(sources):
        start = (c * 104_729) % (frames - play)
        futs.append(cache.prefetch(s, range(start, start + play)))
    while not all(f.done() for f in futs):
        peak_cache = max(peak_cache, cache.stats()["bytes"])
        peak_anon = max(peak_anon, _rss_mb() - anon0)
        time.sleep(0.01)
    for f in futs:
        f.result()
    dt = time.perf_counter() - t
    st = cache.stats()
    peak_cache = max(peak_cache, st["bytes"])
    rss_growth = _rss_mb("VmRSS") - rss0
    frame_mb = WIDTH * HEIGHT / 2 ** 20
    # The bound is on the cache; the process also holds four decoders' picture pools, hence the margin.
    ok = peak_cache <= cache.max_bytes and peak_anon < 256 + 128
    results.append(_result("media.cache_memory_bound", peak_cache / 2 ** 20, "MB", "<= 256", ok,
                           peak_heap_growth_mb=round(peak_anon, 1), rss_growth_mb=round(rss_growth, 1),
                           frames_played=channels * play,
                           cache_fill_fps=round(channels * play / dt, 1), evictions=st["evictions"],
                           detail=f"{channels} channels x {play} frames ({channels * play * frame_mb:.0f} MB "
                                  f"decoded) through FrameCache(max_mb=256) with 2 prefetch workers; pass = "
                                  "cache bytes within the bound and heap (RssAnon) growth < bound + 128 MB"))
    cache.close()
    for s in sources:
        s.close()
    return results


if __name__ == "__main__":
    import json

    for r in run(quick="--quick" in sys.argv):
        print(json.dumps(r))
