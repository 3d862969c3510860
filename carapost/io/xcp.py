"""Read and write Vicon XCP camera calibration files.

An XCP file is XML::

    <Cameras VERSION="2.0" ...>
      <Camera DEVICEID=".." NAME=".." PIXEL_ASPECT_RATIO="1" SENSOR_SIZE="w h" [SKEW="0"] ...>
        ... other elements (ThresholdGrid, Calibration, ...) ...
        <KeyFrames>
          <KeyFrame FRAME="0" FOCAL_LENGTH="f" ORIENTATION="x y z w" POSITION="x y z"
                    PRINCIPAL_POINT="x y" VICON_RADIAL="w0 w1" | VICON_RADIAL2="Vicon3Parameter cx cy k1 k2 k3"
                    IMAGE_ERROR=".." WORLD_ERROR=".."/>
        </KeyFrames>
      </Camera>
    </Cameras>

FOCAL_LENGTH is in pixels (the guide's "mm" is wrong: the files use it as
pixels in ``K``).  A KeyFrame is valid from its FRAME until the next one
(moving cameras); most files have one per camera.

Round trip: every attribute string is kept as read and only the values of a
:class:`~carapost.core.camera.Camera` that changed since reading are written
again, with the shortest repr that re-reads to the same float.  Unknown
attributes and elements are kept.
"""
from __future__ import annotations

import bisect
import copy
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from lxml import etree

from carapost.core.camera import Camera, quaternion_to_matrix
from carapost.core.errors import CaraError
from carapost.io.atomic import atomic_write

__all__ = ["XcpKeyFrame", "XcpCamera", "XcpFile", "read_xcp", "write_xcp", "xcp_from_cameras"]

_XML_HEADER = b'<?xml version="1.0" encoding="UTF-8" standalone="no" ?>\n'
_RADIAL2_TAG = "Vicon3Parameter"


# --------------------------------------------------------------------------- model

@dataclass
class XcpKeyFrame:
    """One KeyFrame: the calibration valid from ``frame`` until the next KeyFrame.

    Attributes
    ----------
    frame : int
    camera : Camera
        Intrinsics (with the Camera element's NAME, DEVICEID, SENSOR_SIZE,
        PIXEL_ASPECT_RATIO, SKEW) and pose of this keyframe.  Edit it (or replace
        it) and :func:`write_xcp` writes the changed values.
    attrs : dict of str to str
        The KeyFrame's attribute strings as read, in file order.
    element : lxml element or None
        The element read (kept for any child elements); None for new keyframes.
    """

    frame: int
    camera: Camera
    attrs: dict = field(default_factory=dict)
    element: Any = field(default=None, repr=False, compare=False)
    # The camera as read, to tell which values were edited.
    _orig: Camera | None = field(default=None, repr=False, compare=False)


@dataclass
class XcpCamera:
    """One Camera element and its keyframes (sorted by frame).

    Attributes
    ----------
    attrs : dict of str to str
        The Camera element's attribute strings, in file order (editing them
        directly is honoured on write unless the matching Camera value changed).
    keyframes : list of XcpKeyFrame
    element : lxml element or None
        The element read, kept so that unknown child elements (ThresholdGrid,
        Calibration, ...) are written back; None for cameras built from scratch.
    """

    attrs: dict = field(default_factory=dict)
    keyframes: list[XcpKeyFrame] = field(default_factory=list)
    element: Any = field(default=None, repr=False, compare=False)

    def at(self, frame: int) -> Camera:
        """The camera valid on ``frame``: the last keyframe with ``FRAME <= frame``.

        Frames before the first keyframe use the first keyframe.  The Camera
        object of the keyframe is returned (not a copy).
        """
        if not self.keyframes:
            raise ValueError("camera has no keyframes")
        frames = [kf.frame for kf in self.keyframes]
        i = bisect.bisect_right(frames, int(frame)) - 1
        return self.keyframes[max(i, 0)].camera

    @property
    def camera(self) -> Camera:
        """The first keyframe's camera (all there is for static cameras)."""
        return self.at(self.keyframes[0].frame if self.keyframes else 0)

    @property
    def device_id(self) -> str:
        return self.attrs.get("DEVICEID", "")

    @property
    def name(self) -> str:
        return self.attrs.get("NAME", "")


