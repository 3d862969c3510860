"""A writer of binary FBX 7.4 files, and a small scene API of animated Nulls on top of it.

Written from the public descriptions of the format (the layout that Blender's
FBX add-on and ufbx document); nothing here depends on the Autodesk SDK.

The file is a tree of *records*: a name, a list of typed properties and nested
records.  In version 7.4 a record starts with three little-endian uint32 (the
absolute offset of its end, its property count, the byte length of its
properties) and the length-prefixed name; a record with nested records, or with
no properties at all, ends with a 13-byte null record, and so does the top
level.  Properties are one type code byte then the value: ``C`` bool, ``Y``
int16, ``I`` int32, ``L`` int64, ``F`` float32, ``D`` float64, ``S`` string and
``R`` raw bytes (uint32 length first), and the arrays ``b i l f d`` (uint32
count, encoding 0 = plain or 1 = zlib, uint32 byte length, data).

:class:`FbxScene` builds what importers look for (Blender's, assimp, ufbx,
MotionBuilder): the header extension, GlobalSettings (axes, unit, frame rate,
time span), Documents, Definitions, Objects (Model ``Null`` + NodeAttribute,
AnimationStack, AnimationLayer, AnimationCurveNode ``T``, one AnimationCurve per
axis), Connections and Takes.  Scripts can build their own node trees with it
(the guide's ``cara_fbx_export.py`` example)::

    scene = FbxScene(60.0)
    face = scene.add_null("Face")
    nose = scene.add_null("Nose_Tip", parent=face)
    scene.set_translation_keys(nose, frames, xyz)     # frames with gaps = missing keys
    scene.write("take.fbx")
"""
from __future__ import annotations

import os
import struct
import time
import zlib
from dataclasses import dataclass, field
from typing import Iterable

import numpy as np

from .atomic import atomic_write

FBX_VERSION = 7400
#: FBX time unit ("KTime"): ticks per second.
KTIME_PER_SECOND = 46186158000

HEADER = b"Kaydara FBX Binary  \x00\x1a\x00"
_NULL_RECORD = b"\x00" * 13
# The FBX SDK ties the footer's first 16 bytes to FileId and CreationTime; this
# triple is the one public writers use, so files pass the SDK's integrity check.
_FILE_ID = bytes.fromhex("28b32aebb624ccc2bfc8b02aa92bfcf1")
_CREATION_TIME = "1970-01-01 10:00:00:000"
_FOOTER_ID = bytes.fromhex("fabcab09d0c8d466b176fb831cf7267e")
_FOOTER_MAGIC = bytes.fromhex("f85a8c6adef5d97eece90ce3758f290b")
# The SDK writes these with a null list even when they have no nested records.
_ALWAYS_CLOSED = frozenset({"AnimationStack", "AnimationLayer"})

#: TimeMode enum of GlobalSettings for the rates FBX names; any other is "custom" (14).
TIME_MODES = {120.0: 1, 100.0: 2, 60.0: 3, 50.0: 4, 48.0: 5, 30.0: 6, 25.0: 10, 24.0: 11, 1000.0: 12,
              96.0: 15, 72.0: 16}
TIME_MODE_CUSTOM = 14

# KeyAttrFlags of a key: linear interpolation (FbxAnimCurveDef::eInterpolationLinear).
# Marker samples are measurements: a cubic curve would overshoot between them.
KEY_LINEAR = 0x00000004

_ARRAY_CODES = {("b", 1): b"b", ("i", 4): b"i", ("i", 8): b"l", ("f", 4): b"f", ("f", 8): b"d"}
_COMPRESS_MIN_BYTES = 128   # smaller arrays grow when deflated


class Int64(int):
    """An ``L`` (int64) property: object ids and times; plain ints are written as ``I`` (int32)."""


class Float32(float):
    """An ``F`` (float32) property; plain floats are written as ``D`` (float64)."""


class Int16(int):
    """A ``Y`` (int16) property."""


@dataclass
class Record:
    """One node record of an FBX file: a name, typed properties and nested records.

    Property values: ``bool`` -> C, ``int`` -> I, :class:`Int64` -> L, ``float`` -> D,
    :class:`Float32` -> F, :class:`Int16` -> Y, ``str`` -> S, ``bytes`` -> R, and 1-D numpy
    arrays of bool, int32, int64, float32 or float64 -> b, i, l, f, d.
    """

    name: str
    props: tuple = ()
    children: list["Record"] = field(default_factory=list)

    def add(self, name: str, *props) -> "Record":
        """Append a nested record and return it."""
        r = Record(name, props)
        self.children.append(r)
        return r


