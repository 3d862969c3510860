"""Benchmarks of blob detection: accuracy, centre precision against the Cramér-Rao bound, speed.

Every figure is reported beside OpenCV's ``SimpleBlobDetector`` (tuned for these
images) run on the same frames.

- ``blobs_{black,white}_{recall,precision,rms}``: frames of ``carapost sample``
  takes (seeds 0-2, all four cameras, 1280x720, the sample's default noise and
  blur), rendered in memory with their ground truth (:func:`~carapost.core.blobs.synth.sample_frames`),
  at the default Blob Parameters (threshold 0.4).  A detection within 1.5 px of a
  visible marker's centre (face or brim) is a hit (one per marker); any other
  detection is false (nostrils, pupils, brows, hair, lips, brim edges), except
  within 6 px of a marker drawn but partly covered or too faint to see (black paint on a
  dense black eyebrow: ``faint`` in the rows).  RMS is of the 2-D centre
  error of hits.  ``blobs_{c}_brim_recall``: the same for the brim's dots alone.  The
  recall rows list the markers missed by name (``missed``).
- ``blobs_{black,white}_clutter_{recall,precision,rms}``: the same on 1280x720
  frames of :func:`~carapost.core.blobs.synth.render` (120 markers, 14 confusers:
  more clutter than a face), markers near a hidden one excepted within 10 px.
- ``blobs_{black,white}_large_{recall,precision,rms}``: the same on 1280x720 frames of
  large dots (semi-major axis 5-24 px, the guide's default Max Radius allowing up to 25;
  60 markers, 14 confusers), with the recall of each size (``recall_by_semi_axis``, ours and
  the baseline's): what a take with bigger dots or closer cameras would give.  No target of
  the issue is set on them; they are reported so that the weakness they show stays in view
  (docs/blobs-history.md, "Session 31").
- ``blobs_crb_ratio_snr{15,50,150}``: isolated blurred discs (radius 4 px, blur
  1 px) at signal-to-noise 15/50/150: per-axis RMS centre error over the
  Cramér-Rao bound computed for that exact image model (target <= 1.5).
- ``blobs_fps``: frames per second of detection of one colour, fitting
  included, on the sample takes' 1280x720 frames, all cores (the thread pool of
  Detect Blobs [Active Range]: the rate of a 48-frame run less a 1-frame one, i.e. without
  the pool's start-up, which is reported apart, as is the rate with it;
  ``single_image_ms`` is one image on one thread, ``single_image_cpu_ms`` its CPU
  time, which other jobs on the machine disturb less; best of 3 runs), beside
  SimpleBlobDetector on a thread pool (OpenCV releases the GIL).

``run(quick=False)`` returns one dict per measurement.
"""
from __future__ import annotations

import os
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import numpy as np

if __package__ in (None, ""):
    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import cv2  # noqa: E402

from carapost.core.blobs import detect  # noqa: E402
from carapost.core.blobs.synth import disc_image, match_truth, render, sample_frames  # noqa: E402

W, H = 1280, 720
#: SimpleBlobDetector's tuned filters for black (False) and white (True) dots (see :func:`simple_blob_detector`).
SBD = {False: {"min_area": 8, "circularity": 0.7, "convexity": 0.85, "inertia": 0.15},
       True: {"min_area": 4, "circularity": 0.5, "convexity": 0.7, "inertia": 0.05}}


def takes(white: bool, seeds=(0, 1, 2), frames: int = 3):
    """Frames of sample takes (all four cameras) with truth."""
    return [s for seed in seeds for s in sample_frames(white, seed=seed, frames=frames)]


def frames(n: int, white: bool, seed: int = 2024):
    """``n`` generated cluttered face-camera frames with truth (default noise of the generator)."""
    rng = np.random.default_rng([seed, int(white)])
    return [render(rng, H, W, markers=120, white=white, radius=(2.5, 6.0), noise=(1.0, 3.0), confusers=14)
            for _ in range(n)]


def large_frames(n: int, white: bool, seed: int = 7):
    """``n`` generated 1280x720 frames of large dots (semi-major axis 5-24 px) with truth."""
    rng = np.random.default_rng([seed, int(white)])
    return [render(rng, H, W, markers=60, white=white, radius=(5.0, 24.0), noise=(1.0, 3.0), confusers=14)
            for _ in range(n)]


#: Semi-major axis bins (px) of the large-dot frames' recall by size.
SIZE_BINS = ((5, 8), (8, 12), (12, 16), (16, 20), (20, 25))


