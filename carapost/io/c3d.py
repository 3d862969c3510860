"""Our own C3D writer and reader (numpy + struct only).

Why our own: ezc3d 1.7.2 writes the fourth word of a point sample with the
camera mask and the residual in swapped bytes, and writes NaN coordinates as
valid samples; the ``c3d`` package and ezc3d both reject real files whose
parameter section has a single malformed record (c3d.org sample 29, a facial
capture).  A C3D file is small and simple enough to do exactly as the C3D.org
user guide says.

File layout (512-byte blocks, numbered from 1)
----------------------------------------------
* Block 1, the header: byte 1 points to the first parameter block, byte 2 is
  0x50; then 16-bit words: point count, analog samples per 3D frame (all
  channels), first and last frame, maximum interpolation gap, POINT:SCALE
  (float, words 7-8), first data block, analog samples per channel and frame,
  frame rate (float, words 11-12); word 150 is the key 0x3039 (four-character
  event labels supported), word 151 the number of header events.
* The parameter section: a 4-byte header (two ignored bytes, the number of
  blocks, the processor type 84 Intel / 85 DEC / 86 MIPS, which fixes the byte
  order of every integer and float of the file outside the first two bytes),
  then group and parameter records chained by a 16-bit "offset to the next
  record", ended by a zero name length or group id.
* The data section: for each frame, for each point, four words x, y, z and
  "residual word"; then the analog samples of that frame (skipped here).  The
  words are int16 (coordinates times |POINT:SCALE|) when POINT:SCALE > 0, or
  float32 in the file's float format (coordinates as they are) when < 0.

The fourth word is a signed 16-bit integer; in float files that integer is
stored as a float value (the guide: "for compatibility the same signed-integer
format is retained internally even when stored as float").  Negative means the
sample is invalid; otherwise its high byte holds the camera contribution mask
(7 bits, bit i = camera i) and its low byte the residual in units of
|POINT:SCALE|.  A residual byte of 0 marks a modelled (interpolated, filtered)
sample.
"""
from __future__ import annotations

import math
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from carapost.core.errors import CaraError, read_bytes
from carapost.io.atomic import atomic_write

__all__ = ["C3DData", "read_c3d", "c3d_info", "write_c3d", "PROCESSOR_INTEL", "PROCESSOR_DEC", "PROCESSOR_MIPS"]

BLOCK = 512
PROCESSOR_INTEL, PROCESSOR_DEC, PROCESSOR_MIPS = 84, 85, 86
_PROCESSOR_NAMES = {PROCESSOR_INTEL: "intel", PROCESSOR_DEC: "dec", PROCESSOR_MIPS: "mips"}
_EVENT_KEY = 0x3039          # header word 150: four-character event labels supported
_PARAM_KEY = 0x50            # header byte 2 (and byte 2 of the parameter section header)
_MAX_RECORD = 32767          # a record's "offset to next" is a signed 16-bit integer
_LABELS_PER_PARAM = 255      # a dimension is one byte: LABELS, LABELS2, ... beyond 255 points

# Parameters the writer derives from the data; extra_params may not override them.
_RESERVED = {
    "POINT": {"USED", "SCALE", "RATE", "DATA_START", "FRAMES", "LONG_FRAMES", "UNITS"},
    "ANALOG": {"USED", "RATE"},
    "TRIAL": {"ACTUAL_START_FIELD", "ACTUAL_END_FIELD"},
}


# Integer parameters whose 16 bits the guide reads as unsigned.
_UNSIGNED = {
    "POINT": {"USED", "FRAMES", "DATA_START"},
    "ANALOG": {"USED"},
    "TRIAL": {"ACTUAL_START_FIELD", "ACTUAL_END_FIELD"},
}


def _reserved(group: str, name: str) -> bool:
    if name in _RESERVED.get(group, ()):
        return True
    # LABELS, LABELS2, ..., DESCRIPTIONS, DESCRIPTIONS2, ...
    return group == "POINT" and any(name == p or (name.startswith(p) and name[len(p):].isdigit())
                                    for p in ("LABELS", "DESCRIPTIONS"))


# --------------------------------------------------------------------------- data model

@dataclass
class C3DData:
    """The 3D point content of a C3D file.

    Attributes
    ----------
    positions : ndarray, shape (F, P, 3), float64
        Coordinates in ``units``; NaN where the sample is invalid.
    residuals : ndarray, shape (F, P), float64
        Residual (low byte of the fourth word times |POINT:SCALE|); NaN where invalid.
    camera_masks : ndarray, shape (F, P), uint8
        Camera contribution mask (bit i = camera i contributed; 7 bits); 0 where invalid.
    labels : list of str
        One per point (POINT:LABELS, LABELS2, ...).
    rate : float
        Frames per second (POINT:RATE).
    units : str
        POINT:UNITS, e.g. ``"mm"``.
    first_frame : int
        Number of the first frame (TRIAL:ACTUAL_START_FIELD, else header word 4).
    scale : float
        POINT:SCALE as stored (negative: float format).
    processor : str
        ``"intel"``, ``"dec"`` or ``"mips"``.
    warnings : list of str
        What was wrong or odd in the file but could be read around.
    parameters : dict
        ``parameters[GROUP][NAME]`` -> decoded value, names upper-case: str for a
        one-dimensional character parameter, list of str (nested lists for more
        dimensions) for character arrays, int/float for scalars, numpy arrays
        (shape = the C3D dimensions reversed) for numeric arrays.
    """

    positions: np.ndarray
    residuals: np.ndarray
    camera_masks: np.ndarray
    labels: list[str]
    rate: float
    units: str
    first_frame: int
    scale: float
    processor: str
    warnings: list[str] = field(default_factory=list)
    parameters: dict[str, dict[str, Any]] = field(default_factory=dict)

    @property
    def frames(self) -> int:
        """Number of frames."""
        return int(self.positions.shape[0])

    @property
    def points(self) -> int:
        """Number of points."""
        return int(self.positions.shape[1])

    @property
    def is_float(self) -> bool:
        """True when the data section is stored as floats (POINT:SCALE < 0)."""
        return self.scale < 0

    @property
    def valid(self) -> np.ndarray:
        """(F, P) bool: the sample has coordinates."""
        return ~np.isnan(self.positions[..., 0])