def encode_records(records: Iterable[Record], version: int = FBX_VERSION, compress: bool = True,
                   level: int = 1) -> list[bytes]:
    """The bytes of a whole binary FBX file holding ``records`` at top level.

    Parameters
    ----------
    records : iterable of Record
    version : int
        Written in the header and footer; offsets are 32-bit, so below 7500.
    compress : bool
        Deflate arrays of 128 bytes or more (encoding 1).
    level : int
        zlib level: on marker curves 1 is 40 % faster than 6 for 1 % more bytes.

    Returns
    -------
    list of bytes
        Chunks to write in order (one big join would copy the file once more).
    """
    if version >= 7500:
        raise ValueError("only the 32-bit record layout (FBX 7.4 and before) is written")
    enc = _Encoder(compress, level)
    out = [HEADER, struct.pack("<I", version)]
    offset = len(HEADER) + 4
    for r in records:
        offset = enc.record(r, offset, out)
    out.append(_NULL_RECORD)
    offset += len(_NULL_RECORD)
    out.append(_FOOTER_ID)
    out.append(b"\x00" * 4)
    offset += len(_FOOTER_ID) + 4
    pad = (-offset) % 16 or 16
    out += [b"\x00" * pad, struct.pack("<I", version), b"\x00" * 120, _FOOTER_MAGIC]
    return out


class _Encoder:
    """Record serialiser.

    It remembers the last large array of each type it encoded: the three curves of
    a node share their key times, so each node's KeyTime array is deflated once,
    at no memory cost.
    """

    def __init__(self, compress: bool, level: int):
        self.compress = compress
        self.level = level
        self.last: dict[bytes, tuple[bytes, bytes]] = {}

    def record(self, r: Record, offset: int, out: list[bytes]) -> int:
        """Append record ``r`` starting at file ``offset``; return the offset after it."""
        name = r.name.encode("ascii")
        props = [self.prop(v) for v in r.props]
        plen = sum(len(p) for p in props)
        head_at = len(out)
        out.append(b"")                      # the header, once the end offset is known
        out += props
        end = offset + 13 + len(name) + plen
        if r.children:
            for c in r.children:
                end = self.record(c, end, out)
        if r.children or not r.props or r.name in _ALWAYS_CLOSED:
            out.append(_NULL_RECORD)
            end += len(_NULL_RECORD)
        if end >= 1 << 32:
            raise ValueError("the file exceeds the 4 GB that FBX 7.4 offsets can address")
        out[head_at] = struct.pack("<IIIB", end, len(props), plen, len(name)) + name
        return end

    def prop(self, v) -> bytes:
        if isinstance(v, np.ndarray):
            return self.array(v)
        if isinstance(v, bool):
            return b"C" + (b"\x01" if v else b"\x00")
        if isinstance(v, Int64):
            return b"L" + struct.pack("<q", v)
        if isinstance(v, Int16):
            return b"Y" + struct.pack("<h", v)
        if isinstance(v, int):
            return b"I" + struct.pack("<i", v)
        if isinstance(v, Float32):
            return b"F" + struct.pack("<f", v)
        if isinstance(v, float):
            return b"D" + struct.pack("<d", v)
        if isinstance(v, str):
            s = v.encode("utf-8")
            return b"S" + struct.pack("<I", len(s)) + s
        if isinstance(v, (bytes, bytearray)):
            return b"R" + struct.pack("<I", len(v)) + bytes(v)
        raise TypeError(f"no FBX property type for {type(v).__name__}")

    def array(self, a: np.ndarray) -> bytes:
        code = _ARRAY_CODES.get((a.dtype.kind, a.dtype.itemsize))
        if code is None:
            raise TypeError(f"no FBX array type for {a.dtype}")
        a = np.ascontiguousarray(a.ravel(), a.dtype.newbyteorder("<"))
        raw = a.tobytes()
        if len(raw) < _COMPRESS_MIN_BYTES:
            return code + struct.pack("<III", len(a), 0, len(raw)) + raw
        last = self.last.get(code)
        if last is not None and last[0] == raw:
            return last[1]
        data, encoding = (zlib.compress(raw, self.level), 1) if self.compress else (raw, 0)
        b = code + struct.pack("<III", len(a), encoding, len(data)) + data
        self.last[code] = (raw, b)
        return b


# --------------------------------------------------------------------------- scene


