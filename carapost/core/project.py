"""The take model: everything a ``.cara`` project holds.

Qt-free and numpy-backed.  Edits go through commands (:mod:`carapost.core.edits`)
so that the GUI, the scripting API and the CLI share one undo history.
"""
from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from .brim import Brim
from .detections import DET_DTYPE, DetectionTable
from .errors import CaraError
from .points import FACE, KINDS, Point
from .properties import Properties
from .rig import CameraRig


@dataclass
class MediaRef:
    """Where a sensor's images come from.

    ``path`` is absolute when saved; ``relative`` is relative to the project's folder,
    so that a moved folder still finds its media.  ``kind`` is ``"pico"``,
    ``"video"``, ``"images"`` or ``""`` (no media).
    """

    path: str = ""
    relative: str = ""
    kind: str = ""
    missing: bool = False


@dataclass
class SensorInfo:
    """One sensor (channel) of the take."""

    name: str
    width: int = 1280
    height: int = 720
    frame_count: int = 0          #: frames of this channel's media (may differ from the take's)
    rotation: int = 0             #: display rotation in 90-degree clockwise steps (0-3)
    image_offset: int = 0         #: image sequence offset: take frame f shows media frame f - offset
    media: MediaRef = field(default_factory=MediaRef)


@dataclass
class Stick:
    """A line between two points, drawn in the views."""

    a: int
    b: int
    color: tuple[int, int, int] = (0, 200, 255)


class Project:
    """A take and everything done to it.

    Parameters
    ----------
    frame_count : int
        Frames in the take.
    sensors : int
        Channels (4 for a Cara rig; any number is supported).
    frame_rate : float
        Frames per second.
    """

    def __init__(self, frame_count: int, sensors: int = 4, frame_rate: float = 60.0,
                 timecode_start: str = "00:00:00:00", name: str = ""):
        if frame_count < 1:
            raise CaraError("a take needs at least one frame")
        if sensors < 1:
            raise CaraError("a take needs at least one sensor")
        self.name = name
        self.frame_count = int(frame_count)
        self.frame_rate = float(frame_rate)
        self.timecode_start = timecode_start
        self.sensors: list[SensorInfo] = [SensorInfo(f"Channel {i}") for i in range(sensors)]
        self.detections: list[DetectionTable] = [DetectionTable(frame_count) for _ in range(sensors)]
        self.points: dict[int, Point] = {}
        self.next_point_id = 0
        self.rig: CameraRig | None = None
        self.brim: Brim | None = None
        self.labels: list[str] = []
        self.sticks: list[Stick] = []
        self.rom_path: str = ""
        self.active_range: tuple[int, int] = (0, self.frame_count - 1)
        self.view_range: tuple[int, int] = (0, self.frame_count - 1)
        self.channel_selection: list[int] = []
        self.properties = Properties()
        #: Blob parameters as they were when the pico files were imported.
        self.pico_blob_parameters: dict = {}
        #: Where the project was loaded from or last saved to.
        self.path: str = ""
        #: Stabilize Data / Align Data result, beside the raw positions
        #: (a :class:`~carapost.core.stabilize.Stabilization`, or None).
        self.stabilization = None

    # ------------------------------------------------------------- structure
    @property
    def sensor_count(self) -> int:
        return len(self.sensors)

    def caddies(self) -> list[tuple[int, int]]:
        """Pairs of sensors on one caddy: (0, 1), (2, 3), ..."""
        return [(i, i + 1) for i in range(0, self.sensor_count - 1, 2)]

    def new_point(self, kind: str = FACE, label: str = "", brim_index: int = -1, point_id: int | None = None) -> Point:
        """A new empty point with a fresh id (not yet added: commands add it)."""
        if kind not in KINDS:
            raise CaraError(f"unknown point kind {kind!r}")
        pid = self.next_point_id if point_id is None else point_id
        return Point(pid, self.frame_count, self.sensor_count, label=label, kind=kind, brim_index=brim_index)

    def add_point(self, point: Point) -> None:
        """Insert ``point`` (commands call this; it keeps ids unique)."""
        if point.id in self.points:
            raise CaraError(f"point {point.id} exists already")
        if point.frames != self.frame_count or point.sensors != self.sensor_count:
            raise CaraError("point does not fit the take's frames and sensors")
        self.points[point.id] = point
        self.next_point_id = max(self.next_point_id, point.id + 1)

    def point(self, pid: int) -> Point:
        try:
            return self.points[pid]
        except KeyError:
            raise CaraError(f"no point {pid}") from None

    def point_by_label(self, label: str) -> Point | None:
        for p in self.points.values():
            if p.label == label:
                return p
        return None

    def face_points(self) -> Iterator[Point]:
        return (p for p in self.points.values() if p.kind == FACE)

    def clamp_frame(self, f: int) -> int:
        return max(0, min(self.frame_count - 1, int(f)))

    def check_range(self, start: int, end: int) -> tuple[int, int]:
        """Validate an inclusive frame range."""
        if not (0 <= start <= end < self.frame_count):
            raise CaraError(f"frame range {start}-{end} is outside the take (0-{self.frame_count - 1})")
        return int(start), int(end)

    def selected_channels(self, active: int | None = None) -> list[int]:
        """The explicit channel selection, else ``[active]``, else every channel."""
        if self.channel_selection:
            return list(self.channel_selection)
        if active is not None:
            return [active]
        return list(range(self.sensor_count))

    # ----------------------------------------------------------- comparison
    def digest(self) -> str:
        """A hash of everything the project holds (tests use it to compare states)."""
        h = hashlib.sha256()

        def put(*items):
            for it in items:
                if isinstance(it, np.ndarray):
                    a = np.ascontiguousarray(it)
                    h.update(str((a.dtype.str, a.shape)).encode())
                    h.update(a.tobytes())
                else:
                    h.update(repr(it).encode())
                h.update(b"|")

        put(self.name, self.frame_count, self.frame_rate, self.timecode_start, self.next_point_id)
        for s in self.sensors:
            put(s.name, s.width, s.height, s.frame_count, s.rotation, s.image_offset, s.media.kind,
                s.media.path)
        for d in self.detections:
            offsets, chunks = d.write_chunks()
            put(offsets, d.detected)
            for c in chunks:  # chunk boundaries depend on edit history, not on content
                h.update(np.ascontiguousarray(c).tobytes())
        for pid, p in self.points.items():
            put(pid, p.label, p.kind, p.brim_index, sorted(p.keyframes.items()), *[p.arrays[k] for k in sorted(p.arrays)])
        if self.rig is not None:
            for c in self.rig.cameras:
                put(c.name, c.device_id, tuple(c.sensor_size), float(c.focal_length), float(c.aspect), float(c.skew),
                    c.distortion_model, np.asarray(c.principal_point, float), np.asarray(c.distortion, float),
                    np.asarray(c.rotation, float), np.asarray(c.position, float))
            put(self.rig.quat, self.rig.position, self.rig.solved)
        if self.brim is not None:
            put(self.brim.name, self.brim.markers, self.brim.svg, self.brim.radius)
        put(self.labels, [(s.a, s.b, s.color) for s in self.sticks], self.rom_path, self.active_range,
            self.view_range, self.channel_selection, self.properties.to_dict(), self.pico_blob_parameters)
        if self.stabilization is not None:
            put("stabilization", *self.stabilization.digest_items())
        return h.hexdigest()

    def memory_bytes(self) -> int:
        """Bytes of per-frame data (memory-mapped arrays count although they stay on disk)."""
        n = sum(p.nbytes() for p in self.points.values())
        for d in self.detections:
            n += d.total() * DET_DTYPE.itemsize
        return n
