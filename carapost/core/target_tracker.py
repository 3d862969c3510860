"""The Target Tracker's engine: one point in one sensor, frame by frame, by pattern matching.

The guide's target tracker matches the pattern of the user's keyframe (the
blue box) at every location of the comparison region (the green cross) in the
next frame.  Here:

- the pattern of a keyframe is the ``(2 pw + 1) x (2 ph + 1)`` patch around its
  2D position (sub-pixel, :func:`carapost.core.tracking.patch.extract`), ``pw``,
  ``ph`` the box's pattern half sizes;
- the comparison region is the search box (half sizes ``sw``, ``sh``) centred on
  the position predicted from the last two tracked frames (constant velocity):
  the pattern is compared at every offset that keeps it inside the region, that
  is within ``sw - pw`` by ``sh - ph`` pixels of the prediction (at least
  :data:`MIN_RADIUS`);
- the comparison is OpenCV's zero-mean normalised cross-correlation
  (``TM_CCOEFF_NORMED``, the one :mod:`carapost.core.tracking.patch` uses), and
  the score of a frame is its value at the sub-pixel peak (parabola through the
  peak and its neighbours), clipped to 0-1;
- between two keyframes the frame is matched against both, weighted by how
  close each is (``w_prev = d_next / (d_prev + d_next)``), so the pattern fades
  from the one to the other across a gap (a closing eyelid changes its look);
- a peak on the edge of the searched offsets means the marker moved further
  than predicted: the search is repeated once around that peak;
- tracking stops (in that sensor) when the score falls below the Break
  Threshold, when the pattern leaves the image, or when the keyframe pattern is
  flat (no texture to match).

:class:`SensorTracker` holds the state carried from frame to frame; the
project-level commands (Track forward/back, keyframes, Gaps To Keys) are in
:mod:`carapost.core.target_ops`.  Nothing here knows about projects or Qt.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import cv2
import numpy as np

from .tracking import patch

#: Half sizes (pattern w, h, search w, h) in pixels; see ``editing.DEFAULT_KEYFRAME_BOX``.
Box = tuple[float, float, float, float]

#: Smallest search offset (px) either way, however tight the boxes are.
MIN_RADIUS = 2
#: Resample-and-refit steps of the sub-pixel peak (see ``_refine``).
REFINE_STEPS = 2
#: Patterns with a grey-level standard deviation below this cannot be matched.
FLAT_STD = 1.0

# Why a sensor's track ended.
STOP_SCORE = "score"        #: best match below the Break Threshold
STOP_EDGE = "edge"          #: the comparison region left the image
STOP_FLAT = "flat"          #: the keyframe pattern has no texture


@dataclass(frozen=True)
class Keyframe:
    """A keyframe of one sensor: frame, raw 2D position and box half sizes."""

    frame: int
    uv: tuple[float, float]
    box: Box


@dataclass(frozen=True)
class Step:
    """What one frame gave: position (NaN when stopped), score and why it stopped (``""``: tracked)."""

    frame: int
    uv: np.ndarray
    score: float
    stop: str = ""
    keyframe: bool = False     #: the frame is a keyframe of this sensor (its sample is kept as it is)


def pattern_size(box: Box) -> tuple[int, int]:
    """``(w, h)`` in pixels (odd, at least 3) of the pattern of ``box``."""
    return (2 * max(1, int(round(box[0]))) + 1, 2 * max(1, int(round(box[1]))) + 1)


def search_radius(box: Box) -> tuple[int, int]:
    """Offsets ``(rx, ry)`` (px) searched either way of the prediction for ``box``."""
    return (max(MIN_RADIUS, int(round(box[2] - box[0]))), max(MIN_RADIUS, int(round(box[3] - box[1]))))


def make_pattern(img: np.ndarray, uv, box: Box) -> np.ndarray | None:
    """The float32 pattern of ``box`` around ``uv`` in ``img``; None when it is flat or leaves the image."""
    w, h = pattern_size(box)
    H, W = img.shape[:2]
    if not (w // 2 <= uv[0] <= W - 1 - w // 2 and h // 2 <= uv[1] <= H - 1 - h // 2):
        return None
    p = patch.extract(img, uv, (w, h))
    return p if float(p.std()) >= FLAT_STD else None


def keyframe_weights(frame: int, prev_frame: int, next_frame: int | None) -> tuple[float, float]:
    """Weights of the previous and next keyframe's patterns on ``frame`` (the nearer counts more)."""
    if next_frame is None:
        return 1.0, 0.0
    dp, dn = abs(frame - prev_frame), abs(next_frame - frame)
    return dn / (dp + dn), dp / (dp + dn)


