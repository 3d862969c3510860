"""Continuity of points: the colours of the Continuity chart and the Selected Point pane (Qt-free).

Every frame of a point gets a small integer *code*; a 256-entry RGBA table
(:data:`LUT`) turns codes into colours.  Codes rather than colours are cached
(one byte per frame instead of four) and they are ordered by *importance*: when
the chart shows more frames than it has screen columns, a column takes the
smallest code of its frames, so a one-frame gap or keyframe stays visible at
any zoom.

Point bar (the 3D sample and how many channels support it):

============  =====================================================
dark green    3D point with 2D data in 4 (or more) channels
light green   3 channels
yellow        2 channels
orange        1 channel (single-sensor tracking, or interpolation with one channel)
red           0 channels: an interpolated / predicted 3D point
gap           no 3D point
============  =====================================================

Channel rows (one per sensor, from ``Point.src``):

============  =====================================================
dark blue     blob detection (``SRC_DETECTION``)
light blue    patch track (``SRC_PATCH``)
white         target-track keyframe (``SRC_KEYFRAME``, or a ``Point.keyframes`` entry)
green .. red  target-track sample (``SRC_TARGET``) coloured by its match score (1 green, 0 red)
gap           no 2D sample
============  =====================================================
"""
from __future__ import annotations

import numpy as np

from .points import SRC_DETECTION, SRC_KEYFRAME, SRC_NONE, SRC_PATCH, SRC_TARGET, ST_NONE, Point

# ----------------------------------------------------------------- codes (lower wins when frames are binned)
C_KEY = 0          #: keyframe (white)
C_GAP = 1          #: nothing (transparent)
C_RED = 2          #: interpolated 3D point, no channel
C_ORANGE = 3       #: 1 channel
C_YELLOW = 4       #: 2 channels
C_LGREEN = 5       #: 3 channels
C_DGREEN = 6       #: 4 channels
C_TARGET0 = 8      #: target sample of score 0; score s has code C_TARGET0 + round(s * TARGET_STEPS)
TARGET_STEPS = 31
C_PATCH = C_TARGET0 + TARGET_STEPS + 1   #: patch track (light blue)
C_BLOB = C_PATCH + 1                     #: blob detection (dark blue)
C_PAD = 255        #: outside the take (transparent; never wins a bin)

#: RGBA of each colour.
COLORS = {
    "key": (255, 255, 255, 255),
    "gap": (0, 0, 0, 0),
    "red": (220, 30, 30, 255),
    "orange": (255, 140, 0, 255),
    "yellow": (235, 215, 0, 255),
    "light_green": (120, 215, 90, 255),
    "dark_green": (0, 120, 40, 255),
    "patch": (120, 190, 255, 255),
    "blob": (20, 50, 190, 255),
}
_TARGET_BAD = np.array([230, 20, 20, 255], float)    # score 0
_TARGET_GOOD = np.array([40, 255, 40, 255], float)   # score 1


def _make_lut() -> np.ndarray:
    lut = np.zeros((256, 4), np.uint8)
    for code, name in ((C_KEY, "key"), (C_GAP, "gap"), (C_RED, "red"), (C_ORANGE, "orange"),
                       (C_YELLOW, "yellow"), (C_LGREEN, "light_green"), (C_DGREEN, "dark_green"),
                       (C_PATCH, "patch"), (C_BLOB, "blob")):
        lut[code] = COLORS[name]
    t = np.linspace(0.0, 1.0, TARGET_STEPS + 1)[:, None]
    lut[C_TARGET0:C_TARGET0 + TARGET_STEPS + 1] = np.round(_TARGET_BAD * (1 - t) + _TARGET_GOOD * t)
    lut[C_PAD] = 0
    return lut


#: code -> RGBA (uint8).
LUT = _make_lut()

