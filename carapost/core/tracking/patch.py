"""Grey-level patch comparison and patch tracking (cv2; runs on a thread pool).

Patch Match Size pixels square patches around a marker are compared by
zero-mean normalised cross-correlation (NCC, -1..1): a match needs NCC >=
Patch Match Threshold.  OpenCV releases the GIL, so batches of patch jobs run
on both cores.
"""
from __future__ import annotations

from concurrent.futures import ThreadPoolExecutor

import cv2
import numpy as np

#: Fewer jobs than this run inline (thread hand-off costs more than it saves).
POOL_MIN_JOBS = 8


def extract(img: np.ndarray, xy, size) -> np.ndarray:
    """Float32 patch centred (sub-pixel) on raw pixel ``xy``: ``size`` x ``size``, or ``size = (w, h)``."""
    w, h = (int(size[0]), int(size[1])) if isinstance(size, tuple) else (int(size), int(size))
    return cv2.getRectSubPix(img, (w, h), (float(xy[0]), float(xy[1])), patchType=cv2.CV_32F)


def ncc(a: np.ndarray, b: np.ndarray) -> float:
    """Zero-mean normalised cross-correlation of two equal patches (0 when either is flat)."""
    a = a - a.mean()
    b = b - b.mean()
    den = float(np.sqrt((a * a).sum() * (b * b).sum()))
    return float((a * b).sum() / den) if den > 1e-6 else 0.0


def compare(prev_img, prev_xy, img, xy, size: int) -> float:
    """NCC of the patch at ``prev_xy`` in ``prev_img`` and the one at ``xy`` in ``img``."""
    return ncc(extract(prev_img, prev_xy, size), extract(img, xy, size))


def _subpixel(res: np.ndarray, i: int, j: int) -> tuple[float, float]:
    """Parabola vertex offsets around the integer peak ``res[i, j]``."""
    def vertex(a, b, c):
        den = a - 2 * b + c
        return 0.5 * (a - c) / den if abs(den) > 1e-9 else 0.0
    dy = vertex(res[i - 1, j], res[i, j], res[i + 1, j]) if 0 < i < res.shape[0] - 1 else 0.0
    dx = vertex(res[i, j - 1], res[i, j], res[i, j + 1]) if 0 < j < res.shape[1] - 1 else 0.0
    # min/max: np.clip on scalars costs ~10 us, a third of a small match
    return min(0.5, max(-0.5, float(dx))), min(0.5, max(-0.5, float(dy)))


def peak(res: np.ndarray) -> tuple[float, float, float]:
    """Sub-pixel ``(x, y)`` (column, row of ``res``) and value of the maximum of a correlation map."""
    i, j = np.unravel_index(int(np.argmax(res)), res.shape)
    dx, dy = _subpixel(res, i, j)
    return j + dx, i + dy, float(res[i, j])


def track_patch(prev_img, prev_xy, img, pred_xy, radius: float, size: int) -> tuple[np.ndarray, float]:
    """Find the patch of ``prev_img`` at ``prev_xy`` in ``img`` within ``radius`` of ``pred_xy``.

    Returns
    -------
    xy : ndarray (2,)
        Raw pixels of the best match (sub-pixel).
    score : float
        Its NCC (-1 when nothing was searched).
    """
    r = int(np.ceil(radius))
    if r < 1:
        return np.array([np.nan, np.nan]), -1.0
    templ = extract(prev_img, prev_xy, size)
    if float(templ.std()) < 1e-3:
        return np.array([np.nan, np.nan]), -1.0
    cx, cy = float(np.round(pred_xy[0])), float(np.round(pred_xy[1]))
    win = cv2.getRectSubPix(img, (size + 2 * r, size + 2 * r), (cx, cy), patchType=cv2.CV_32F)
    res = cv2.matchTemplate(win, templ, cv2.TM_CCOEFF_NORMED)
    # Only the disc of the search radius counts.
    yy, xx = np.mgrid[-r:r + 1, -r:r + 1]
    res = np.where(xx * xx + yy * yy <= radius * radius, res, -1.0)
    i, j = np.unravel_index(int(np.argmax(res)), res.shape)
    dx, dy = _subpixel(res, i, j)
    return np.array([cx + j - r + dx, cy + i - r + dy]), float(res[i, j])


class PatchPool:
    """Runs batches of patch jobs on ``workers`` threads.

    Parameters
    ----------
    workers : int
        Threads (2 uses both cores of the target machine).
    """

    def __init__(self, workers: int = 2):
        self.workers = max(1, int(workers))
        self._pool = ThreadPoolExecutor(self.workers) if self.workers > 1 else None

    def map(self, fn, jobs: list) -> list:
        if self._pool is None or len(jobs) < POOL_MIN_JOBS:
            return [fn(*j) for j in jobs]
        return list(self._pool.map(lambda j: fn(*j), jobs))

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None
