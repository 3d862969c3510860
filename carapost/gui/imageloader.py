"""Channel images for the camera views, decoded off the GUI thread.

Take frame ``f`` of sensor ``s`` is media frame ``f - image_offset``.  A cached
frame is returned at once; a missing one is decoded by the shared
:class:`~carapost.io.framecache.FrameCache` in its worker threads and
:attr:`ImageLoader.imageReady` tells the views when it is there, so scrubbing
a long-GOP ``.pico`` never blocks the window.
"""
from __future__ import annotations

import logging

import numpy as np
from PySide6.QtCore import QObject, Signal

log = logging.getLogger("carapost")

#: Frames decoded ahead of the one asked for (playback and stepping go forwards).
READ_AHEAD = 6


class ImageLoader(QObject):
    """Frame sources of the take's channels and the frame cache.

    Parameters
    ----------
    cache : FrameCache, optional
        Shared cache (a 512 MB one is made when None).
    synchronous : bool
        Decode in the calling thread (screenshots, tests, benchmarks).
    """

    imageReady = Signal(int)  #: sensor whose image arrived

    def __init__(self, cache=None, synchronous: bool = False, parent=None):
        super().__init__(parent)
        if cache is None:
            from ..io.framecache import FrameCache

            cache = FrameCache(512)
        self.cache = cache
        self.synchronous = synchronous
        self.sources: list = []
        self.offsets: list[int] = []
        self._pending: set[tuple[int, int]] = set()
        self._failed: set[int] = set()

    def set_sources(self, sources: list, offsets: list[int]) -> None:
        """Channel sources (None where a channel has no media) and their image offsets."""
        self.close_sources()
        self.sources = list(sources)
        self.offsets = list(offsets)
        self._pending.clear()
        self._failed.clear()

    def set_offsets(self, offsets: list[int]) -> None:
        self.offsets = list(offsets)

    def has_media(self, sensor: int) -> bool:
        return 0 <= sensor < len(self.sources) and self.sources[sensor] is not None

    def media_index(self, sensor: int, frame: int) -> int | None:
        """Media frame shown on take frame ``frame`` (None outside the media)."""
        if not self.has_media(sensor):
            return None
        i = frame - self.offsets[sensor]
        return i if 0 <= i < self.sources[sensor].frame_count else None

    def image(self, sensor: int, frame: int) -> np.ndarray | None:
        """The image of take frame ``frame``, or None (no media, or still decoding: watch imageReady)."""
        i = self.media_index(sensor, frame)
        if i is None:
            return None
        src = self.sources[sensor]
        if self.synchronous or self.cache.contains(src, i):
            return self._read(sensor, i)
        key = (sensor, i)
        if key not in self._pending:
            self._pending.add(key)
            ahead = [j for j in range(i, min(i + READ_AHEAD, src.frame_count))]
            fut = self.cache.prefetch(src, ahead)
            fut.add_done_callback(lambda _f, k=key: self._arrived(k))
        return None

    def _read(self, sensor: int, i: int) -> np.ndarray | None:
        from ..core.errors import CaraError

        try:
            return self.cache.get(self.sources[sensor], i)
        except (CaraError, IndexError, OSError) as e:
            if sensor not in self._failed:       # one line per channel, not one per frame
                self._failed.add(sensor)
                log.error(f"channel {sensor}: cannot read frame {i}: {e}")
            return None

    def _arrived(self, key) -> None:
        # Runs in a cache worker thread: the signal is queued to the GUI thread.
        self._pending.discard(key)
        self.imageReady.emit(key[0])

    def pixel(self, sensor: int, frame: int, x: float, y: float) -> int | None:
        """Grey level at raw pixel (x, y) of the cached image, or None."""
        i = self.media_index(sensor, frame)
        if i is None or not self.cache.contains(self.sources[sensor], i):
            return None
        img = self.cache.get(self.sources[sensor], i)
        c, r = int(round(x)), int(round(y))
        if 0 <= r < img.shape[0] and 0 <= c < img.shape[1]:
            return int(img[r, c])
        return None

    def close_sources(self) -> None:
        for s in self.sources:
            if s is not None:
                self.cache.clear(s)
                try:
                    s.close()
                except Exception:  # noqa: BLE001 - closing a broken decoder must not stop the window
                    pass
        self.sources = []


def open_sources(project) -> list:
    """Open each sensor's media (None where missing or unreadable, with a log line naming it)."""
    try:
        from ..io.media import open_source
    except ImportError:  # the media module is not in this build
        return [None] * project.sensor_count
    from ..core.errors import CaraError

    out = []
    for i, s in enumerate(project.sensors):
        src = None
        if s.media.path and not s.media.missing:
            try:
                src = open_source(s.media.path)
            except CaraError as e:
                log.warning(f"channel {i}: {e}")
        elif s.media.path:
            log.warning(f"channel {i}: media not found: {s.media.path} (Edit > Relocate Files)")
        out.append(src)
    return out