def simple_blob_detector(white: bool):
    """OpenCV's SimpleBlobDetector tuned for painted dots of 1-12 px semi-axis, oblique ones included.

    Tuned on a sample take's frames (seed 0, the best recall at precision >= 0.9
    of 54 settings of minimum area, circularity, convexity and inertia per colour).
    """
    t = SBD[bool(white)]
    p = cv2.SimpleBlobDetector_Params()
    p.minThreshold, p.maxThreshold, p.thresholdStep = 10, 230, 10
    p.minRepeatability = 2
    p.filterByColor, p.blobColor = True, 255 if white else 0
    p.filterByArea, p.minArea, p.maxArea = True, t["min_area"], 800
    p.filterByCircularity, p.minCircularity = True, t["circularity"]
    p.filterByConvexity, p.minConvexity = True, t["convexity"]
    p.filterByInertia, p.minInertiaRatio = True, t["inertia"]
    p.minDistBetweenBlobs = 4
    return cv2.SimpleBlobDetector_create(p)


def sbd_points(det, img):
    kp = det.detect(img)
    return np.array([k.pt for k in kp], float).reshape(-1, 2)


def _row(name, value, unit, target, ok, **extra):
    return {"benchmark": name, "value": float(value), "unit": unit, "target": target, "pass": bool(ok), **extra}


def accuracy(white: bool, data, prefix: str = "", hidden_px: float = 6.0, by_size: bool = False) -> list[dict]:
    """Recall, precision and centre RMS of ours and SimpleBlobDetector's on ``data`` (SynthImage list).

    With ``by_size``, the recall rows also give the recall of each semi-major axis bin (:data:`SIZE_BINS`).
    """
    sbd = simple_blob_detector(white)
    tot = {"ours": [0, 0, 0, [], 0, 0], "sbd": [0, 0, 0, [], 0, 0]}
    missed: dict[str, int] = {}
    sizes = {"ours": [], "sbd": []}
    for s in data:
        r = detect(s.image, white=white)
        for key, pts in (("ours", np.stack([r["x"], r["y"]], 1).astype(float)), ("sbd", sbd_points(sbd, s.image))):
            hit, f, e = match_truth(pts, s, hidden_px=hidden_px)
            sizes[key].append(np.column_stack([s.axes[:, 0], hit]) if len(hit) else np.zeros((0, 2)))
            if key == "ours" and s.names is not None:
                for k in np.flatnonzero(~hit):
                    missed[s.names[k]] = missed.get(s.names[k], 0) + 1
            t = tot[key]
            t[0] += int(hit.sum())
            t[1] += f
            t[2] += int((~hit).sum())
            t[3].append(e)
            if s.brim is not None:
                t[4] += int(hit[s.brim].sum())
                t[5] += int(s.brim.sum())
    out = []
    c = ("white" if white else "black") + prefix
    figs = {}
    for key, (h, f, m, e, bh, bn) in tot.items():
        e = np.concatenate(e)
        figs[key] = (h / max(h + m, 1), h / max(h + f, 1), float(np.sqrt((e ** 2).sum(1).mean())) if len(e) else np.nan,
                     bh / max(bn, 1), bn)
    o, b = figs["ours"], figs["sbd"]
    extra = {"frames": len(data), "markers": int(sum(len(s.centres) for s in data)), "load_average": os.getloadavg()[0],
             "faint": int(sum(len(s.faint) for s in data if s.faint is not None))}
    if by_size:
        for key in sizes:
            a = np.concatenate(sizes[key])
            extra[f"recall_by_semi_axis{'' if key == 'ours' else '_baseline'}"] = {
                f"{lo}-{hi}": round(float(a[(a[:, 0] >= lo) & (a[:, 0] < hi), 1].mean()), 4) for lo, hi in SIZE_BINS}
    out.append(_row(f"blobs_{c}_recall", o[0], "fraction", ">= 0.995", o[0] >= 0.995,
                    baseline="SimpleBlobDetector", baseline_value=b[0],
                    missed=dict(sorted(missed.items(), key=lambda kv: -kv[1])), **extra))
    out.append(_row(f"blobs_{c}_precision", o[1], "fraction", ">= 0.98", o[1] >= 0.98,
                    baseline="SimpleBlobDetector", baseline_value=b[1], **extra))
    out.append(_row(f"blobs_{c}_rms", o[2], "px", "<= 0.08", o[2] <= 0.08,
                    baseline="SimpleBlobDetector", baseline_value=b[2], **extra))
    if o[4]:
        out.append(_row(f"blobs_{c}_brim_recall", o[3], "fraction", ">= 0.995", o[3] >= 0.995,
                        baseline="SimpleBlobDetector", baseline_value=b[3], brim_markers=o[4]))
    return out