#: Point-bar code by (has 3D point) * 8 + min(channels, 4).
_BAR = np.full(16, C_GAP, np.uint8)
_BAR[8:13] = (C_RED, C_ORANGE, C_YELLOW, C_LGREEN, C_DGREEN)
#: Channel code by source (target samples are coloured by score afterwards).
_SRC = np.full(256, C_GAP, np.uint8)
_SRC[SRC_NONE], _SRC[SRC_DETECTION], _SRC[SRC_PATCH], _SRC[SRC_KEYFRAME] = C_GAP, C_BLOB, C_PATCH, C_KEY
_SRC[SRC_TARGET] = C_TARGET0 + TARGET_STEPS


def _make_score_lut() -> np.ndarray:
    """Target-sample code of every float16 score (by its bit pattern): NaN counts as a good score."""
    v = np.arange(1 << 16, dtype=np.uint16).view(np.float16).astype(np.float32)
    v = np.fmax(np.fmin(v, 1.0), 0.0)
    return (C_TARGET0 + np.rint(v * TARGET_STEPS)).astype(np.uint8)


_SCORE = _make_score_lut()


def _score_codes(score: np.ndarray) -> np.ndarray:
    if score.dtype == np.float16:
        return _SCORE.take(score.view(np.uint16))
    v = np.fmax(np.fmin(score.astype(np.float32), 1.0), 0.0)
    return (C_TARGET0 + np.rint(v * TARGET_STEPS)).astype(np.uint8)


def target_color(score: float) -> tuple[int, int, int, int]:
    """RGBA of a target-track sample of match ``score`` (0 red .. 1 green)."""
    s = 1.0 if not np.isfinite(score) else min(max(float(score), 0.0), 1.0)
    return tuple(int(v) for v in LUT[C_TARGET0 + int(round(s * TARGET_STEPS))])


# ------------------------------------------------------------------ per point
def _channel_count(src: np.ndarray) -> np.ndarray:
    """``(F,)`` number of sensors with a 2D sample (uint32)."""
    F, S = src.shape
    if S == 4 and src.flags.c_contiguous:
        # four 0/1 bytes per frame read as one uint32: multiplying by 0x01010101 sums them in the top byte
        m = (src != SRC_NONE).view("<u4").reshape(F)
        return (m * np.uint32(0x01010101)) >> np.uint32(24)
    n = np.zeros(F, np.uint32)
    for s in range(S):
        n += src[:, s] != SRC_NONE
    return n


def point_codes(point: Point) -> np.ndarray:
    """``(F,)`` uint8 point-bar codes of ``point``."""
    n = _channel_count(point.src).astype(np.uint8)
    np.minimum(n, 4, out=n)
    n += 1                                   # C_RED + channels - C_GAP
    n *= point.status != ST_NONE             # no 3D point: 0
    n += C_GAP
    return n


def channel_codes(point: Point) -> np.ndarray:
    """``(S, F)`` uint8 channel-row codes of ``point``."""
    src = point.src
    codes = _SRC.take(src)
    tgt = src == SRC_TARGET
    if tgt.any():
        codes += tgt * (_score_codes(point.score) - codes)    # uint8 arithmetic wraps: exact
    codes = np.ascontiguousarray(codes.T)
    for (f, s) in point.keyframes:
        if 0 <= f < point.frames and 0 <= s < point.sensors:
            codes[s, f] = C_KEY
    return codes


def point_rgba(point: Point) -> np.ndarray:
    """``(F, 4)`` uint8 RGBA of the point bar."""
    return LUT[point_codes(point)]


def channel_rgba(point: Point) -> np.ndarray:
    """``(S, F, 4)`` uint8 RGBA of the channel rows."""
    return LUT[channel_codes(point)]


def rgba(codes: np.ndarray) -> np.ndarray:
    """Colours of an array of codes (a trailing axis of 4 is added)."""
    return LUT[codes]


def halve(codes: np.ndarray) -> np.ndarray:
    """Codes binned by two frames (the more important code of each pair wins)."""
    if len(codes) % 2:
        codes = np.append(codes, np.uint8(C_PAD))
    return np.minimum(codes[0::2], codes[1::2])