# --------------------------------------------------------------------------- number formats

def _dec_to_float(words: np.ndarray) -> np.ndarray:
    """DEC (VAX F-floating) numbers, given as little-endian uint32 loads of their 4 bytes, to float64.

    A VAX float is two 16-bit little-endian words, the *first* holding sign,
    8-bit exponent (bias 128) and the top 7 fraction bits, the second the low
    16 fraction bits; its value is 0.1fff x 2^(e-128) = 1.fff x 2^(e-129), i.e.
    a quarter of the IEEE float with the same bits once the words are swapped.
    Computed exactly in float64 (a plain IEEE reinterpretation / 4 would turn
    exponent 255 into inf and underflow small numbers).  Exponent 0 is zero.
    """
    u = np.asarray(words, dtype=np.uint32)
    bits = ((u & 0xFFFF) << 16) | (u >> 16)
    exp = ((bits >> 23) & 0xFF).astype(np.int32)
    frac = (bits & 0x7FFFFF).astype(np.float64)
    val = np.ldexp(1.0 + frac / 8388608.0, exp - 129)
    val[exp == 0] = 0.0
    return np.where(bits >> 31, -val, val)


class _Codec:
    """Reads integers and floats in the byte order of one processor type."""

    def __init__(self, processor: int):
        self.processor = processor
        self.end = ">" if processor == PROCESSOR_MIPS else "<"

    def i16(self, buf: bytes, off: int) -> int:
        return struct.unpack_from(self.end + "h", buf, off)[0]

    def u16(self, buf: bytes, off: int) -> int:
        return struct.unpack_from(self.end + "H", buf, off)[0]

    def floats(self, buf, offset: int = 0, count: int = -1) -> np.ndarray:
        """float64 array of ``count`` 4-byte floats from ``buf`` at ``offset``."""
        if self.processor == PROCESSOR_DEC:
            return _dec_to_float(np.frombuffer(buf, "<u4", count, offset))
        return np.frombuffer(buf, self.end + "f4", count, offset).astype(np.float64)

    def f32(self, buf: bytes, off: int) -> float:
        return float(self.floats(buf, off, 1)[0])


# --------------------------------------------------------------------------- parameter section

def _decode_text(b: bytes) -> str:
    try:
        s = b.decode("utf-8")
    except UnicodeDecodeError:
        s = b.decode("latin-1")  # old files carry 8-bit code pages; latin-1 never fails
    return s.replace("\x00", " ").strip()


def _decode_value(bpe: int, dims: list[int], data: bytes, codec: _Codec) -> Any:
    """A parameter's value from its element size, dimensions (column-major) and bytes."""
    if bpe == -1:
        if not dims:
            return _decode_text(data)
        if len(dims) == 1:
            return _decode_text(data)
        n = dims[0]
        rest = dims[1:]
        count = int(np.prod(rest))
        if n == 0 or count == 0:
            return []
        strings = [_decode_text(data[i * n:(i + 1) * n]) for i in range(count)]
        if len(rest) == 1:
            return strings
        return np.array(strings, dtype=object).reshape(rest[::-1]).tolist()
    if bpe == 1:
        arr = np.frombuffer(data, np.int8)
    elif bpe == 2:
        arr = np.frombuffer(data, codec.end + "i2").astype(np.int64)
    else:  # 4: float
        arr = codec.floats(data)
    if not dims:
        v = arr[0] if len(arr) else 0
        return float(v) if bpe == 4 else int(v)
    return arr.reshape(dims[::-1]) if len(dims) > 1 else arr.copy()


@dataclass
class _Param:
    group: int
    name: str
    bpe: int
    dims: list[int]
    data: bytes
    value: Any


def _record_start_ok(buf: bytes, pos: int, end: int) -> bool:
    """Whether a record (or the zero fill that ends the section) can start at ``pos``."""
    if pos == end:
        return True
    if pos + 2 > end:
        return False
    nlen, gid = struct.unpack_from("bb", buf, pos)
    if nlen == 0 or gid == 0:
        return True
    n = abs(nlen)
    return pos + 4 + n <= end and all(0x21 <= c <= 0x7E for c in buf[pos + 2:pos + 2 + n])