def match(img: np.ndarray, centre, patterns: Sequence[np.ndarray], weights: Sequence[float],
          radius: tuple[int, int]) -> tuple[np.ndarray, float, bool] | None:
    """Best weighted match of ``patterns`` within ``radius`` of ``centre``.

    Parameters
    ----------
    img : ndarray (H, W)
        Grey image.
    centre : (x, y)
        Predicted raw position.
    patterns : sequence of ndarray
        Odd-sized float32 patterns (sizes may differ).
    weights : sequence of float
        One per pattern, summing to 1.
    radius : (rx, ry)
        Offsets searched either way.

    Returns
    -------
    (uv, score, on_edge) or None
        Sub-pixel raw position, weighted NCC at the peak and whether the
        peak is on the edge of the searched offsets; None when the region
        leaves the image.
    """
    rx, ry = radius
    cx, cy = float(np.round(centre[0])), float(np.round(centre[1]))
    H, W = img.shape[:2]
    res = None
    for pat, w in zip(patterns, weights):
        if w <= 0:
            continue
        ph, pw = pat.shape
        hx, hy = pw // 2 + rx, ph // 2 + ry
        if not (hx <= cx <= W - 1 - hx and hy <= cy <= H - 1 - hy):
            return None
        win = patch.extract(img, (cx, cy), (2 * hx + 1, 2 * hy + 1))
        r = cv2.matchTemplate(win, pat, cv2.TM_CCOEFF_NORMED)
        res = w * r if res is None else res + w * r
    x, y, score = patch.peak(res)
    on_edge = not (0 < round(x) < 2 * rx and 0 < round(y) < 2 * ry)
    uv = np.array([cx + x - rx, cy + y - ry])
    if not on_edge:
        uv, score = _refine(img, uv, patterns, weights, score)
    return uv, min(1.0, max(0.0, float(score))), on_edge


def _refine(img, uv, patterns, weights, score):
    """Re-centre on the sub-pixel peak and fit again until the correction vanishes.

    A parabola through a correlation peak is biased towards the nearest whole
    pixel (up to ~0.3 px for a marker-sized blob); resampling the image at the
    estimate and fitting the small remaining offset removes most of it.
    """
    for _ in range(REFINE_STEPS):
        res = None
        for pat, w in zip(patterns, weights):
            if w <= 0:
                continue
            ph, pw = pat.shape
            r = cv2.matchTemplate(patch.extract(img, uv, (pw + 2, ph + 2)), pat, cv2.TM_CCOEFF_NORMED)
            res = w * r if res is None else res + w * r
        x, y, value = patch.peak(res)
        if not (0.5 <= x <= 1.5 and 0.5 <= y <= 1.5):
            break               # the fit moved a whole pixel: keep the first estimate
        uv, score = uv + (x - 1.0, y - 1.0), value
        if abs(x - 1.0) + abs(y - 1.0) < 0.01:
            break
    return uv, score


