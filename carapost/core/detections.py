"""Blob detections of one sensor over the whole take, stored as arrays.

A take holds tens of millions of detections, so they live in one structured
array per sensor in frame order (CSR layout: ``offsets[f]:offsets[f+1]`` are
frame ``f``'s records), memory-mapped from the project file.  Replacing one
frame's detections must not copy the whole array, so replaced frames sit in an
overlay dict until the next save consolidates them.
"""
from __future__ import annotations

from typing import Iterator

import numpy as np

#: One detection: centre (raw image pixels), ellipse axes (pixels, full lengths),
#: angle (degrees, of the major axis from +x towards +y), probability score, colour.
#: 17 bytes: a ten-minute take holds ~30 million of them, so shape and score are
#: half floats (0.06 px at 100 px, 0.1 degree, 0.0005 in score); centres stay float32.
DET_DTYPE = np.dtype(
    [("x", "<f4"), ("y", "<f4"), ("major", "<f2"), ("minor", "<f2"),
     ("angle", "<f2"), ("score", "<f2"), ("color", "u1")]
)
COLOR_BLACK = 0
COLOR_WHITE = 1


def make_detections(x, y, major=None, minor=None, angle=None, score=None, color=COLOR_BLACK) -> np.ndarray:
    """Build a detection record array from columns (scalars broadcast).

    Parameters
    ----------
    x, y : array_like
        Centres in raw image pixels.
    major, minor, angle, score, color : array_like, optional
        Ellipse full axes (default 8 px), angle in degrees (0), score (1), colour (black).

    Returns
    -------
    numpy.ndarray
        Records of :data:`DET_DTYPE`.
    """
    x = np.atleast_1d(np.asarray(x, dtype=np.float32))
    n = x.shape[0]
    out = np.zeros(n, DET_DTYPE)
    out["x"] = x
    out["y"] = y
    out["major"] = 8.0 if major is None else major
    out["minor"] = out["major"] if minor is None else minor
    out["angle"] = 0.0 if angle is None else angle
    out["score"] = 1.0 if score is None else score
    out["color"] = color
    return out


class DetectionTable:
    """Detections of one sensor, frame by frame.

    Parameters
    ----------
    frame_count : int
        Frames in the take.
    records : numpy.ndarray, optional
        All detections in frame order (:data:`DET_DTYPE`), possibly a memory map.
    offsets : numpy.ndarray, optional
        ``int64`` array of ``frame_count + 1`` record offsets.
    """

    def __init__(self, frame_count: int, records: np.ndarray | None = None, offsets: np.ndarray | None = None):
        self.frame_count = int(frame_count)
        if records is None:
            records = np.zeros(0, DET_DTYPE)
            offsets = np.zeros(self.frame_count + 1, np.int64)
        if offsets is None or len(offsets) != self.frame_count + 1:
            raise ValueError("offsets must have frame_count + 1 entries")
        self._records = records
        self._offsets = offsets
        self._overlay: dict[int, np.ndarray] = {}
        # Frames that were never run through detection differ from frames with none found.
        self._detected = np.zeros(self.frame_count, bool)

    # ----------------------------------------------------------------- access
    def frame(self, f: int) -> np.ndarray:
        """Detections of frame ``f`` (a read-only view; use :meth:`set_frame` to change)."""
        arr = self._overlay.get(f)
        if arr is None:
            arr = self._records[self._offsets[f]:self._offsets[f + 1]]
        v = arr.view()
        v.flags.writeable = False
        return v

    def count(self, f: int) -> int:
        """Number of detections on frame ``f``."""
        arr = self._overlay.get(f)
        return len(arr) if arr is not None else int(self._offsets[f + 1] - self._offsets[f])

    def counts(self) -> np.ndarray:
        """Detections per frame, ``(frame_count,)`` int64."""
        c = np.diff(self._offsets)
        for f, arr in self._overlay.items():
            c[f] = len(arr)
        return c

    def total(self) -> int:
        """All detections of the take."""
        return int(self.counts().sum())

    @property
    def detected(self) -> np.ndarray:
        """``(frame_count,)`` bool: blob detection has run on the frame."""
        return self._detected

    def set_frame(self, f: int, records: np.ndarray, detected: bool = True) -> None:
        """Replace frame ``f``'s detections (callers go through a command for undo)."""
        if records.dtype != DET_DTYPE:
            records = np.asarray(records).astype(DET_DTYPE)
        self._overlay[f] = np.array(records, DET_DTYPE, copy=True)
        self._detected[f] = detected

    def iter_frames(self) -> Iterator[np.ndarray]:
        """Every frame's records in order, without consolidating."""
        for f in range(self.frame_count):
            yield self.frame(f)

    # ------------------------------------------------------------ persistence
    def write_chunks(self) -> tuple[np.ndarray, list[np.ndarray]]:
        """Offsets and the record chunks, in order, that together form the consolidated array.

        Runs of frames untouched since loading are one chunk each, so saving
        streams the memory map instead of copying it.
        """
        counts = self.counts()
        offsets = np.zeros(self.frame_count + 1, np.int64)
        np.cumsum(counts, out=offsets[1:])
        chunks: list[np.ndarray] = []
        run_start = 0
        for f in sorted(self._overlay):
            if f > run_start:
                chunks.append(self._records[self._offsets[run_start]:self._offsets[f]])
            chunks.append(self._overlay[f])
            run_start = f + 1
        if run_start < self.frame_count:
            chunks.append(self._records[self._offsets[run_start]:self._offsets[self.frame_count]])
        return offsets, [c for c in chunks if len(c)]

    def consolidate(self) -> None:
        """Fold the overlay into one array (used after bulk operations)."""
        offsets, chunks = self.write_chunks()
        self._records = np.concatenate(chunks) if chunks else np.zeros(0, DET_DTYPE)
        self._offsets = offsets
        self._overlay.clear()

    def nbytes_overlay(self) -> int:
        """Memory held by replaced frames."""
        return sum(a.nbytes for a in self._overlay.values())