def _parse_parameters(buf: bytes, start: int, end: int, codec: _Codec, warnings: list[str]):
    """Walk the parameter records from ``start`` (just past the 4-byte section header) to ``end``.

    Returns ``(groups, params)``: group id -> name, and the parameters read.

    Records are chained by their "offset to next" (counted from the offset
    field itself; 0 marks the last record).  When that offset does not lead to
    a record, the byte-swapped offset and the record's own content length are
    tried (c3d.org sample 02 in SGI byte order stores the offset of its last
    record, POINT:LABELS, in Intel order: 0x013F read big-endian is 16129).
    When nothing fits, the walk stops and keeps what was read before.  A
    parameter whose data is complete but whose description-length byte is cut
    off by its offset keeps its value (sample 29, below).
    """
    groups: dict[int, str] = {}
    params: list[_Param] = []
    pos = start
    while pos + 2 <= end:
        nlen, gid = struct.unpack_from("bb", buf, pos)
        if nlen == 0 or gid == 0:
            break  # zero fill after the last record
        nlen = abs(nlen)  # negative = locked
        if pos + 4 + nlen > end:
            warnings.append(f"parameter record at byte {pos} runs past the parameter section; "
                            f"parameters from there on are ignored")
            break
        raw_name = buf[pos + 2:pos + 2 + nlen]
        if not all(0x21 <= c <= 0x7E for c in raw_name):  # names are printable 7-bit ASCII
            warnings.append(f"parameter record at byte {pos} has an invalid name {raw_name!r}; "
                            f"parameters from there on are ignored")
            break
        name = raw_name.decode("ascii").upper()
        what = f"group {name}" if gid < 0 else f"parameter {groups.get(gid, f'#{gid}')}:{name}"
        off_at = pos + 2 + nlen
        off = codec.i16(buf, off_at)
        b0 = off_at + 2  # first byte of the record's content

        # The content's own layout, independent of the offset.
        bpe = ndim = nbytes = 0
        dims: list[int] = []
        if gid < 0:
            clen = 1 + (buf[b0] if b0 < end else 0)
        else:
            if b0 + 2 > end:
                warnings.append(f"{what}: record cut by the end of the parameter section; "
                                f"parameters from there on are ignored")
                break
            bpe = struct.unpack_from("b", buf, b0)[0]
            ndim = buf[b0 + 1]
            if bpe not in (-1, 1, 2, 4) or ndim > 7 or b0 + 2 + ndim > end:
                warnings.append(f"{what}: invalid element size {bpe} or dimension count {ndim}; "
                                f"parameters from there on are ignored")
                break
            dims = list(buf[b0 + 2:b0 + 2 + ndim])
            nbytes = abs(bpe) * (int(np.prod(dims)) if dims else 1)
            dend = b0 + 2 + ndim + nbytes
            clen = dend - b0 + 1 + (buf[dend] if dend < end else 0)

        # Where the next record starts.
        if off == 0:
            nxt = end
        else:
            nxt = off_at + off
            if not (off >= 2 and nxt <= end and _record_start_ok(buf, nxt, end)):
                swapped = struct.unpack("<h" if codec.end == ">" else ">h", buf[off_at:off_at + 2])[0]
                for how, o in (("its byte-swapped value", swapped), ("the record's own length", 2 + clen)):
                    n = off_at + o
                    if o >= 2 and n <= end and _record_start_ok(buf, n, end):
                        warnings.append(f"{what}: offset to the next record ({off}) leads nowhere; "
                                        f"{how} ({o}) does and was used")
                        nxt = n
                        break
                else:
                    warnings.append(f"{what}: offset to the next record ({off}) leads outside the parameter "
                                    f"records; parameters from there on are ignored")
                    if gid < 0 or b0 + 2 + ndim + nbytes > end:
                        break
                    nxt = -1  # keep this parameter if its data is whole, then stop

        rec_end = end if nxt < 0 else nxt
        if gid < 0:
            if -gid in groups and groups[-gid] != name:
                warnings.append(f"group id {-gid} is defined twice ({groups[-gid]}, {name}); keeping the first")
            else:
                groups[-gid] = name
        else:
            dstart = b0 + 2 + ndim
            if dstart + nbytes > rec_end:
                warnings.append(f"{what}: its data ({nbytes} bytes) runs past its record "
                                f"({max(rec_end - dstart, 0)} bytes); parameters from there on are ignored")
                break
            if dstart + nbytes == rec_end and nxt != end:
                # The description-length byte is missing: the record's offset ends
                # exactly after the data.  This is the defect of c3d.org sample 29
                # (Facial-Sing): POINT:LABELS (char, dims 12 x 38) has the offset
                # 462 where its content needs 463 (2 offset bytes + element size +
                # dimension count + 2 dimensions + 456 label bytes + 1 description
                # length); the next record, POINT:DESCRIPTIONS, starts where the
                # description length should be (it reads as 12, the length of the
                # name "DESCRIPTIONS").  The labels themselves are complete: keep them.
                warnings.append(f"{what}: record ends right after its data, without the description "
                                f"length byte the format requires (its offset to the next record is "
                                f"1 byte short); value kept, description taken as empty")
            elif dstart + nbytes < rec_end and dstart + nbytes + 1 + buf[dstart + nbytes] > rec_end:
                warnings.append(f"{what}: description runs past its record; ignored")
            data = buf[dstart:dstart + nbytes]
            try:
                value = _decode_value(bpe, dims, data, codec)
            except (ValueError, IndexError) as e:  # numbers that cannot be decoded
                warnings.append(f"{what}: value could not be decoded ({e}); parameters from there on are ignored")
                break
            params.append(_Param(gid, name, bpe, dims, data, value))
        if off == 0 or nxt < 0:
            break
        pos = nxt
    return groups, params


# --------------------------------------------------------------------------- reader