@dataclass
class XcpFile:
    """An XCP file: its cameras, the root element's attributes and the parsed tree.

    Attributes
    ----------
    cameras : list of XcpCamera
    attrs : dict of str to str
        Attributes of the ``<Cameras>`` root (VERSION, SOURCE, NAME, ...).
    tree : lxml ElementTree or None
        The parsed document (kept for elements this module does not model);
        None for files built with :func:`xcp_from_cameras`.
    path : Path or None
        Where it was read from.
    """

    cameras: list[XcpCamera] = field(default_factory=list)
    attrs: dict = field(default_factory=dict)
    tree: Any = field(default=None, repr=False, compare=False)
    path: Path | None = field(default=None, compare=False)

    def cameras_at(self, frame: int) -> list[Camera]:
        """Every camera's calibration valid on ``frame``."""
        return [c.at(frame) for c in self.cameras]


# --------------------------------------------------------------------------- number formatting

def _fmt(x: float) -> str:
    """Shortest text that re-reads to the same float ("1" for 1.0, as Vicon writes)."""
    x = float(x)
    if not np.isfinite(x):
        raise ValueError(f"cannot write the non-finite value {x}")
    if x == int(x) and abs(x) < 1e15:
        return str(int(x))
    return repr(x)


def _fmt_seq(values) -> str:
    return " ".join(_fmt(v) for v in values)


# --------------------------------------------------------------------------- reading

class _Ctx:
    """Where we are in the file, for error messages."""

    def __init__(self, path: Path):
        self.path = path

    def fail(self, elem, message: str):
        where = f"line {elem.sourceline}: " if elem is not None and elem.sourceline else ""
        raise CaraError(f"{where}{message}", self.path)


def _numbers(ctx: _Ctx, elem, name: str, count: int | None, what: str,
             required: bool = True, default=None) -> np.ndarray | None:
    text = elem.get(name)
    if text is None:
        if required:
            ctx.fail(elem, f"{what} has no {name} attribute")
        return default
    parts = text.split()
    if count is not None and len(parts) != count:
        ctx.fail(elem, f"{what} {name} must be {count} number{'s' if count > 1 else ''}, "
                       f"got {len(parts)} ({text!r})")
    try:
        vals = np.array([float(p) for p in parts], dtype=np.float64)
    except ValueError:
        ctx.fail(elem, f"{what} {name} is not numeric: {text!r}")
    if not np.all(np.isfinite(vals)):
        ctx.fail(elem, f"{what} {name} is not finite: {text!r}")
    return vals


def _distortion(ctx: _Ctx, kf, what: str) -> tuple[str, np.ndarray]:
    """The distortion model of a KeyFrame (VICON_RADIAL2 wins if both are present:
    it is the newer, fuller model Nexus writes)."""
    text = kf.get("VICON_RADIAL2")
    if text is not None:
        parts = text.split()
        if parts and parts[0] == _RADIAL2_TAG:
            parts = parts[1:]
        elif parts:
            try:
                float(parts[0])
            except ValueError:
                ctx.fail(kf, f"{what} VICON_RADIAL2 model {parts[0]!r} is not supported "
                             f"(only {_RADIAL2_TAG})")
        if len(parts) != 5:
            ctx.fail(kf, f"{what} VICON_RADIAL2 must be '{_RADIAL2_TAG} cx cy k1 k2 k3', got {text!r}")
        try:
            vals = np.array([float(p) for p in parts])
        except ValueError:
            ctx.fail(kf, f"{what} VICON_RADIAL2 is not numeric: {text!r}")
        if not np.all(np.isfinite(vals)):
            ctx.fail(kf, f"{what} VICON_RADIAL2 is not finite: {text!r}")
        return "VICON_RADIAL2", vals
    if kf.get("VICON_RADIAL") is not None:
        return "VICON_RADIAL", _numbers(ctx, kf, "VICON_RADIAL", 2, what)
    return "none", np.zeros(0)