def crb(radius=4.0, blur=1.0, amplitude=100.0, sigma=1.0, size=25) -> float:
    """Cramér-Rao bound (px, per axis) of the centre of the rendered disc, amplitude and background unknown."""
    from carapost.core.blobs.synth import _ellipse_coverage, _paste

    def base(cx, cy):
        # 32x32 supersampling: smooth enough in the centre for finite differences.
        y0, x0, cov = _ellipse_coverage(size, size, cx, cy, radius, radius, 0.0, ss=32)
        img = np.zeros((size, size), np.float64)
        _paste(img, y0, x0, cov.astype(np.float64), 1.0)
        return cv2.GaussianBlur(img, (0, 0), blur) * amplitude

    c = (size // 2 + 0.3, size // 2 + 0.2)
    e = 0.1
    J = np.stack([(base(c[0] + e, c[1]) - base(c[0] - e, c[1])) / (2 * e),
                  (base(c[0], c[1] + e) - base(c[0], c[1] - e)) / (2 * e),
                  base(*c) / amplitude, np.ones((size, size))], -1).reshape(-1, 4)
    fim = J.T @ J / sigma ** 2
    return float(np.sqrt(np.linalg.inv(fim)[0, 0]))


def centre_precision(snr: float, n: int) -> dict:
    """Per-axis RMS centre error of isolated discs through the whole detector, over the CRB."""
    rng = np.random.default_rng(int(snr))
    A, size = 100.0, 48
    sigma = A / snr
    errs = []
    for _ in range(n):
        img, c = disc_image(rng, size, 4.0, 1.0, A, 200.0, sigma, dark=True)
        r = detect(np.clip(np.rint(img), 0, 255).astype(np.uint8))
        if len(r):
            k = np.argmin(np.hypot(r["x"] - c[0], r["y"] - c[1]))
            errs.append((r["x"][k] - c[0], r["y"][k] - c[1]))
    e = np.array(errs)
    rms = float(np.sqrt((e ** 2).mean()))
    # uint8 rounding adds 1/12 grey level^2 of noise: the bound is for the total.
    bound = crb(sigma=float(np.sqrt(sigma ** 2 + 1 / 12)))
    return _row(f"blobs_crb_ratio_snr{int(snr)}", rms / bound, "ratio", "<= 1.5", rms / bound <= 1.5,
                rms_px=rms, crb_px=bound, guide_crb_px=0.49 * sigma / A, found=len(e), trials=n)


def speed(data: list[np.ndarray]) -> list[dict]:
    """Frames/s of one colour (black, the default), fitting included: one thread, and the range operation's pool."""
    workers = os.cpu_count() or 1
    detect(data[0])  # load the model and the compiled kernels
    t, c = time.perf_counter(), time.thread_time()
    for img in data:
        detect(img)
    one = len(data) / (time.perf_counter() - t)
    cpu_ms = 1000.0 * (time.thread_time() - c) / len(data)
    from carapost.core.blob_ops import detect_frames
    from carapost.core.properties import Properties

    props = Properties()
    # A run on one frame (the pool's start-up plus one frame), then one on >= 48 frames: the
    # difference is the steady rate of a long take.  Best of 3 (ours and the baseline alike):
    # other jobs on the machine only ever slow a run down.
    many = data * max(1, -(-48 // len(data)))
    sbd = simple_blob_detector(False)
    ours = wall = base = 0.0
    startup = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        detect_frames(enumerate(data[:1]), props, workers)
        t1 = time.perf_counter()
        detect_frames(enumerate(many), props, workers)
        t2 = time.perf_counter()
        rate = (len(many) - 1) / max((t2 - t1) - (t1 - t0), 1e-6)
        if rate > ours:
            ours, wall = rate, len(many) / (t2 - t1)
        startup = min(startup, max((t1 - t0) - 1.0 / max(rate, 1e-6), 0.0))
        t = time.perf_counter()
        with ThreadPoolExecutor(workers) as pool:
            list(pool.map(sbd.detect, data * 2))
        base = max(base, 2 * len(data) / (time.perf_counter() - t))
    load = os.getloadavg()[0]
    return [_row("blobs_fps", ours, "frames/s", ">= 240", ours >= 240, threads=workers, single_thread_fps=one,
                 single_image_ms=1000.0 / one, single_image_cpu_ms=cpu_ms, pool_startup_s=startup,
                 fps_with_startup=wall, frames=len(many),
                 baseline="SimpleBlobDetector", baseline_value=base, load_average=load,
                 size=f"{data[0].shape[1]}x{data[0].shape[0]}")]


def run(quick: bool = False) -> list[dict]:
    rows = []
    for white in (False, True):
        data = takes(white, seeds=(0,) if quick else (0, 1, 2), frames=1 if quick else 3)
        rows += accuracy(white, data)
        if white is False:
            sample_images = [s.image for s in data]
        rows += accuracy(white, frames(2 if quick else 8, white), prefix="_clutter", hidden_px=10.0)
        rows += accuracy(white, large_frames(2 if quick else 8, white), prefix="_large", hidden_px=10.0, by_size=True)
    for snr in (15, 50, 150):
        rows.append(centre_precision(snr, 60 if quick else 400))
    rows += speed(sample_images[:6] if quick else sample_images[:24])
    return rows


if __name__ == "__main__":
    import json

    for r in run(quick="--quick" in sys.argv):
        print(json.dumps(r))