def _parse(path: str | os.PathLike):
    """Header, parameters and the decoded data section of a C3D file."""
    path = Path(path)
    buf = read_bytes(path)
    warnings: list[str] = []
    if len(buf) < BLOCK:
        raise CaraError(f"not a C3D file: {len(buf)} bytes, shorter than the 512-byte header", path)
    param_block, key = buf[0], buf[1]
    if key != _PARAM_KEY:
        raise CaraError(f"not a C3D file: byte 2 of the header is 0x{key:02X}, expected 0x50", path)
    pstart = (param_block - 1) * BLOCK
    if param_block < 2 or pstart + 4 > len(buf):
        raise CaraError(f"not a C3D file: the header points to parameter block {param_block}, "
                        f"outside the file", path)
    proc = buf[pstart + 3]
    if proc not in _PROCESSOR_NAMES:
        warnings.append(f"unknown processor type {proc} in the parameter section header; read as Intel")
        proc = PROCESSOR_INTEL
    codec = _Codec(proc)

    # Header record (words 2-12); byte order is that of the processor type.
    h_points = codec.u16(buf, 2)
    h_analog = codec.u16(buf, 4)
    h_first = codec.u16(buf, 6)
    h_last = codec.u16(buf, 8)
    h_scale = codec.f32(buf, 12)
    h_data_start = codec.u16(buf, 16)
    h_rate = codec.f32(buf, 20)

    nblocks = buf[pstart + 2]
    pend = pstart + nblocks * BLOCK
    if nblocks == 0:
        warnings.append("the parameter section header gives 0 blocks; reading up to the data section")
        pend = max(pstart, (h_data_start - 1) * BLOCK)
    pend = min(pend, len(buf))
    gnames, plist = _parse_parameters(buf, pstart + 4, pend, codec, warnings)

    parameters: dict[str, dict[str, Any]] = {}
    raw: dict[tuple[str, str], _Param] = {}
    for p in plist:
        g = gnames.get(p.group)
        if g is None:
            g = f"GROUP{p.group}"
            warnings.append(f"parameter {p.name} belongs to group id {p.group}, which has no group record")
        if p.name in parameters.setdefault(g, {}):
            warnings.append(f"parameter {g}:{p.name} appears twice; keeping the first")
            continue
        value = p.value
        if p.bpe == 2 and p.name in _UNSIGNED.get(g, ()):
            value = value & 0xFFFF  # counts the guide reads as unsigned 16-bit (up to 65535)
        parameters[g][p.name] = value
        raw[(g, p.name)] = p
    for g in gnames.values():
        parameters.setdefault(g, {})

    def param(g: str, n: str) -> _Param | None:
        return raw.get((g, n))

    def scalar_u16(g: str, n: str) -> int | None:
        """An integer parameter read as unsigned 16-bit (the guide's extension of the int16 range)."""
        p = param(g, n)
        if p is None or not p.data:
            return None
        if p.bpe == 2:
            return int(np.frombuffer(p.data[:2], codec.end + "u2")[0])
        if p.bpe == 4:
            v = float(codec.floats(p.data, 0, 1)[0])
            return int(round(v)) if math.isfinite(v) and v >= 0 else None
        if p.bpe == 1:
            return p.data[0]
        return None

    def scalar_float(g: str, n: str) -> float | None:
        p = param(g, n)
        if p is None or not p.data:
            return None
        if p.bpe == 4:
            return float(codec.floats(p.data, 0, 1)[0])
        if p.bpe in (1, 2):
            return float(np.asarray(p.value).ravel()[0])
        return None

    # Points, scale, rate: the parameters rule; the header holds copies (and the
    # fallback when a malformed record stopped the walk before them).
    n_points = scalar_u16("POINT", "USED")
    if n_points is None:
        n_points = h_points
    elif n_points != h_points:
        warnings.append(f"POINT:USED ({n_points}) differs from the header's point count ({h_points}); "
                        f"using POINT:USED")
    scale = scalar_float("POINT", "SCALE")
    if scale is None or not math.isfinite(scale) or scale == 0:
        if scale is not None:
            warnings.append(f"POINT:SCALE is {scale}; using the header's scale {h_scale}")
        scale = h_scale
    elif (scale < 0) != (h_scale < 0):
        warnings.append(f"POINT:SCALE ({scale}) and the header's scale ({h_scale}) disagree on the "
                        f"format; using POINT:SCALE")
    rate = scalar_float("POINT", "RATE")
    if rate is None or not math.isfinite(rate) or rate <= 0:
        rate = h_rate
    data_start = h_data_start
    p_ds = scalar_u16("POINT", "DATA_START")
    if p_ds is not None and p_ds != h_data_start:
        warnings.append(f"POINT:DATA_START ({p_ds}) differs from the header ({h_data_start}); using the header")
    if data_start < 2 or (data_start - 1) * BLOCK > len(buf):
        raise CaraError(f"the header's data section block ({data_start}) is outside the file", path)

    # Frame range.  POINT:FRAMES (unsigned 16-bit, or a float) is the count;
    # beyond 65535 frames the count is in POINT:LONG_FRAMES (float, C-Motion)
    # or TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD (Vicon), each two unsigned
    # 16-bit words, low word first (the guide writes "*65535", a typo for the
    # 32-bit value it describes).  The header's words 4-5 are the fallback.
    def trial_field(n: str) -> int | None:
        p = param("TRIAL", n)
        if p is None or p.bpe != 2 or len(p.data) < 4:
            return None
        lo, hi = np.frombuffer(p.data[:4], codec.end + "u2")
        return int(lo) + 65536 * int(hi)

    t_start, t_end = trial_field("ACTUAL_START_FIELD"), trial_field("ACTUAL_END_FIELD")
    first_frame = t_start if t_start is not None else h_first
    n_trial = t_end - t_start + 1 if t_start is not None and t_end is not None and t_end >= t_start else None
    p_frames = param("POINT", "FRAMES")
    n_frames = scalar_u16("POINT", "FRAMES")
    long_frames = scalar_float("POINT", "LONG_FRAMES")
    if p_frames is not None and p_frames.bpe == 4 and n_frames is not None:
        frames = n_frames
    elif long_frames is not None and math.isfinite(long_frames) and long_frames > (n_frames or 0):
        frames = int(round(long_frames))
    elif n_frames is not None:
        frames = n_frames
        # FRAMES saturated at 65535 (the guide) or wrapped modulo 65536 by a writer
        if n_trial is not None and n_trial > 65535 and n_frames in (65535, n_trial % 65536):
            frames = n_trial
    elif n_trial is not None:
        frames = n_trial
    else:
        frames = max(0, h_last - h_first + 1)

    # Analog samples interleaved after each frame's points: the header's word 3
    # (all channels x samples per frame) defines the layout.
    analog_words = h_analog
    a_used = scalar_u16("ANALOG", "USED")
    a_rate = scalar_float("ANALOG", "RATE")
    if a_used is not None and a_rate and rate and a_used * int(round(a_rate / rate)) != h_analog:
        warnings.append(f"ANALOG:USED x ANALOG:RATE/POINT:RATE ({a_used} x {a_rate:g}/{rate:g}) differs from "
                        f"the header's analog samples per frame ({h_analog}); using the header")

    frame_words = 4 * n_points + analog_words
    dstart = (data_start - 1) * BLOCK
    if not (math.isfinite(scale) and scale != 0):
        # No usable scale anywhere: its sign is the format, so take the one the file is big enough for.
        is_float = dstart + frames * frame_words * 4 <= len(buf)
        warnings.append(f"POINT:SCALE and the header's scale are {scale}; read as "
                        f"{'float' if is_float else 'integer'} data with scale {'-1' if is_float else '1'}")
        scale = -1.0 if is_float else 1.0
    is_float = scale < 0
    word = 4 if is_float else 2
    need = frames * frame_words * word
    if dstart + need > len(buf):
        have = (len(buf) - dstart) // (frame_words * word) if frame_words else 0
        raise CaraError(f"data section truncated: {frames} frames of {n_points} points declared, the file "
                        f"holds {max(have, 0)} complete frames ({len(buf)} bytes, {dstart + need} needed)", path)

    labels = _labels(parameters, n_points, warnings)
    units = parameters.get("POINT", {}).get("UNITS", "")
    units = units if isinstance(units, str) else (units[0] if units else "")
    info = dict(path=path, processor=proc, scale=float(scale), rate=float(rate), frames=frames,
                points=n_points, first_frame=first_frame, units=units, labels=labels,
                parameters=parameters, warnings=warnings, analog_words=analog_words,
                data_start=data_start)
    absscale = abs(scale)
    if is_float:
        if proc == PROCESSOR_DEC:
            raw_words = np.frombuffer(buf, "<u4", frames * frame_words, dstart).reshape(frames, frame_words)
            pts = _dec_to_float(raw_words[:, :4 * n_points]).reshape(frames, n_points, 4)
        else:
            vals = np.frombuffer(buf, codec.end + "f4", frames * frame_words, dstart).reshape(frames, frame_words)
            pts = vals[:, :4 * n_points].astype(np.float64).reshape(frames, n_points, 4)
        xyz = pts[..., :3]
        w = pts[..., 3]
        w_ok = np.isfinite(w)
        w_int = np.where(w_ok, np.trunc(np.where(w_ok, w, -1.0)), -1.0)
        nonint = int(np.count_nonzero(w_ok & (w >= 0) & (w != w_int)))
        if nonint:
            warnings.append(f"{nonint} samples have a fractional fourth word; read as the integer part, "
                            f"as the format stores a 16-bit integer there")
        big = int(np.count_nonzero(w_int > 32767))
        if big:
            warnings.append(f"{big} samples have a fourth word above 32767; only its low 16 bits are used")
        w4 = np.clip(w_int, -1, None).astype(np.int64)
    else:
        vals = np.frombuffer(buf, codec.end + "i2", frames * frame_words, dstart).reshape(frames, frame_words)
        pts = vals[:, :4 * n_points].reshape(frames, n_points, 4)
        xyz = pts[..., :3].astype(np.float64) * absscale
        w4 = pts[..., 3].astype(np.int64)

    finite = np.isfinite(xyz).all(axis=-1)
    valid = (w4 >= 0) & finite
    odd = int(np.count_nonzero((w4 >= 0) & ~finite))
    if odd:
        warnings.append(f"{odd} samples have non-finite coordinates but a valid residual word; read as invalid")
    positions = np.where(valid[..., None], xyz, np.nan)
    residuals = np.where(valid, (w4 & 0xFF) * absscale, np.nan)
    masks = np.where(valid, (w4 >> 8) & 0x7F, 0).astype(np.uint8)
    return info, (positions, residuals, masks)