class SensorTracker:
    """Tracks one point in one sensor from a start frame, one frame per :meth:`step`.

    Parameters
    ----------
    image : callable
        ``image(frame) -> (H, W) uint8`` grey image of this sensor.
    start_frame : int
    start_uv : (x, y)
        The point's raw 2D position on ``start_frame`` (where tracking starts).
    direction : {+1, -1}
    keyframes : sequence of Keyframe
        This sensor's keyframes (any order).  Patterns come from the keyframe
        behind each frame and the one ahead of it; without a keyframe behind
        the start, the start sample's patch (of ``default_box``) is the pattern.
    break_threshold : float
        Tracking stops when the best score is below this.
    default_box : Box
        Box of the start sample when it is not a keyframe and none is behind it.
    """

    def __init__(self, image: Callable[[int], np.ndarray], start_frame: int, start_uv, direction: int,
                 keyframes: Sequence[Keyframe], break_threshold: float, default_box: Box):
        self.image = image
        self.direction = 1 if direction > 0 else -1
        self.threshold = float(break_threshold)
        self.keys = {k.frame: k for k in keyframes}
        self._order = sorted(self.keys, key=lambda f: f * self.direction)     # in tracking order
        self._patterns: dict[Keyframe, np.ndarray | None] = {}
        self.frame = int(start_frame)
        self.uv = np.asarray(start_uv, float)
        self.velocity = np.zeros(2)
        self.stopped = ""
        behind = self._behind(self.frame, inclusive=True)
        if behind is None:
            # The start sample itself is the pattern (not stored as a keyframe).
            ahead = self._ahead(self.frame)
            box = self.keys[ahead].box if ahead is not None else default_box
            self._start_key = Keyframe(self.frame, tuple(self.uv), box)
        else:
            self._start_key = None

    # ------------------------------------------------------------ keyframes
    def _behind(self, frame: int, inclusive: bool) -> int | None:
        d = self.direction
        cands = [f for f in self._order if (f - frame) * d < 0 or (inclusive and f == frame)]
        return cands[-1] if cands else None

    def _ahead(self, frame: int) -> int | None:
        d = self.direction
        return next((f for f in self._order if (f - frame) * d > 0), None)

    def _pattern(self, key: Keyframe) -> np.ndarray | None:
        if key not in self._patterns:
            self._patterns[key] = make_pattern(self.image(key.frame), key.uv, key.box)
        return self._patterns[key]

    # ------------------------------------------------------------ tracking
    def step(self) -> Step:
        """Track into the next frame; once stopped, every step returns the stop again."""
        f = self.frame + self.direction
        nan = np.array([np.nan, np.nan])
        if self.stopped:
            return Step(f, nan, 0.0, self.stopped)
        if f in self.keys:
            # A keyframe is the user's word: the track passes through it unchanged.
            k = self.keys[f]
            uv = np.asarray(k.uv, float)
            self.velocity, self.uv, self.frame = uv - self.uv, uv, f
            return Step(f, uv, 1.0, keyframe=True)
        behind = self._behind(f, inclusive=False)
        prev_key = self.keys[behind] if behind is not None else self._start_key
        if self._start_key is not None and behind is not None:
            self._start_key = None           # a real keyframe is behind now
        nxt = self._ahead(f)
        next_key = self.keys[nxt] if nxt is not None else None
        pats, weights = [], []
        wp, wn = keyframe_weights(f, prev_key.frame, next_key.frame if next_key else None)
        for key, w in ((prev_key, wp), (next_key, wn)):
            if key is None or w <= 0:
                continue
            pat = self._pattern(key)
            if pat is not None:
                pats.append(pat)
                weights.append(w)
        if not pats:
            return self._stop(f, STOP_FLAT)
        total = sum(weights)
        weights = [w / total for w in weights]
        img = self.image(f)
        radius = search_radius(prev_key.box)
        pred = self.uv + self.velocity
        got = match(img, pred, pats, weights, radius)
        if got is not None and got[2]:
            again = match(img, got[0], pats, weights, radius)
            if again is not None and again[1] > got[1]:
                got = again
        if got is None:
            return self._stop(f, STOP_EDGE)
        uv, score, _edge = got
        if score < self.threshold:
            return self._stop(f, STOP_SCORE, score)
        self.velocity, self.uv, self.frame = uv - self.uv, uv, f
        return Step(f, uv, score)

    def _stop(self, f: int, why: str, score: float = 0.0) -> Step:
        self.stopped = why
        return Step(f, np.array([np.nan, np.nan]), score, why)


def track_sequence(images: Callable[[int], np.ndarray], start_frame: int, start_uv, direction: int, count: int,
                   keyframes: Sequence[Keyframe], break_threshold: float = 0.9,
                   default_box: Box = (8.0, 8.0, 16.0, 16.0)) -> tuple[np.ndarray, np.ndarray, str]:
    """Track up to ``count`` frames from ``start_frame``; stops early where the tracker stops.

    Returns
    -------
    uv : ndarray (count, 2)
        Raw positions of frames ``start + d, start + 2d, ...`` (NaN after a stop).
    score : ndarray (count,)
        Scores (keyframe frames score 1).
    stop : str
        Why it stopped (``""``: it tracked all ``count`` frames).
    """
    tr = SensorTracker(images, start_frame, start_uv, direction, keyframes, break_threshold, default_box)
    uv = np.full((count, 2), np.nan)
    score = np.full(count, np.nan)
    for i in range(count):
        st = tr.step()
        if st.stop:
            return uv, score, st.stop
        uv[i], score[i] = st.uv, st.score
    return uv, score, ""
