"""The ``.cara`` project file: one versioned file, saved atomically, loaded lazily.

Layout (little-endian)::

    0   8s  magic  b"CARAPOST"
    8   u4  format version
    12  u4  flags (0)
    16  u8  offset of the JSON manifest
    24  u8  length of the JSON manifest
    32  u4  CRC-32 of the JSON manifest
    36  u4  reserved
    40  u8  total file length
    48  ..  zero padding to 64
    64  ..  raw arrays, each at a 4096-byte aligned offset
    ..      the JSON manifest (UTF-8): everything that is not a big array, and for
            each array {"offset", "dtype", "shape"}

Arrays are memory-mapped copy-on-write on load, so a ten-minute take opens at
once and only the pages a user looks at are read; edits stay private to the
process until the next save.  Saving writes a temporary file beside the target,
syncs it and renames it over the target, so a crash mid-save leaves the old
file intact.
"""
from __future__ import annotations

import contextlib
import json
import os
import struct
import threading
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from .. import __version__
from .atomic import atomic_open
from ..core.brim import Brim
from ..core.camera import Camera
from ..core.detections import DET_DTYPE, DetectionTable
from ..core.errors import CaraError
from ..core.points import POINT_FIELDS, Point, field_shape
from ..core.project import MediaRef, Project, SensorInfo, Stick
from ..core.properties import Properties
from ..core.rig import CameraRig
from ..core.stabilize import Stabilization
from ..core.rom_ops import rom_tools_json, set_saved_rom_tools

MAGIC = b"CARAPOST"
FORMAT_VERSION = 1
_HEADER = struct.Struct("<8sIIQQIIQ")
HEADER_SIZE = 64
_ALIGN = 4096


# --------------------------------------------------------------------- cameras
def camera_to_json(cam: Camera) -> dict:
    """Intrinsics and pose of a camera as plain JSON values."""
    return {
        "name": cam.name, "device_id": cam.device_id, "sensor_size": list(map(int, cam.sensor_size)),
        "focal_length": float(cam.focal_length), "principal_point": np.asarray(cam.principal_point, float).tolist(),
        "aspect": float(cam.aspect), "skew": float(cam.skew), "distortion_model": cam.distortion_model,
        "distortion": np.asarray(cam.distortion, float).tolist(),
        "quaternion": np.asarray(cam.quaternion(), float).tolist(),
        # the matrix too: a quaternion round trip changes the last bits of R
        "rotation": np.asarray(cam.rotation, float).ravel().tolist(),
        "position": np.asarray(cam.position, float).tolist(),
    }


def camera_from_json(d: dict) -> Camera:
    if "rotation" in d:
        return Camera(
            name=d.get("name", ""), device_id=d.get("device_id", ""), sensor_size=tuple(d["sensor_size"]),
            focal_length=float(d["focal_length"]), principal_point=np.asarray(d["principal_point"], float),
            aspect=float(d.get("aspect", 1.0)), skew=float(d.get("skew", 0.0)),
            distortion_model=d.get("distortion_model", "none"), distortion=np.asarray(d.get("distortion", []), float),
            rotation=np.asarray(d["rotation"], float).reshape(3, 3), position=np.asarray(d["position"], float))
    return Camera.from_quaternion(
        np.asarray(d["quaternion"], float), np.asarray(d["position"], float),
        name=d.get("name", ""), device_id=d.get("device_id", ""), sensor_size=tuple(d["sensor_size"]),
        focal_length=float(d["focal_length"]), principal_point=np.asarray(d["principal_point"], float),
        aspect=float(d.get("aspect", 1.0)), skew=float(d.get("skew", 0.0)),
        distortion_model=d.get("distortion_model", "none"), distortion=np.asarray(d.get("distortion", []), float),
    )