def _labels(parameters: dict, n_points: int, warnings: list[str]) -> list[str]:
    """POINT:LABELS, LABELS2, LABELS3, ... concatenated, one per point."""
    point = parameters.get("POINT", {})
    labels: list[str] = []
    k = 1
    while True:
        v = point.get("LABELS" if k == 1 else f"LABELS{k}")
        if v is None:
            break
        labels.extend([v] if isinstance(v, str) else [str(x) for x in np.ravel(np.array(v, dtype=object))])
        k += 1
    if len(labels) < n_points:
        if n_points:
            warnings.append(f"{n_points - len(labels)} of {n_points} points have no label; "
                            f"named Point_<n> (1-based)")
        labels += [f"Point_{i + 1}" for i in range(len(labels), n_points)]
    return labels[:n_points]


def read_c3d(path: str | os.PathLike) -> C3DData:
    """Read the 3D points of a C3D file.

    Reads Intel, DEC and MIPS (SGI) files, integer and float formats, labels
    beyond 255 points (LABELS2, ...), long files (POINT:LONG_FRAMES, TRIAL
    ACTUAL_START_FIELD / ACTUAL_END_FIELD, float POINT:FRAMES).  Analog data
    are skipped.

    A malformed parameter record does not stop the reading: the parameters
    before it are kept, the header provides point count, frames, scale, rate
    and data start, and ``warnings`` says what was wrong.

    Parameters
    ----------
    path : str or path-like

    Returns
    -------
    C3DData

    Raises
    ------
    CaraError
        Missing or unreadable file, not a C3D file (header byte 2 is not 0x50,
        parameter pointer outside the file), or a data section shorter than
        the frames it declares.  The message names the file.
    """
    return _read(path)[0]