def _keyframe_elements(cam_el) -> list:
    kfs = cam_el.findall("KeyFrames/KeyFrame")
    return kfs if kfs else cam_el.findall("KeyFrame")


def _read_camera(ctx: _Ctx, index: int, cam_el) -> XcpCamera:
    label = cam_el.get("DEVICEID") or cam_el.get("NAME") or ""
    what = f"Camera {index + 1}" + (f" ({label})" if label else "")
    size = _numbers(ctx, cam_el, "SENSOR_SIZE", 2, what)
    if np.any(size <= 0) or np.any(size != np.round(size)):
        ctx.fail(cam_el, f"{what} SENSOR_SIZE must be two positive integers, got {cam_el.get('SENSOR_SIZE')!r}")
    aspect = _numbers(ctx, cam_el, "PIXEL_ASPECT_RATIO", 1, what, required=False, default=np.ones(1))[0]
    if aspect <= 0:
        ctx.fail(cam_el, f"{what} PIXEL_ASPECT_RATIO must be positive")
    skew = _numbers(ctx, cam_el, "SKEW", 1, what, required=False, default=np.zeros(1))[0]
    kf_els = _keyframe_elements(cam_el)
    if not kf_els:
        ctx.fail(cam_el, f"{what} has no KeyFrame")
    keyframes = []
    for j, kf in enumerate(kf_els):
        kwhat = f"{what} KeyFrame {j + 1}"
        if kf.get("FRAME") is None:
            if len(kf_els) > 1:
                ctx.fail(kf, f"{kwhat} has no FRAME attribute (needed with several keyframes)")
            frame = 0
        else:
            fr = _numbers(ctx, kf, "FRAME", 1, kwhat)[0]
            if fr != int(fr):
                ctx.fail(kf, f"{kwhat} FRAME must be an integer, got {kf.get('FRAME')!r}")
            frame = int(fr)
        if keyframes and frame <= keyframes[-1].frame:
            ctx.fail(kf, f"{kwhat} FRAME {frame} does not follow FRAME {keyframes[-1].frame}: "
                         "keyframes must be in increasing frame order")
        focal = _numbers(ctx, kf, "FOCAL_LENGTH", 1, kwhat)[0]
        if focal <= 0:
            ctx.fail(kf, f"{kwhat} FOCAL_LENGTH must be positive, got {kf.get('FOCAL_LENGTH')!r}")
        q = _numbers(ctx, kf, "ORIENTATION", 4, kwhat)
        if np.linalg.norm(q) < 1e-9:
            ctx.fail(kf, f"{kwhat} ORIENTATION is not a rotation (zero quaternion)")
        pos = _numbers(ctx, kf, "POSITION", 3, kwhat)
        pp = _numbers(ctx, kf, "PRINCIPAL_POINT", 2, kwhat)
        model, dist = _distortion(ctx, kf, kwhat)
        try:
            cam = Camera(name=cam_el.get("NAME", ""), device_id=cam_el.get("DEVICEID", ""),
                         sensor_size=(int(size[0]), int(size[1])), focal_length=focal,
                         principal_point=pp, aspect=aspect, skew=skew, distortion_model=model,
                         distortion=dist, rotation=quaternion_to_matrix(q), position=pos)
        except ValueError as exc:
            ctx.fail(kf, f"{kwhat}: {exc}")
        keyframes.append(XcpKeyFrame(frame=frame, camera=cam, attrs=dict(kf.attrib), element=kf,
                                     _orig=cam.copy()))
    return XcpCamera(attrs=dict(cam_el.attrib), keyframes=keyframes, element=cam_el)


