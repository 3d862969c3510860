"""Images of a take: sensor ``s`` on take frame ``f``, through the shared frame cache.

Sensor ``s`` shows media frame ``f - image_offset`` (Increment Image Sequence
Offset moves a channel one frame forward).  Frames outside a channel's media
are blank; media that cannot be found give blank frames and one warning.
"""
from __future__ import annotations

import logging

import numpy as np

from ..core.errors import CaraError
from ..core.project import Project
from .framecache import FrameCache
from .media import FrameSource, open_source

log = logging.getLogger("carapost")


class TakeFrames:
    """Random access to a take's images.

    Parameters
    ----------
    project : Project
        The take (its sensors' media paths and offsets are read on every call,
        so relocating media or shifting offsets takes effect at once).
    cache : FrameCache, optional
        A shared cache (default: a private one of 512 MB).
    """

    def __init__(self, project: Project, cache: FrameCache | None = None):
        self.project = project
        self.cache = cache or FrameCache(512)
        self._sources: dict[int, tuple[str, FrameSource | None]] = {}

    def source(self, sensor: int) -> FrameSource | None:
        """The open source of a sensor, or None when it has no (findable) media."""
        path = self.project.sensors[sensor].media.path
        cached = self._sources.get(sensor)
        if cached is not None and cached[0] == path:
            return cached[1]
        if cached is not None and cached[1] is not None:
            cached[1].close()
        src = None
        if path:
            try:
                src = open_source(path)
            except CaraError as e:
                log.warning(str(e))
        self._sources[sensor] = (path, src)
        return src

    def media_index(self, sensor: int, frame: int) -> int:
        """Media frame shown by ``sensor`` on take frame ``frame`` (may be out of the media's range)."""
        return int(frame) - int(self.project.sensors[sensor].image_offset)

    def image(self, sensor: int, frame: int) -> np.ndarray:
        """The grey image of ``sensor`` on ``frame`` (zeros where there is none)."""
        s = self.project.sensors[sensor]
        src = self.source(sensor)
        k = self.media_index(sensor, frame)
        if src is None or not 0 <= k < src.frame_count:
            h, w = (src.height, src.width) if src is not None else (s.height, s.width)
            return np.zeros((h, w), np.uint8)
        return self.cache.get(src, k)

    def prefetch(self, frame: int, count: int = 8, step: int = 1, sensors=None) -> None:
        """Start decoding the next ``count`` frames (``step`` apart) of ``sensors`` (default: every sensor)."""
        for sensor in range(self.project.sensor_count) if sensors is None else sensors:
            src = self.source(sensor)
            if src is None:
                continue
            idx = [self.media_index(sensor, frame + step * i) for i in range(1, count + 1)]
            idx = [k for k in idx if 0 <= k < src.frame_count]
            if idx:
                self.cache.prefetch(src, idx)

    def close(self) -> None:
        for _p, src in self._sources.values():
            if src is not None:
                src.close()
        self._sources.clear()