def _read(path) -> tuple[C3DData, dict]:
    info, (positions, residuals, masks) = _parse(path)
    return C3DData(positions=positions, residuals=residuals, camera_masks=masks, labels=info["labels"],
                   rate=info["rate"], units=info["units"], first_frame=info["first_frame"],
                   scale=info["scale"], processor=_PROCESSOR_NAMES[info["processor"]],
                   warnings=info["warnings"], parameters=info["parameters"]), info


def c3d_info(path: str | os.PathLike, max_labels: int = 10) -> dict:
    """Summary of a C3D file for ``carapost info``.

    Parameters
    ----------
    path : str or path-like
    max_labels : int
        How many labels to list.

    Returns
    -------
    dict
        ``file, kind, points, frames, first_frame, rate, duration_s, units,
        processor, format ('int' | 'float'), scale, labels (first few),
        valid_fraction, camera_masks (samples with a mask), analog_words_per_frame,
        groups, warnings``.

    Raises
    ------
    CaraError
        As :func:`read_c3d`.
    """
    d, info = _read(path)
    valid = d.valid
    n = valid.size
    return {
        "file": str(path), "kind": "C3D motion capture",
        "points": d.points, "frames": d.frames, "first_frame": d.first_frame,
        "rate": d.rate, "duration_s": round(d.frames / d.rate, 3) if d.rate > 0 else None,
        "units": d.units, "processor": d.processor, "format": "float" if d.is_float else "int",
        "scale": d.scale,
        "labels": d.labels[:max_labels] + ([f"... {d.points - max_labels} more"] if d.points > max_labels else []),
        "valid_fraction": round(float(valid.sum()) / n, 4) if n else 0.0,
        "camera_masks": int(np.count_nonzero(d.camera_masks)),
        "analog_words_per_frame": info["analog_words"],
        "groups": sorted(d.parameters),
        "warnings": d.warnings,
    }


# --------------------------------------------------------------------------- writer

def _record(gid: int, name: str, body: bytes, locked: bool = False) -> bytes:
    """A group (gid < 0) or parameter record: name length, id, name, offset to next, body."""
    nb = name.encode("ascii")
    if not 1 <= len(nb) <= 127:
        raise ValueError(f"C3D group/parameter name {name!r} must have 1 to 127 characters")
    off = 2 + len(body)
    if off > _MAX_RECORD:
        raise ValueError(f"C3D parameter {name} is {len(body)} bytes, more than a record can hold")
    return struct.pack("<bb", -len(nb) if locked else len(nb), gid) + nb + struct.pack("<h", off) + body


def _group_record(gid: int, name: str, desc: str = "") -> bytes:
    d = desc.encode("ascii", "replace")[:255]
    return _record(-gid, name, bytes([len(d)]) + d)


def _param_body(bpe: int, dims: list[int], data: bytes, desc: str = "") -> bytes:
    if len(dims) > 7 or any(not 0 <= x <= 255 for x in dims):
        raise ValueError(f"C3D parameter dimensions {dims} out of range (at most 7, each 0-255)")
    d = desc.encode("ascii", "replace")[:255]
    return struct.pack("<bB", bpe, len(dims)) + bytes(dims) + data + bytes([len(d)]) + d


def _text_array(strings: list[str], min_len: int = 1) -> tuple[list[int], bytes]:
    """Dims and bytes of a character array: every string space-padded to the longest."""
    enc = [s.encode("utf-8") for s in strings]
    n = max([min_len] + [len(e) for e in enc])
    if n > 255:
        raise ValueError(f"C3D strings are at most 255 bytes; got {n}")
    return [n, len(enc)], b"".join(e.ljust(n, b" ") for e in enc)


def _encode_value(value: Any) -> tuple[int, list[int], bytes]:
    """(element size, dims, bytes) of a Python value, for extra_params."""
    if isinstance(value, str):
        b = value.encode("utf-8")
        return -1, [len(b)], b
    if isinstance(value, (bytes, bytearray)):
        return 1, [len(value)], bytes(value)
    if isinstance(value, (list, tuple)) and value and all(isinstance(v, str) for v in value):
        dims, data = _text_array(list(value))
        return -1, dims, data
    arr = np.asarray(value)
    if arr.dtype.kind == "b":
        arr = arr.astype(np.int16)
    if arr.dtype.kind in "iu":
        if arr.size and (arr.min() < -32768 or arr.max() > 65535):
            arr, bpe, dt = arr.astype(np.float64), 4, "<f4"
        else:
            bpe, dt = 2, "<i2"
            arr = arr.astype(np.int64)
            arr = np.where(arr > 32767, arr - 65536, arr)  # unsigned 16-bit values as their bit pattern
    elif arr.dtype.kind == "f":
        bpe, dt = 4, "<f4"
    else:
        raise ValueError(f"cannot store a {type(value).__name__} as a C3D parameter")
    dims = [] if arr.ndim == 0 else list(arr.shape[::-1])
    return bpe, dims, np.ascontiguousarray(arr, dtype=dt).tobytes()


def _auto_scale(positions: np.ndarray, valid: np.ndarray, residuals: np.ndarray | None) -> float:
    """|POINT:SCALE| so that integer coordinates fit (max/32000) and residuals fit in a byte (max/255)."""
    s = 0.0
    if valid.any():
        s = float(np.abs(positions[valid]).max()) / 32000.0
        if residuals is not None:
            r = residuals[valid]
            r = r[np.isfinite(r)]
            if r.size:
                s = max(s, float(r.max()) / 255.0)
    return s if s > 0 and math.isfinite(s) else 0.1