# ------------------------------------------------------------------------ save
class _ArrayWriter:
    """Streams arrays into the file at aligned offsets and returns their references.

    Every ``_FLUSH_BYTES`` written, a background thread asks the kernel to write
    the data out (``fdatasync``) while we go on filling the page cache: a gigabyte
    save then costs about the slower of the two instead of their sum, and the
    final fsync has little left to do.
    """

    _FLUSH_BYTES = 128 << 20

    def __init__(self, f):
        self.f = f
        self.pos = HEADER_SIZE
        self._since_flush = 0
        self._flusher: threading.Thread | None = None

    def _background_flush(self) -> None:
        if self._flusher is not None and self._flusher.is_alive():
            return  # one writeback at a time; the next trigger picks up the rest
        self.f.flush()
        fd = self.f.fileno()
        sync = getattr(os, "fdatasync", os.fsync)

        def run():
            # An error here is not lost: the final fsync of the save reports it.
            with contextlib.suppress(OSError):
                sync(fd)

        self._flusher = threading.Thread(target=run, daemon=True)
        self._flusher.start()

    def finish(self) -> None:
        """Wait for the background writeback (before the file is closed)."""
        if self._flusher is not None:
            self._flusher.join()

    def _align(self) -> None:
        pad = (-self.pos) % _ALIGN
        if pad:
            self.f.write(b"\0" * pad)
            self.pos += pad

    def put(self, arr: np.ndarray) -> dict:
        return self.put_chunks([arr], arr.dtype, arr.shape)

    def put_chunks(self, chunks: list[np.ndarray], dtype: np.dtype, shape: tuple) -> dict:
        self._align()
        ref = {"offset": self.pos, "dtype": _dtype_to_json(np.dtype(dtype)), "shape": list(shape)}
        for c in chunks:
            c = np.ascontiguousarray(c)
            if c.nbytes:
                self.f.write(memoryview(c).cast("B"))
                self.pos += c.nbytes
                self._since_flush += c.nbytes
                if self._since_flush >= self._FLUSH_BYTES:
                    self._since_flush = 0
                    self._background_flush()
        return ref


def _dtype_to_json(dt: np.dtype) -> Any:
    return dt.descr if dt.names else dt.str


def _dtype_from_json(v: Any) -> np.dtype:
    if isinstance(v, str):
        return np.dtype(v)
    return np.dtype([tuple(x) for x in v])


def save_project(project: Project, path: str | Path) -> None:
    """Save ``project`` to ``path`` atomically.

    Raises
    ------
    CaraError
        When the folder cannot be written (the old file, if any, is untouched).
    """
    path = Path(path).absolute()
    with atomic_open(path, "the project") as f:
        f.write(b"\0" * HEADER_SIZE)
        w = _ArrayWriter(f)
        try:
            manifest = _manifest(project, w, path.parent)
        finally:
            w.finish()
        blob = json.dumps(manifest, separators=(",", ":"), allow_nan=True).encode("utf-8")
        json_offset = w.pos
        f.write(blob)
        total = json_offset + len(blob)
        f.seek(0)
        f.write(_HEADER.pack(MAGIC, FORMAT_VERSION, 0, json_offset, len(blob), zlib.crc32(blob), 0, total))
    project.path = str(path)


def _media_json(m: MediaRef, folder: Path) -> dict:
    rel = ""
    if m.path:
        try:
            rel = os.path.relpath(m.path, folder)
        except ValueError:  # another drive on Windows
            rel = ""
    return {"path": m.path, "relative": rel, "kind": m.kind}


def _manifest(project: Project, w: _ArrayWriter, folder: Path) -> dict:
    points = []
    for p in project.points.values():
        points.append({
            "id": p.id, "label": p.label, "kind": p.kind, "brim_index": p.brim_index,
            "keyframes": [[f, s, *box] for (f, s), box in sorted(p.keyframes.items())],
            "arrays": {k: w.put(a) for k, a in p.arrays.items()},
        })
    detections = []
    for table in project.detections:
        offsets, chunks = table.write_chunks()
        detections.append({
            "offsets": w.put(offsets),
            "records": w.put_chunks(chunks, DET_DTYPE, (int(offsets[-1]),)),
            "detected": w.put(table.detected),
        })
    rig = None
    if project.rig is not None:
        r = project.rig
        rig = {"cameras": [camera_to_json(c) for c in r.cameras], "quat": w.put(r.quat),
               "position": w.put(r.position), "solved": w.put(r.solved)}
    return {
        "format": "carapost-project", "version": FORMAT_VERSION, "writer": f"carapost {__version__}",
        "take": {"name": project.name, "frame_count": project.frame_count, "frame_rate": project.frame_rate,
                 "timecode_start": project.timecode_start},
        "sensors": [{"name": s.name, "width": s.width, "height": s.height, "frame_count": s.frame_count,
                     "rotation": s.rotation, "image_offset": s.image_offset,
                     "media": _media_json(s.media, folder)} for s in project.sensors],
        "properties": project.properties.to_dict(),
        "labels": project.labels,
        "sticks": [[s.a, s.b, list(s.color)] for s in project.sticks],
        "rom_path": project.rom_path,
        "rom_tools": rom_tools_json(project),
        "active_range": list(project.active_range),
        "view_range": list(project.view_range),
        "channel_selection": project.channel_selection,
        "pico_blob_parameters": project.pico_blob_parameters,
        "next_point_id": project.next_point_id,
        "points": points,
        "detections": detections,
        "rig": rig,
        "brim": project.brim.to_json() if project.brim is not None else None,
        "stabilization": _stabilization_json(project.stabilization, w),
    }