# ------------------------------------------------------------------ the cache
class ContinuityModel:
    """Codes of a project's points, computed on demand and cached per point.

    Each row (a point bar, or one channel of a point) is cached with its
    *pyramid*: level ``k`` bins ``2**k`` frames per code, so a chart that shows
    a ten-minute take in 2,000 screen columns reads 2,250 codes per row instead
    of 36,000.  Call :meth:`invalidate` when the project changes (all points, or
    the ids an edit touched); rows are recomputed the next time they are asked for.

    Parameters
    ----------
    project : Project
    """

    def __init__(self, project=None):
        self.project = project
        #: (pid, channel) -> (point object, [level 0, level 1, ...])
        self._rows: dict[tuple[int, int], tuple[Point, list[np.ndarray]]] = {}

    def set_project(self, project) -> None:
        if project is not self.project:
            self.project = project
            self.invalidate()

    def invalidate(self, ids=None) -> None:
        """Forget cached rows (of ``ids``; all when None)."""
        if ids is None:
            self._rows.clear()
        else:
            ids = set(ids)
            for key in [k for k in self._rows if k[0] in ids]:
                del self._rows[key]

    @property
    def frames(self) -> int:
        return self.project.frame_count if self.project is not None else 0

    @property
    def sensors(self) -> int:
        return self.project.sensor_count if self.project is not None else 0

    def _levels(self, pid: int, channel: int) -> list[np.ndarray]:
        pt = self.project.points[pid]
        hit = self._rows.get((pid, channel))
        if hit is None or hit[0] is not pt:
            if channel < 0:
                hit = self._rows[(pid, -1)] = (pt, [point_codes(pt)])
            else:
                for ch, codes in enumerate(channel_codes(pt)):
                    self._rows[(pid, ch)] = (pt, [codes])
                hit = self._rows[(pid, channel)]
        return hit[1]

    def row(self, pid: int, channel: int = -1, level: int = 0) -> np.ndarray:
        """Codes of one row: the point bar (``channel`` -1) or one channel; ``level``: 2**level frames per code."""
        levels = self._levels(pid, channel)
        while len(levels) <= level:
            levels.append(halve(levels[-1]))
        return levels[level]

    def bar(self, pid: int) -> np.ndarray:
        """``(F,)`` codes of point ``pid``'s bar."""
        return self.row(pid, -1)

    def channels(self, pid: int) -> np.ndarray:
        """``(S, F)`` codes of point ``pid``'s channel rows."""
        return np.stack([self.row(pid, ch) for ch in range(self.sensors)])

    def codes(self, rows, start: int = 0, stop: int | None = None, columns: int | None = None
              ) -> tuple[np.ndarray, int, int]:
        """Codes of ``rows`` (``(pid, channel)`` pairs) over frames ``[start, stop)``.

        With ``columns`` smaller than the frame count, frames are binned by a
        power of two (the most important code of a bin wins) so that at most
        ``columns`` columns come back.

        Returns
        -------
        codes : ndarray (len(rows), C) uint8
        bin : int
            Frames per column.
        first : int
            First frame of column 0 (column ``c`` covers ``first + c*bin ... first + (c+1)*bin - 1``).
        """
        F = self.frames
        stop = F if stop is None else min(int(stop), F)
        start = min(max(0, int(start)), stop)
        n = stop - start
        level = 0
        if columns:
            while n > 0 and -(-n // (1 << level)) > max(int(columns), 1):
                level += 1
        b = 1 << level
        c0, c1 = start // b, -(-stop // b)
        out = np.empty((len(rows), c1 - c0), np.uint8)
        for r, (pid, ch) in enumerate(rows):
            out[r] = self.row(pid, ch, level)[c0:c1]
        return out, b, c0 * b

    def image(self, rows, start: int = 0, stop: int | None = None, columns: int | None = None
              ) -> tuple[np.ndarray, int, int]:
        """Like :meth:`codes` but RGBA: ``(len(rows), C, 4)`` uint8, the bin and the first frame."""
        codes, b, first = self.codes(rows, start, stop, columns)
        return LUT[codes], b, first