def write_c3d(path: str | os.PathLike, positions: np.ndarray, labels: list[str], rate: float,
              residuals: np.ndarray | None = None, camera_masks: np.ndarray | None = None,
              descriptions: list[str] | None = None, first_frame: int = 1, units: str = "mm",
              float_format: bool = True, point_scale: float | None = None,
              extra_params: dict | None = None) -> None:
    """Write 3D points to a C3D file (Intel byte order), atomically.

    Parameters
    ----------
    path : str or path-like
        The file to write; written to a temporary file in the same folder,
        synced, then renamed over ``path`` (no partial file on failure).
    positions : ndarray, shape (F, P, 3)
        Coordinates in ``units``; NaN (any of x, y, z) marks a missing sample.
    labels : list of str
        One per point, at most 255 bytes each.
    rate : float
        Frames per second (> 0).
    residuals : ndarray, shape (F, P), optional
        Residual of each present sample (>= 0, same units as POINT:SCALE's
        magnitude); stored as a byte in units of |POINT:SCALE|, clamped to
        0..255, and at least 1 when > 0 (a 0 byte means "modelled sample" in
        C3D).  A negative residual marks the sample missing; NaN is stored as 0.
        Default: 0 for every present sample.
    camera_masks : ndarray, shape (F, P), uint8, optional
        Bit i set = sensor i contributed (bits 0-6 only: bit 7 would make the
        16-bit word negative, i.e. invalid).  Default 0.
    descriptions : list of str, optional
        POINT:DESCRIPTIONS, one per point (default empty).
    first_frame : int
        Number of the first frame (C3D frames start at 1).
    units : str
        POINT:UNITS.
    float_format : bool
        True: float32 coordinates (POINT:SCALE negative); False: int16
        coordinates times |POINT:SCALE|.
    point_scale : float, optional
        |POINT:SCALE|; default: max(max |coordinate| / 32000, max residual / 255),
        or 0.1 when there is no data.
    extra_params : dict, optional
        ``{GROUP: {NAME: value}}`` further parameters: str, list of str, int,
        float, bytes or numeric arrays.  The parameters the writer derives from
        the data (POINT:USED, SCALE, RATE, DATA_START, FRAMES, LONG_FRAMES,
        UNITS, LABELS*, DESCRIPTIONS*, ANALOG:USED, RATE, TRIAL:ACTUAL_*) cannot
        be given here.

    Raises
    ------
    ValueError
        Inconsistent shapes, rate <= 0, camera masks above 7 bits, integer
        coordinates that do not fit POINT:SCALE, a parameter section over 255 blocks.
    CaraError
        The file cannot be written (folder missing or not writable, ...).
    """
    path = Path(path)
    pos = np.asarray(positions, dtype=np.float64)
    if pos.ndim != 3 or pos.shape[2] != 3:
        raise ValueError(f"positions must have shape (frames, points, 3); got {pos.shape}")
    F, P, _ = pos.shape
    labels = [str(x) for x in labels]
    if len(labels) != P:
        raise ValueError(f"{len(labels)} labels for {P} points")
    if P > 65535:
        raise ValueError(f"a C3D file holds at most 65535 points; got {P}")
    rate = float(rate)
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be > 0; got {rate}")
    first_frame = int(first_frame)
    if first_frame < 1:
        raise ValueError(f"first_frame must be >= 1 (C3D frame numbers start at 1); got {first_frame}")
    valid = np.isfinite(pos).all(axis=2)
    res = None
    if residuals is not None:
        res = np.asarray(residuals, dtype=np.float64)
        if res.shape != (F, P):
            raise ValueError(f"residuals must have shape {(F, P)}; got {res.shape}")
        valid &= ~(res < 0)
    masks = None
    if camera_masks is not None:
        masks = np.asarray(camera_masks)
        if masks.shape != (F, P):
            raise ValueError(f"camera_masks must have shape {(F, P)}; got {masks.shape}")
        if np.any(masks[valid].astype(np.int64) & ~0x7F):
            raise ValueError("camera masks hold 7 bits (sensors 0-6); bit 7 would mark the sample invalid")
    if descriptions is not None:
        descriptions = [str(x) for x in descriptions]
        if len(descriptions) != P:
            raise ValueError(f"{len(descriptions)} descriptions for {P} points")
    else:
        descriptions = [""] * P

    if point_scale is None:
        scale = _auto_scale(pos, valid, res)
    else:
        scale = abs(float(point_scale))
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"point_scale must be non-zero and finite; got {point_scale}")

    # ---- the fourth word: mask << 8 | residual byte, -1 for a missing sample
    word4 = np.full((F, P), -1, dtype=np.int32)
    low = np.zeros((F, P), dtype=np.int32)
    if res is not None:
        q = np.where(np.isfinite(res) & valid, res, 0.0) / scale
        low = np.clip(np.rint(q), 0, 255).astype(np.int32)
        low[(q > 0) & (low == 0)] = 1  # a measured (> 0) residual must not read as "modelled"
    high = np.zeros((F, P), dtype=np.int32) if masks is None else (masks.astype(np.int32) & 0x7F)
    word4[valid] = (high[valid] << 8) | low[valid]

    # ---- data section
    if float_format:
        data = np.zeros((F, P, 4), dtype="<f4")
        data[..., :3] = np.where(valid[..., None], pos, 0.0)
        data[..., 3] = word4
    else:
        ints = np.rint(np.where(valid[..., None], pos, 0.0) / scale)
        if ints.size and np.abs(ints).max() > 32767:
            raise ValueError(f"coordinates up to {np.abs(pos[valid]).max():g} do not fit 16-bit integers "
                             f"with POINT:SCALE {scale:g}; use a larger point_scale or float_format")
        data = np.empty((F, P, 4), dtype="<i2")
        data[..., :3] = ints
        data[..., 3] = word4
    data_bytes = data.tobytes()

    # ---- parameters
    last = first_frame + F - 1
    groups: dict[str, list[tuple[str, int, list[int], bytes, bool]]] = {"POINT": [], "ANALOG": [], "TRIAL": [],
                                                                       "MANUFACTURER": []}

    def add(g: str, name: str, bpe: int, dims: list[int], data: bytes, locked: bool = False) -> None:
        groups.setdefault(g, []).append((name, bpe, dims, data, locked))

    def i16(v: int) -> bytes:
        return struct.pack("<H", v & 0xFFFF)  # unsigned 16-bit values as the int16 bit pattern

    pt = "POINT"
    add(pt, "USED", 2, [], i16(P), True)
    add(pt, "SCALE", 4, [], struct.pack("<f", -scale if float_format else scale), True)
    add(pt, "RATE", 4, [], struct.pack("<f", rate), True)
    add(pt, "DATA_START", 2, [], b"\0\0", True)  # filled in below, once the section size is known
    add(pt, "FRAMES", 2, [], i16(min(F, 65535)), True)  # the guide: 65535 when the count is larger
    if F > 32767:
        # Readers that take FRAMES as signed stop at 32767: give the count also as
        # a float (C-Motion) besides the TRIAL group (Vicon) written below.
        add(pt, "LONG_FRAMES", 4, [], struct.pack("<f", float(F)), True)
    ub = units.encode("utf-8")
    add(pt, "UNITS", -1, [len(ub)], ub)
    label_len = max([4] + [len(x.encode("utf-8")) for x in labels])
    desc_len = max([1] + [len(x.encode("utf-8")) for x in descriptions])
    # Up to 255 entries per parameter (a dimension is a byte) and a record must stay
    # below 32767 bytes: LABELS, LABELS2, ... hold consecutive runs of points.
    per = max(1, min(_LABELS_PER_PARAM, 32000 // max(label_len, desc_len)))
    chunks = [(i, min(i + per, P)) for i in range(0, P, per)] or [(0, 0)]
    for k, (a, b) in enumerate(chunks):
        sfx = "" if k == 0 else str(k + 1)
        dims, d = _text_array(labels[a:b], label_len)
        add(pt, "LABELS" + sfx, -1, [label_len, b - a] if b > a else [label_len, 0], d)
        dims, d = _text_array(descriptions[a:b], desc_len)
        add(pt, "DESCRIPTIONS" + sfx, -1, [desc_len, b - a] if b > a else [desc_len, 0], d)
    add("ANALOG", "USED", 2, [], i16(0), True)
    add("ANALOG", "RATE", 4, [], struct.pack("<f", 0.0), True)
    # TRIAL:ACTUAL_START_FIELD / ACTUAL_END_FIELD: 32-bit frame numbers as two
    # unsigned 16-bit words, low word first (Vicon's convention for > 65535 frames).
    add("TRIAL", "ACTUAL_START_FIELD", 2, [2], i16(first_frame) + i16(first_frame >> 16))
    add("TRIAL", "ACTUAL_END_FIELD", 2, [2], i16(last) + i16(last >> 16))
    add("TRIAL", "CAMERA_RATE", 4, [], struct.pack("<f", rate))
    from carapost import __version__

    for name, text in (("COMPANY", "carapost"), ("SOFTWARE", "carapost"), ("VERSION_LABEL", __version__)):
        b = text.encode("utf-8")
        add("MANUFACTURER", name, -1, [len(b)], b)

    for g, entries in (extra_params or {}).items():
        g = str(g).upper()
        for name, value in entries.items():
            name = str(name).upper()
            if _reserved(g, name):
                raise ValueError(f"{g}:{name} is written from the data and cannot be given in extra_params")
            bpe, dims, d = _encode_value(value)
            lst = groups.setdefault(g, [])
            lst[:] = [e for e in lst if e[0] != name]  # extra_params replace our defaults (MANUFACTURER)
            lst.append((name, bpe, dims, d, False))

    def build(data_start: int) -> bytes:
        out = [bytes([1, _PARAM_KEY, 0, PROCESSOR_INTEL])]
        for gid, (g, entries) in enumerate(groups.items(), start=1):
            if gid > 127:
                raise ValueError("a C3D file holds at most 127 parameter groups")
            out.append(_group_record(gid, g))
            for name, bpe, dims, d, locked in entries:
                if g == "POINT" and name == "DATA_START":
                    d = i16(data_start)
                out.append(_record(gid, name, _param_body(bpe, dims, d), locked))
        return b"".join(out)

    section = build(0)
    nblocks = (len(section) + 2 + BLOCK - 1) // BLOCK  # + room for the zero terminator
    if nblocks > 255:
        raise ValueError(f"the C3D parameter section needs {nblocks} blocks; the format allows 255")
    data_start = 2 + nblocks
    section = bytearray(build(data_start).ljust(nblocks * BLOCK, b"\0"))
    section[2] = nblocks

    # ---- header (block 1)
    if last <= 65535:
        h_first, h_last = first_frame, last
    else:  # the guide: write 1..65535 (capped at the count) and rely on the TRIAL group
        h_first, h_last = 1, min(F, 65535)
    header = bytearray(BLOCK)
    struct.pack_into("<BBHHHHHfHHf", header, 0, 2, _PARAM_KEY, P, 0, h_first, h_last, 0,
                     -scale if float_format else scale, data_start, 0, rate)
    struct.pack_into("<HH", header, 298, _EVENT_KEY, 0)

    pad = (-len(data_bytes)) % BLOCK
    atomic_write(path, (bytes(header), bytes(section), data_bytes, b"\0" * pad), "C3D file")