def read_xcp(path) -> XcpFile:
    """Read an XCP calibration file.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    XcpFile

    Raises
    ------
    CaraError
        Naming the file (and the line) when it is missing or unreadable, not
        XML, has no ``<Cameras>`` root or no cameras, a camera without KeyFrame,
        a missing, non-numeric or wrongly sized attribute, or keyframes out of
        order.
    """
    path = Path(path)
    ctx = _Ctx(path)
    # No entity expansion or network access: a calibration file has no business
    # with either, and this keeps hostile XML harmless.
    parser = etree.XMLParser(resolve_entities=False, no_network=True, remove_blank_text=False)
    # Asked before parsing: libxml2 reports a folder either as an I/O error or as an empty
    # document, depending on its state.
    if path.is_dir():
        raise CaraError("is a folder, not an XCP file", path)
    try:
        tree = etree.parse(str(path), parser)
    except OSError as exc:
        if not path.exists():
            raise CaraError("file not found", path) from None
        raise CaraError(f"cannot read the file ({exc})", path) from None
    except etree.XMLSyntaxError as exc:
        raise CaraError(f"not a valid XML (XCP) file: {exc.msg}"
                        + (f" (line {exc.lineno})" if exc.lineno else ""), path) from None
    root = tree.getroot()
    if root.tag != "Cameras":
        raise CaraError(f"not an XCP file: the root element is <{root.tag}>, expected <Cameras>", path)
    cam_els = [c for c in root if c.tag == "Camera"]
    if not cam_els:
        raise CaraError("the XCP file has no <Camera> elements", path)
    cameras = [_read_camera(ctx, i, el) for i, el in enumerate(cam_els)]
    return XcpFile(cameras=cameras, attrs=dict(root.attrib), tree=tree, path=path)


# --------------------------------------------------------------------------- writing

def _camera_level(cam: Camera) -> dict[str, str]:
    """Camera-element attributes a Camera defines."""
    d = {"DEVICEID": cam.device_id, "NAME": cam.name,
         "PIXEL_ASPECT_RATIO": _fmt(cam.aspect),
         "SENSOR_SIZE": f"{cam.sensor_size[0]} {cam.sensor_size[1]}"}
    if cam.skew != 0.0:
        d["SKEW"] = _fmt(cam.skew)
    return d


def _radial_attr(cam: Camera, old: dict) -> tuple[str, str] | None:
    if cam.distortion_model == "VICON_RADIAL":
        return "VICON_RADIAL", _fmt_seq(cam.distortion)
    if cam.distortion_model == "VICON_RADIAL2":
        # Keep the model tag as the file spelled it.
        parts = old.get("VICON_RADIAL2", "").split()
        tag = parts[0] if parts and not _is_number(parts[0]) else _RADIAL2_TAG
        return "VICON_RADIAL2", f"{tag} {_fmt_seq(cam.distortion)}"
    return None


def _is_number(s: str) -> bool:
    try:
        float(s)
    except ValueError:
        return False
    return True


def _merge(old: dict, updates: dict, remove=()) -> dict:
    """``old`` with ``updates`` applied in place (order kept); new keys go in
    alphabetical position when the old keys were sorted (Vicon sorts them)."""
    out = {k: v for k, v in old.items() if k not in remove}
    was_sorted = list(out) == sorted(out)
    out.update(updates)
    if was_sorted:
        out = dict(sorted(out.items()))
    return out


def _camera_attrs(xc: XcpCamera) -> dict:
    """The Camera element's attributes to write."""
    if not xc.keyframes:
        return dict(xc.attrs)
    fields_attr = {"name": "NAME", "device_id": "DEVICEID", "sensor_size": "SENSOR_SIZE",
                   "aspect": "PIXEL_ASPECT_RATIO", "skew": "SKEW"}
    # The values the file holds: every read keyframe was built from this element.
    base = next((kf._orig for kf in xc.keyframes if kf._orig is not None), None)
    updates: dict[str, str] = {}
    for fname, attr in fields_attr.items():
        src = None
        for kf in xc.keyframes:
            ref = kf._orig if kf._orig is not None else base
            if ref is None or getattr(kf.camera, fname) != getattr(ref, fname):
                src = kf.camera
                break
        if src is None:
            continue  # unchanged: keep the original string (or its absence)
        vals = _camera_level(src)
        if attr in vals:
            updates[attr] = vals[attr]
        elif attr == "SKEW" and "SKEW" in xc.attrs:
            updates[attr] = "0"  # the file had SKEW; keep it, now zero
    return _merge(xc.attrs, updates)


