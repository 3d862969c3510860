"""The selected Target Tracker keyframe's comparison region and drag handles in a camera view.

The guide ("About target tracks") draws a selected target track as a blue box, the pattern, and a green
cross, the comparison region searched in the next frames, with a green circle at the pattern's middle;
both are resized "using the handles": white squares the user drags.  Here the pattern's handles are the
box's four corners (a corner dragged sets both half sizes) and the region's the cross's four arm ends
(an arm dragged sets that half size).  Sizes stay symmetric about the keyframe's 2D position, whole
pixels, at least 1 px, and the region at least the pattern (a pattern dragged past it takes the region
along).  A drag is one command, :func:`~carapost.core.target_ops.set_keyframe_box`, on release: one
History entry, undone as the Tracker pane's Keyframe box edits are.

Qt-free geometry (:func:`handles`, :func:`grab`, :func:`resized`, :func:`shapes`) and
:func:`selected_keyframe`, which reads the session; :class:`~carapost.gui.cameraview.CameraView` draws
and drags them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.points import SRC_KEYFRAME
from .overlays import boxes, circles, combine, segments

#: Half size of a handle's square, screen pixels.
HANDLE_R = 3.0
#: How near (screen pixels) a press must be to a handle to take it.
GRAB = 7.0
#: Radius of the green circle at the pattern's middle, screen pixels.
MIDDLE_R = 4.0

PATTERN, REGION_W, REGION_H = "pattern", "region_w", "region_h"


@dataclass(frozen=True)
class KeyTarget:
    """The keyframe the handles edit: point ``pid`` on ``frame`` in ``sensor``, at raw ``(x, y)``."""

    pid: int
    frame: int
    sensor: int
    x: float
    y: float
    box: tuple           #: (pattern w, pattern h, region w, region h) half sizes, px


def selected_keyframe(session, sensor: int) -> KeyTarget | None:
    """The keyframe of the one selected point in ``sensor`` on the current frame, or None."""
    p, fd = session.project, session.frame_data()
    if p is None or fd is None or len(session.selection.points) != 1:
        return None
    pid = session.selection.points[0]
    row = fd.row_of(pid)
    if row < 0 or sensor >= p.sensor_count or fd.src[row, sensor] != SRC_KEYFRAME:
        return None
    box = fd.keyboxes.get((row, sensor))
    uv = fd.uv[row, sensor]
    if box is None or not np.all(np.isfinite(uv)):
        return None
    return KeyTarget(int(pid), session.frame, int(sensor), float(uv[0]), float(uv[1]), tuple(float(v) for v in box))


def handles(t: KeyTarget, box=None) -> list[tuple[str, float, float]]:
    """``(kind, x, y)`` of every handle of ``t`` sized by ``box`` (``t.box`` by default), raw pixels."""
    pw, ph, sw, sh = t.box if box is None else box
    x, y = t.x, t.y
    out = [(PATTERN, x + i * pw, y + j * ph) for i in (-1, 1) for j in (-1, 1)]
    out += [(REGION_W, x - sw, y), (REGION_W, x + sw, y), (REGION_H, x, y - sh), (REGION_H, x, y + sh)]
    return out


def grab(t: KeyTarget, x: float, y: float, tolerance: float) -> str | None:
    """The kind of the handle nearest raw ``(x, y)`` within ``tolerance`` (raw pixels), or None."""
    hs = handles(t)
    d = [np.hypot(hx - x, hy - y) for _, hx, hy in hs]
    i = int(np.argmin(d))
    return hs[i][0] if d[i] <= tolerance else None


def resized(box, kind: str, dx: float, dy: float) -> tuple:
    """``box`` with the handle ``kind`` dragged to ``(dx, dy)`` from the keyframe's position (raw pixels)."""
    pw, ph, sw, sh = (float(v) for v in box)
    ax, ay = max(1.0, float(round(abs(dx)))), max(1.0, float(round(abs(dy))))
    if kind == PATTERN:
        pw, ph = ax, ay
        sw, sh = max(sw, pw), max(sh, ph)
    elif kind == REGION_W:
        sw = max(ax, pw)
    elif kind == REGION_H:
        sh = max(ay, ph)
    else:
        raise ValueError(f"no keyframe handle {kind!r}")
    return (pw, ph, sw, sh)


def shapes(t: KeyTarget, box, px: float):
    """Segments of the comparison region (the green cross and the middle's circle) and of the white handles.

    ``px`` is the size of a screen pixel in raw pixels (the handles keep their size at any zoom).
    """
    pw, ph, sw, sh = box
    x, y = t.x, t.y
    region = combine(segments([x - sw, x], [y, y - sh], [x + sw, x], [y, y + sh]),
                     circles([x], [y], MIDDLE_R * px))
    hs = handles(t, box)
    squares = boxes([h[1] for h in hs], [h[2] for h in hs], HANDLE_R * px, HANDLE_R * px)
    return region, squares