def frames_to_ktime(frames: np.ndarray, frame_rate: float) -> np.ndarray:
    """FBX times (int64 ticks) of frame numbers at ``frame_rate``."""
    f = np.asarray(frames, np.int64)
    ticks_per_frame = KTIME_PER_SECOND / float(frame_rate)
    if ticks_per_frame.is_integer():          # 24, 25, 30, 50, 60, 100, 120 ... fps: exact
        return f * np.int64(ticks_per_frame)
    return np.rint(f * ticks_per_frame).astype(np.int64)


def time_mode(frame_rate: float) -> int:
    """GlobalSettings TimeMode of a frame rate (``TIME_MODE_CUSTOM`` for rates FBX has no name for)."""
    return TIME_MODES.get(float(frame_rate), TIME_MODE_CUSTOM)


@dataclass(eq=False)
class FbxNull:
    """A Null model of an :class:`FbxScene` (returned by :meth:`FbxScene.add_null`)."""

    id: int
    name: str
    parent: "FbxNull | None"
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    key_frames: np.ndarray | None = None
    key_xyz: np.ndarray | None = None


@dataclass
class _Ids:
    next: int = 1_000_000

    def __call__(self) -> Int64:
        self.next += 1
        return Int64(self.next)


class FbxScene:
    """A scene of (animated) Null nodes written as binary FBX 7.4.

    Parameters
    ----------
    frame_rate : float
        Frames per second of the take: keys are at ``frame / frame_rate`` seconds
        and GlobalSettings declare this rate (TimeMode, CustomFrameRate).
    take_name : str
        Name of the animation stack and take (what MotionBuilder lists as the take).
    unit_scale_cm : float
        GlobalSettings UnitScaleFactor, the centimetres per unit of the values
        written: 0.1 for millimetres (the default).
    axes : str
        ``"z-up"`` (the default: +Z up, -Y forward, +X right, right-handed, the
        axis system of Blender) or ``"y-up"`` (+Y up, +Z forward: the FBX and
        Maya default).  Only declared; values are written as given.
    creator : str
        Creator string of the header.

    Notes
    -----
    Every object id is a distinct int64; ids count up from a fixed start, so the
    same scene always gives the same records.
    """

    _AXES = {"z-up": ((2, 1), (1, -1), (0, 1)), "y-up": ((1, 1), (2, 1), (0, 1))}

    def __init__(self, frame_rate: float, take_name: str = "Take 001", unit_scale_cm: float = 0.1,
                 axes: str = "z-up", creator: str = "carapost"):
        if not frame_rate > 0:
            raise ValueError(f"frame rate must be positive, not {frame_rate}")
        if axes not in self._AXES:
            raise ValueError(f"axes must be one of {sorted(self._AXES)}")
        self.frame_rate = float(frame_rate)
        self.take_name = take_name
        self.unit_scale_cm = float(unit_scale_cm)
        self.axes = axes
        self.creator = creator
        self.nulls: list[FbxNull] = []
        self.time_span: tuple[int, int] | None = None
        self._ids = _Ids()

    # -- building

    def add_null(self, name: str, parent: FbxNull | None = None) -> FbxNull:
        """Add a Null node under ``parent`` (the scene root when None) and return it."""
        if parent is not None and parent not in self.nulls:
            raise ValueError(f"the parent of {name!r} is not a node of this scene")
        node = FbxNull(self._ids(), str(name), parent)
        self.nulls.append(node)
        return node

    def set_translation(self, node: FbxNull, xyz) -> None:
        """The node's static local translation (what readers show where it has no keys)."""
        node.translation = tuple(float(v) for v in np.asarray(xyz, float).reshape(3))

    def set_translation_keys(self, node: FbxNull, frames: np.ndarray, xyz: np.ndarray) -> None:
        """Animate the node's local translation: one key per frame of ``frames``.

        Parameters
        ----------
        node : FbxNull
        frames : ndarray (n,) int
            Increasing frame numbers; frames left out are missing keys (gaps).
        xyz : ndarray (n, 3)
            Translation at those frames, in the scene's unit.  Written as float32,
            the type of FBX key values.
        """
        frames = np.asarray(frames, np.int64).ravel()
        xyz = np.asarray(xyz, np.float64).reshape(-1, 3)
        if len(frames) != len(xyz):
            raise ValueError(f"{len(frames)} frames but {len(xyz)} positions for {node.name!r}")
        if len(frames) > 1 and np.any(np.diff(frames) <= 0):
            raise ValueError(f"the key frames of {node.name!r} must increase")
        if not np.isfinite(xyz).all():
            raise ValueError(f"the keys of {node.name!r} are not all finite (leave gaps out instead)")
        node.key_frames, node.key_xyz = frames, xyz
        if len(frames):
            self.set_translation(node, xyz[0])

    def set_time_span(self, first_frame: int, last_frame: int) -> None:
        """The take's frame range (default: from the first to the last key of any node)."""
        self.time_span = (int(first_frame), int(last_frame))

    # -- output

    def records(self) -> list[Record]:
        """The top-level records of the file."""
        span = self._span()
        t0, t1 = (int(t) for t in frames_to_ktime(np.array(span), self.frame_rate))
        animated = [n for n in self.nulls if n.key_frames is not None and len(n.key_frames)]
        ids = _Ids(self._ids.next)     # objects besides the Nulls, after theirs
        stack_id, layer_id = ids(), ids()
        objects = Record("Objects")
        conns = Record("Connections")
        for n in self.nulls:
            attr_id = ids()
            attr = objects.add("NodeAttribute", attr_id, f"{n.name}\x00\x01NodeAttribute", "Null")
            p = attr.add("Properties70")
            _p(p, "Size", "double", "Number", "", 100.0)
            _p(p, "Look", "enum", "", "", 1)
            attr.add("TypeFlags", "Null")
            model = objects.add("Model", n.id, f"{n.name}\x00\x01Model", "Null")
            model.add("Version", 232)
            p = model.add("Properties70")
            _p(p, "Lcl Translation", "Lcl Translation", "", "A", *n.translation)
            _p(p, "DefaultAttributeIndex", "int", "Integer", "", 0)
            _p(p, "InheritType", "enum", "", "", 1)
            model.add("Shading", True)
            model.add("Culling", "CullingOff")
            conns.add("C", "OO", attr_id, n.id)
            conns.add("C", "OO", n.id, Int64(0) if n.parent is None else n.parent.id)
        stack = objects.add("AnimationStack", stack_id, f"{self.take_name}\x00\x01AnimStack", "")
        p = stack.add("Properties70")
        for name, t in (("LocalStart", t0), ("LocalStop", t1), ("ReferenceStart", t0), ("ReferenceStop", t1)):
            _p(p, name, "KTime", "Time", "", Int64(t))
        objects.add("AnimationLayer", layer_id, "BaseLayer\x00\x01AnimLayer", "")
        conns.add("C", "OO", layer_id, stack_id)
        flags = np.array([KEY_LINEAR], np.int32)
        attr_data = np.zeros(4, np.float32)      # slopes and weights: unused by linear keys
        for n in animated:
            cn_id = ids()
            cn = objects.add("AnimationCurveNode", cn_id, "T\x00\x01AnimCurveNode", "")
            p = cn.add("Properties70")
            for axis in "XYZ":
                _p(p, f"d|{axis}", "Number", "", "A", n.translation["XYZ".index(axis)])
            conns.add("C", "OO", cn_id, layer_id)
            conns.add("C", "OP", cn_id, n.id, "Lcl Translation")
            times = frames_to_ktime(n.key_frames, self.frame_rate)
            values = n.key_xyz.astype(np.float32)
            for k, axis in enumerate("XYZ"):
                c_id = ids()
                c = objects.add("AnimationCurve", c_id, "\x00\x01AnimCurve", "")
                c.add("Default", float(values[0, k]))
                c.add("KeyVer", 4008)
                c.add("KeyTime", times)
                c.add("KeyValueFloat", np.ascontiguousarray(values[:, k]))
                c.add("KeyAttrFlags", flags)
                c.add("KeyAttrDataFloat", attr_data)
                c.add("KeyAttrRefCount", np.array([len(times)], np.int32))
                conns.add("C", "OP", c_id, cn_id, f"d|{axis}")
        counts = {"Model": len(self.nulls), "NodeAttribute": len(self.nulls), "AnimationStack": 1,
                  "AnimationLayer": 1, "AnimationCurveNode": len(animated), "AnimationCurve": 3 * len(animated)}
        return [self._header_extension(), Record("FileId", (_FILE_ID,)),
                Record("CreationTime", (_CREATION_TIME,)), Record("Creator", (self.creator,)),
                self._global_settings(t0, t1), self._documents(ids()), Record("References"),
                _definitions(counts), objects, conns, self._takes(t0, t1)]

    def to_bytes(self, compress: bool = True) -> bytes:
        """The whole file as bytes."""
        return b"".join(encode_records(self.records(), compress=compress))

    def write(self, path: str | os.PathLike, compress: bool = True) -> None:
        """Write the scene to ``path`` atomically (:mod:`carapost.io.atomic`).

        Raises
        ------
        CaraError
            When the folder is missing or the file cannot be written; an existing
            file is then left as it was.
        """
        atomic_write(path, encode_records(self.records(), compress=compress), "the FBX file")

    # -- the fixed sections

    def _span(self) -> tuple[int, int]:
        if self.time_span is not None:
            return self.time_span
        keyed = [n.key_frames for n in self.nulls if n.key_frames is not None and len(n.key_frames)]
        if not keyed:
            return (0, 0)
        return (int(min(k[0] for k in keyed)), int(max(k[-1] for k in keyed)))

    def _header_extension(self) -> Record:
        h = Record("FBXHeaderExtension")
        h.add("FBXHeaderVersion", 1003)
        h.add("FBXVersion", FBX_VERSION)
        h.add("EncryptionType", 0)
        t = time.localtime()
        ts = h.add("CreationTimeStamp")
        for name, v in (("Version", 1000), ("Year", t.tm_year), ("Month", t.tm_mon), ("Day", t.tm_mday),
                        ("Hour", t.tm_hour), ("Minute", t.tm_min), ("Second", t.tm_sec), ("Millisecond", 0)):
            ts.add(name, v)
        h.add("Creator", self.creator)
        info = h.add("SceneInfo", "GlobalInfo\x00\x01SceneInfo", "UserData")
        info.add("Type", "UserData")
        info.add("Version", 100)
        meta = info.add("MetaData")
        meta.add("Version", 100)
        for name in ("Title", "Subject", "Author", "Keywords", "Revision", "Comment"):
            meta.add(name, self.take_name if name == "Title" else "")
        p = info.add("Properties70")
        _p(p, "Original|ApplicationName", "KString", "", "", self.creator)
        _p(p, "LastSaved|ApplicationName", "KString", "", "", self.creator)
        return h

    def _global_settings(self, t0: int, t1: int) -> Record:
        g = Record("GlobalSettings")
        g.add("Version", 1000)
        p = g.add("Properties70")
        (up, up_sign), (front, front_sign), (coord, coord_sign) = self._AXES[self.axes]
        for name, v in (("UpAxis", up), ("UpAxisSign", up_sign), ("FrontAxis", front),
                        ("FrontAxisSign", front_sign), ("CoordAxis", coord), ("CoordAxisSign", coord_sign),
                        ("OriginalUpAxis", up), ("OriginalUpAxisSign", up_sign)):
            _p(p, name, "int", "Integer", "", v)
        _p(p, "UnitScaleFactor", "double", "Number", "", self.unit_scale_cm)
        _p(p, "OriginalUnitScaleFactor", "double", "Number", "", self.unit_scale_cm)
        _p(p, "AmbientColor", "ColorRGB", "Color", "", 0.0, 0.0, 0.0)
        _p(p, "DefaultCamera", "KString", "", "", "Producer Perspective")
        _p(p, "TimeMode", "enum", "", "", time_mode(self.frame_rate))
        _p(p, "TimeProtocol", "enum", "", "", 2)
        _p(p, "SnapOnFrameMode", "enum", "", "", 0)
        _p(p, "TimeSpanStart", "KTime", "Time", "", Int64(t0))
        _p(p, "TimeSpanStop", "KTime", "Time", "", Int64(t1))
        _p(p, "CustomFrameRate", "double", "Number", "", self.frame_rate)
        _p(p, "CurrentTimeMarker", "int", "Integer", "", -1)
        return g

    def _documents(self, doc_id: Int64) -> Record:
        d = Record("Documents")
        d.add("Count", 1)
        doc = d.add("Document", doc_id, "", "Scene")
        p = doc.add("Properties70")
        _p(p, "SourceObject", "object", "", "")
        _p(p, "ActiveAnimStackName", "KString", "", "", self.take_name)
        doc.add("RootNode", Int64(0))
        return d

    def _takes(self, t0: int, t1: int) -> Record:
        t = Record("Takes")
        t.add("Current", self.take_name)
        take = t.add("Take", self.take_name)
        take.add("FileName", self.take_name.replace(" ", "_") + ".tak")
        take.add("LocalTime", Int64(t0), Int64(t1))
        take.add("ReferenceTime", Int64(t0), Int64(t1))
        return t


def _p(props70: Record, name: str, type_: str, label: str, flags: str, *values) -> None:
    """One ``P`` entry of a Properties70 block."""
    props70.add("P", name, type_, label, flags, *values)


def _definitions(counts: dict[str, int]) -> Record:
    d = Record("Definitions")
    d.add("Version", 100)
    types = {"GlobalSettings": 1, **{k: v for k, v in counts.items() if v}}
    d.add("Count", sum(types.values()))
    for name, n in types.items():
        ot = d.add("ObjectType", name)
        ot.add("Count", n)
    return d