def _keyframe_attrs(kf: XcpKeyFrame) -> dict:
    """The KeyFrame element's attributes to write."""
    cam, orig, old = kf.camera, kf._orig, kf.attrs
    updates: dict[str, str] = {}
    remove: list[str] = []
    try:
        same_frame = "FRAME" in old and float(old["FRAME"]) == kf.frame
    except ValueError:
        same_frame = False
    if not same_frame:
        updates["FRAME"] = str(int(kf.frame))
    new = orig is None
    if new or cam.focal_length != orig.focal_length or "FOCAL_LENGTH" not in old:
        updates["FOCAL_LENGTH"] = _fmt(cam.focal_length)
    if new or not np.array_equal(cam.rotation, orig.rotation) or "ORIENTATION" not in old:
        updates["ORIENTATION"] = _fmt_seq(cam.quaternion())
    if new or not np.array_equal(cam.position, orig.position) or "POSITION" not in old:
        updates["POSITION"] = _fmt_seq(cam.position)
    if new or not np.array_equal(cam.principal_point, orig.principal_point) or "PRINCIPAL_POINT" not in old:
        updates["PRINCIPAL_POINT"] = _fmt_seq(cam.principal_point)
    if (new or cam.distortion_model != orig.distortion_model
            or not np.array_equal(cam.distortion, orig.distortion)):
        # A changed model replaces the old attribute(s): leaving a stale one
        # would give readers two disagreeing distortions.
        rad = _radial_attr(cam, old)
        remove = [a for a in ("VICON_RADIAL", "VICON_RADIAL2") if rad is None or a != rad[0]]
        if rad is not None:
            updates[rad[0]] = rad[1]
    return _merge(old, updates, remove)


def _set_attrs(el, attrs: dict) -> None:
    el.attrib.clear()
    for k, v in attrs.items():
        el.set(k, v)


def _fill_slots(parent, tag: str, new_children: list) -> None:
    """Replace ``parent``'s ``tag`` children by ``new_children``, keeping their
    positions among other children and the whitespace around them."""
    old = [c for c in parent if c.tag == tag]
    if not old and not new_children:
        return
    # Whitespace between siblings and before the closing tag, as the file had it.
    if len(old) >= 2:
        sep = old[0].tail
    elif parent.text and not parent.text.strip():
        sep = parent.text
    else:
        sep = "\n"
    if old:
        closing = old[-1].tail
    else:
        closing = parent[-1].tail if len(parent) else parent.text
        parent.text = parent.text if len(parent) else sep
    prev = None
    for i, new in enumerate(new_children):
        if i < len(old):
            new.tail = old[i].tail
            parent.replace(old[i], new)
        else:
            if prev is None:
                parent.append(new)
            else:
                prev.addnext(new)
            if prev is not None:
                prev.tail = sep
            new.tail = closing
        prev = new
    for el in old[len(new_children):]:
        # Removing an element removes its tail: hand the closing whitespace on.
        before = el.getprevious()
        if el is old[-1] and before is not None:
            before.tail = el.tail
        parent.remove(el)


def _indent_new(el, level: int) -> None:
    etree.indent(el, space="  ", level=level)


def _build_keyframe(kf: XcpKeyFrame):
    el = copy.deepcopy(kf.element) if kf.element is not None else etree.Element("KeyFrame")
    _set_attrs(el, _keyframe_attrs(kf))
    return el


