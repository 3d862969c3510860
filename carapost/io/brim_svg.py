"""Calibration brims from SVG (File > Import Calibration Brim [svg], CONTRACT section 4).

Every ``<circle>`` in document order is a brim marker, index 0, 1, ...; its
centre after the SVG transforms, in the user units of the ``viewBox``, is in
millimetres.  Marker ``i`` sits at world ``(cx_i, cy_i, 0)``: the brim defines
the world frame, with no flip of the SVG y axis.  Its ``r`` (scaled by the
transforms) is the printed dot's radius, which the camera solves use to take
the perspective offset of the dot's image off its detections.
"""
from __future__ import annotations

import re
from pathlib import Path

import numpy as np
from lxml import etree

from ..core.brim import Brim
from ..core.errors import CaraError, read_bytes

_SVG_NS = "http://www.w3.org/2000/svg"
_NUM = r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?"


def parse_transform(text: str | None) -> np.ndarray:
    """A 3x3 affine matrix from an SVG ``transform`` attribute (matrix, translate, scale, rotate, skewX, skewY)."""
    m = np.eye(3)
    if not text:
        return m
    for name, args in re.findall(r"(matrix|translate|scale|rotate|skewX|skewY)\s*\(([^)]*)\)", text):
        v = [float(x) for x in re.findall(_NUM, args)]
        t = np.eye(3)
        if name == "matrix" and len(v) == 6:
            t[0, :] = [v[0], v[2], v[4]]
            t[1, :] = [v[1], v[3], v[5]]
        elif name == "translate" and v:
            t[0, 2] = v[0]
            t[1, 2] = v[1] if len(v) > 1 else 0.0
        elif name == "scale" and v:
            t[0, 0] = v[0]
            t[1, 1] = v[1] if len(v) > 1 else v[0]
        elif name == "rotate" and v:
            a = np.deg2rad(v[0])
            r = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
            if len(v) == 3:
                c = np.array([[1, 0, v[1]], [0, 1, v[2]], [0, 0, 1]])
                ci = np.array([[1, 0, -v[1]], [0, 1, -v[2]], [0, 0, 1]])
                r = c @ r @ ci
            t = r
        elif name == "skewX" and v:
            t[0, 1] = np.tan(np.deg2rad(v[0]))
        elif name == "skewY" and v:
            t[1, 0] = np.tan(np.deg2rad(v[0]))
        else:
            raise ValueError(f"bad transform {name}({args})")
        m = m @ t
    return m


def _length(value: str | None) -> float:
    if value is None or not value.strip():
        return 0.0
    m = re.match(_NUM, value.strip())
    if not m:
        raise ValueError(f"bad length {value!r}")
    return float(m.group(0))


def read_brim_svg(path: str | Path) -> Brim:
    """Read a calibration brim from an SVG file.

    Returns
    -------
    Brim
        Markers ``(M, 3)`` in mm with z = 0, the SVG text kept for View > Show Calibration Brim SVG.

    Raises
    ------
    CaraError
        For a missing file, malformed XML, a bad transform or fewer than 4 circles.
    """
    path = Path(path)
    data = read_bytes(path)
    try:
        root = etree.fromstring(data, etree.XMLParser(resolve_entities=False, no_network=True, huge_tree=False))
    except etree.XMLSyntaxError as e:
        raise CaraError(f"not valid SVG/XML: {e}", path) from None
    if etree.QName(root).localname != "svg":
        raise CaraError("not an SVG file (the root element is not <svg>)", path)
    centres, radii = [], []
    try:
        for el in root.iter():
            if not isinstance(el.tag, str) or etree.QName(el).localname != "circle":
                continue
            m = np.eye(3)
            chain = [el] + list(el.iterancestors())
            for node in reversed(chain):
                m = m @ parse_transform(node.get("transform"))
            c = m @ np.array([_length(el.get("cx")), _length(el.get("cy")), 1.0])
            centres.append(c[:2])
            # A circle under a non-uniform scale is an ellipse: its radius is that of the same area.
            radii.append(_length(el.get("r")) * np.sqrt(abs(np.linalg.det(m[:2, :2]))))
    except ValueError as e:
        raise CaraError(f"cannot read a circle: {e}", path) from None
    if len(centres) < 4:
        raise CaraError(f"has {len(centres)} <circle> elements; a calibration brim needs at least 4", path)
    markers = np.zeros((len(centres), 3))
    markers[:, :2] = centres
    return Brim(path.name, markers, svg=data.decode("utf-8", "replace"), radius=radii)


def brim_to_svg(brim: Brim, radius: float = 1.5) -> str:
    """An SVG of a brim following the same convention (used for the default brims and the sample take).

    Dots of unknown radius (0) are drawn with ``radius``.
    """
    xy = brim.markers[:, :2]
    r = np.where(brim.radius > 0, brim.radius, radius)
    lo = xy.min(axis=0) - 5 * r.max()
    hi = xy.max(axis=0) + 5 * r.max()
    w, h = hi - lo
    lines = [f'<svg xmlns="{_SVG_NS}" width="{w:.3f}mm" height="{h:.3f}mm" '
             f'viewBox="{lo[0]:.6g} {lo[1]:.6g} {w:.6g} {h:.6g}">',
             f'  <rect x="{lo[0]:.6g}" y="{lo[1]:.6g}" width="{w:.6g}" height="{h:.6g}" fill="white"/>']
    for (x, y), ri in zip(xy, r):
        lines.append(f'  <circle cx="{x:.6f}" cy="{y:.6f}" r="{ri:g}" fill="black"/>')
    lines.append("</svg>")
    return "\n".join(lines) + "\n"