def _stabilization_json(s: Stabilization | None, w: _ArrayWriter) -> dict | None:
    if s is None:
        return None
    return {"transforms": w.put(np.ascontiguousarray(s.transforms, np.float64)), "method": s.method,
            "base_frame": int(s.base_frame), "frame_range": [int(x) for x in s.frame_range],
            "point_ids": [int(x) for x in s.point_ids], "usage": [float(x) for x in s.usage],
            "errors": {k: float(v) for k, v in s.errors.items()}, "parameters": dict(s.parameters),
            "alignment": None if s.alignment is None else np.asarray(s.alignment, float).ravel().tolist()}


# ------------------------------------------------------------------------ load
def read_header(path: str | Path) -> tuple[int, dict]:
    """Check a project file and return ``(format version, manifest)`` without mapping arrays.

    Raises
    ------
    CaraError
        For a missing, truncated, corrupt or too new file.
    """
    path = Path(path)
    try:
        with open(path, "rb") as f:
            head = f.read(HEADER_SIZE)
            size = os.fstat(f.fileno()).st_size
            if len(head) < HEADER_SIZE or head[:8] != MAGIC:
                raise CaraError("not a carapost project (.cara) file", path)
            _m, version, _flags, joff, jlen, crc, _r, total = _HEADER.unpack(head[:_HEADER.size])
            if version > FORMAT_VERSION:
                raise CaraError(f"written by a newer carapost (project format {version}; this version reads "
                                f"up to {FORMAT_VERSION}); update carapost to open it", path)
            if version < 1:
                raise CaraError(f"unknown project format version {version}", path)
            if size < total:
                raise CaraError(f"the file is truncated ({size} of {total} bytes); it was not saved completely",
                                path)
            if joff + jlen > size or joff < HEADER_SIZE:
                raise CaraError("the file is corrupt (bad manifest position)", path)
            f.seek(joff)
            blob = f.read(jlen)
    except FileNotFoundError:
        raise CaraError("no such file", path) from None
    except IsADirectoryError:
        raise CaraError("is a folder, not a .cara file", path) from None
    except PermissionError:
        raise CaraError("permission denied", path) from None
    if zlib.crc32(blob) != crc:
        raise CaraError("the file is corrupt (manifest checksum mismatch)", path)
    try:
        manifest = json.loads(blob.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CaraError(f"the file is corrupt (manifest: {e})", path) from None
    manifest["_file_size"] = size
    return version, manifest


def load_project(path: str | Path) -> Project:
    """Open a ``.cara`` file.

    Arrays are memory-mapped, so this takes milliseconds whatever the take's length.

    Raises
    ------
    CaraError
        For a missing, truncated, corrupt or too new file; nothing is changed.
    """
    path = Path(path).absolute()
    _version, m = read_header(path)
    size = m.pop("_file_size")
    mm = np.memmap(path, dtype=np.uint8, mode="c")

    def arr(ref: dict) -> np.ndarray:
        dt = _dtype_from_json(ref["dtype"])
        shape = tuple(int(x) for x in ref["shape"])
        n = int(np.prod(shape)) * dt.itemsize
        off = int(ref["offset"])
        if off < HEADER_SIZE or off + n > size:
            raise CaraError("the file is corrupt (array outside the file)", path)
        if n == 0:
            return np.zeros(shape, dt)
        return mm[off:off + n].view(dt).reshape(shape)

    try:
        take = m["take"]
        project = Project(int(take["frame_count"]), len(m["sensors"]), float(take["frame_rate"]),
                          take.get("timecode_start", "00:00:00:00"), take.get("name", ""))
        folder = path.parent
        for i, s in enumerate(m["sensors"]):
            media = _resolve_media(s.get("media", {}), folder)
            project.sensors[i] = SensorInfo(s["name"], int(s["width"]), int(s["height"]), int(s["frame_count"]),
                                            int(s["rotation"]) % 4, int(s["image_offset"]), media)
        F, S = project.frame_count, project.sensor_count
        project.properties = Properties(m.get("properties", {}))
        project.labels = list(m.get("labels", []))
        project.sticks = [Stick(int(a), int(b), tuple(c)) for a, b, c in m.get("sticks", [])]
        project.rom_path = m.get("rom_path", "")
        set_saved_rom_tools(project, m.get("rom_tools"))
        project.active_range = tuple(m["active_range"])
        project.view_range = tuple(m["view_range"])
        project.channel_selection = list(m.get("channel_selection", []))
        project.pico_blob_parameters = dict(m.get("pico_blob_parameters", {}))
        for d in m["points"]:
            arrays = {}
            for k, ref in d["arrays"].items():
                if k not in POINT_FIELDS:
                    continue
                a = arr(ref)
                if a.shape != field_shape(k, F, S):
                    raise CaraError(f"the file is corrupt (point {d['id']} {k} has shape {a.shape})", path)
                arrays[k] = a
            p = Point(int(d["id"]), F, S, d.get("label", ""), d.get("kind", "face"), int(d.get("brim_index", -1)),
                      arrays, {(int(k[0]), int(k[1])): tuple(map(float, k[2:6])) for k in d.get("keyframes", [])})
            project.points[p.id] = p
        project.next_point_id = max([int(m.get("next_point_id", 0))] + [pid + 1 for pid in project.points])
        for i, d in enumerate(m["detections"]):
            offsets = np.asarray(arr(d["offsets"]), np.int64)
            records = arr(d["records"])
            if records.dtype != DET_DTYPE:
                records = records.astype(DET_DTYPE)
            if len(offsets) != F + 1 or offsets[-1] != len(records) or np.any(np.diff(offsets) < 0):
                raise CaraError(f"the file is corrupt (detections of sensor {i})", path)
            table = DetectionTable(F, records, offsets)
            table._detected = np.array(arr(d["detected"]), bool)
            project.detections[i] = table
        if m.get("rig"):
            r = m["rig"]
            project.rig = CameraRig([camera_from_json(c) for c in r["cameras"]], F,
                                    arr(r["quat"]), arr(r["position"]), arr(r["solved"]))
        if m.get("brim"):
            project.brim = Brim.from_json(m["brim"])
        if m.get("stabilization"):
            d = m["stabilization"]
            t = np.array(arr(d["transforms"]), np.float64)
            if t.shape != (F, 3, 4):
                raise CaraError(f"the file is corrupt (stabilization transforms have shape {t.shape})", path)
            project.stabilization = Stabilization(
                t, str(d["method"]), int(d["base_frame"]), tuple(int(x) for x in d["frame_range"]),
                np.asarray(d["point_ids"], np.int64), np.asarray(d["usage"], np.float32),
                {k: float(v) for k, v in d["errors"].items()}, dict(d.get("parameters", {})),
                None if d.get("alignment") is None else np.asarray(d["alignment"], np.float64).reshape(3, 4))
    except CaraError:
        raise
    except (KeyError, TypeError, ValueError, IndexError) as e:
        raise CaraError(f"the file is corrupt (manifest entry {e!s})", path) from None
    project.path = str(path)
    return project


def _resolve_media(d: dict, folder: Path) -> MediaRef:
    """Find a sensor's media again: the saved path, then relative to the project, then beside it."""
    ref = MediaRef(d.get("path", ""), d.get("relative", ""), d.get("kind", ""))
    if not ref.path:
        return ref
    candidates = [Path(ref.path)]
    if ref.relative:
        candidates.append(folder / ref.relative)
    candidates.append(folder / Path(ref.path).name)
    for c in candidates:
        if c.exists():
            ref.path = str(c.absolute())
            return ref
    ref.missing = True
    return ref


def missing_media(project: Project) -> list[int]:
    """Sensors whose media could not be found (File > Relocate Files)."""
    return [i for i, s in enumerate(project.sensors) if s.media.missing]


def read_labels(path: str | Path) -> list[str]:
    """The label list of another project (File > Import Labels From Cara File)."""
    _v, m = read_header(path)
    labels = list(m.get("labels", []))
    for d in m.get("points", []):
        if d.get("label") and d["label"] not in labels:
            labels.append(d["label"])
    return labels