def _build_camera(xc: XcpCamera):
    if xc.element is not None:
        el = copy.deepcopy(xc.element)
        el.tail = None
    else:
        el = etree.Element("Camera")
        etree.SubElement(el, "KeyFrames")
    _set_attrs(el, _camera_attrs(xc))
    container = el.find("KeyFrames")
    if container is None:
        container = el if el.find("KeyFrame") is not None else etree.SubElement(el, "KeyFrames")
    _fill_slots(container, "KeyFrame", [_build_keyframe(kf) for kf in xc.keyframes])
    if xc.element is None:
        _indent_new(el, 1)
    return el


def _to_bytes(xcp: XcpFile) -> bytes:
    if xcp.tree is not None:
        tree = copy.deepcopy(xcp.tree)
        root = tree.getroot()
    else:
        root = etree.Element("Cameras")
        root.text = "\n\n  "
        tree = etree.ElementTree(root)
    _set_attrs(root, xcp.attrs)
    _fill_slots(root, "Camera", [_build_camera(xc) for xc in xcp.cameras])
    if xcp.tree is None:
        # Vicon's layout: a blank line between cameras.
        for c in root:
            c.tail = "\n\n  "
        if len(root):
            root[-1].tail = "\n\n"
    # Top-level comments / processing instructions each on their own line (lxml
    # keeps no whitespace outside the root element).
    parts = [_XML_HEADER]
    doctype = tree.docinfo.doctype
    if doctype:
        parts.append(doctype.encode("utf-8") + b"\n")
    for sib in reversed(list(root.itersiblings(preceding=True))):
        sib.tail = None
        parts.append(etree.tostring(sib, encoding="UTF-8", xml_declaration=False) + b"\n")
    root.tail = None
    parts.append(etree.tostring(root, encoding="UTF-8", xml_declaration=False) + b"\n")
    for sib in root.itersiblings():
        sib.tail = None
        parts.append(etree.tostring(sib, encoding="UTF-8", xml_declaration=False) + b"\n")
    return b"".join(parts)


def write_xcp(path, xcp: XcpFile) -> None:
    """Write an XCP file atomically.

    Parameters
    ----------
    path : str or Path
    xcp : XcpFile
        As read (unknown attributes and elements are written back unchanged;
        values of keyframe cameras edited since reading are written from the
        Camera) or from :func:`xcp_from_cameras`.

    Raises
    ------
    CaraError
        Naming the file when it cannot be written (no partial file is left) or
        a camera holds a non-finite value.
    """
    path = Path(path)
    try:
        data = _to_bytes(xcp)
    except ValueError as exc:
        raise CaraError(f"cannot write the calibration: {exc}", path) from None
    atomic_write(path, [data], "the calibration")


def xcp_from_cameras(cameras: list[list[tuple[int, Camera]]], name: str = "") -> XcpFile:
    """Build an XCP file from cameras.

    Parameters
    ----------
    cameras : list of list of (int, Camera)
        Per camera, its keyframes as ``(frame, Camera)``; one keyframe for a
        static camera.  The Camera element's attributes come from the first.
    name : str
        NAME of the ``<Cameras>`` root.

    Returns
    -------
    XcpFile
        With ``VERSION="2.0"``; write it with :func:`write_xcp`.
    """
    out = []
    for i, kfs in enumerate(cameras):
        kfs = sorted(kfs, key=lambda fc: int(fc[0]))
        if not kfs:
            raise ValueError(f"camera {i + 1} has no keyframes")
        frames = [int(f) for f, _ in kfs]
        if len(set(frames)) != len(frames):
            raise ValueError(f"camera {i + 1} has two keyframes on one frame")
        keyframes = []
        for f, cam in kfs:
            kf = XcpKeyFrame(frame=int(f), camera=cam)
            kf.attrs = _keyframe_attrs(kf)      # everything, as a fresh keyframe
            kf._orig = cam.copy()               # ... then tracked like a read one
            keyframes.append(kf)
        xc = XcpCamera(attrs={}, keyframes=keyframes)
        first = kfs[0][1]
        xc.attrs = dict(sorted(_camera_level(first).items()))
        out.append(xc)
    return XcpFile(cameras=out, attrs={"NAME": str(name), "VERSION": "2.0"})
