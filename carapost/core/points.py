"""Points: a marker's 3D trajectory and, per sensor, the 2D data it is built from.

Every per-frame quantity of a point is an array over the whole take.  Arrays
are point-major (one set of arrays per point) so that the edits artists make
most — one point over a range of frames — touch contiguous memory, and a
command can keep just that slice for undo.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

# Point kinds.
FACE = "face"
BRIM = "brim"
KINDS = (FACE, BRIM)

# Status of a point's 3D sample on a frame.
ST_NONE = 0            #: no 3D position
ST_RECONSTRUCTED = 1   #: triangulated from 2+ sensors
ST_SINGLE = 2          #: on the ray of one sensor's 2D sample
ST_INTERPOLATED = 3    #: predicted / gap-filled, no 2D support
STATUS_NAMES = {ST_NONE: "none", ST_RECONSTRUCTED: "reconstructed", ST_SINGLE: "single-sensor",
                ST_INTERPOLATED: "interpolated"}

# Source of a point's 2D sample in one sensor on a frame.
SRC_NONE = 0        #: no 2D sample
SRC_DETECTION = 1   #: attached blob detection (``det`` holds its index in the frame)
SRC_PATCH = 2       #: grey-level patch track by the automatic tracker
SRC_TARGET = 3      #: target-tracker sample
SRC_KEYFRAME = 4    #: target-tracker keyframe placed by the user
SOURCE_NAMES = {SRC_NONE: "none", SRC_DETECTION: "detection", SRC_PATCH: "patch",
                SRC_TARGET: "target", SRC_KEYFRAME: "keyframe"}

#: Per-frame arrays of a point: name -> (dtype, trailing shape given sensor count S, fill value).
#: Sizes are chosen for ten-minute takes (36,000 frames x 200 points x 4 sensors
#: is 7 million samples): float32 positions resolve 0.00003 mm at 300 mm, far below
#: reconstruction noise, and C3D stores float32 anyway; scores and residuals are
#: display quantities.
POINT_FIELDS: dict[str, tuple[str, str, float]] = {
    "pos": ("<f4", "3", np.nan),
    "status": ("u1", "", ST_NONE),
    "residual": ("<f2", "", np.nan),
    "src": ("u1", "S", SRC_NONE),
    "det": ("<i4", "S", -1),
    "uv": ("<f4", "S2", np.nan),
    "score": ("<f2", "S", np.nan),
}


def field_shape(name: str, frames: int, sensors: int) -> tuple[int, ...]:
    """Full array shape of a point field."""
    tail = POINT_FIELDS[name][1]
    shape = [frames]
    if "S" in tail:
        shape.append(sensors)
    if "3" in tail:
        shape.append(3)
    if "2" in tail:
        shape.append(2)
    return tuple(shape)


@dataclass(eq=False)
class Point:
    """One marker point.

    Attributes
    ----------
    id : int
        Stable identifier (never reused within a project).
    label : str
        Label name, ``""`` when unlabelled.
    kind : str
        ``"face"`` or ``"brim"``.
    brim_index : int
        Index of the brim marker for brim points, else -1.
    pos : ndarray (F, 3) float32
        3D position in mm, NaN where absent.
    status : ndarray (F,) uint8
        ``ST_*`` of each frame.
    residual : ndarray (F,) float16
        RMS reprojection error (px) of the frame's 3D sample.
    src, det, uv, score : ndarray (F, S[, 2])
        Per sensor: ``SRC_*``, attached detection index (-1), 2D position in raw
        pixels, and match score (0-1; target-tracker bars use it).
    keyframes : dict
        ``(frame, sensor) -> (pattern_w, pattern_h, search_w, search_h)`` half-sizes
        in pixels of target-track keyframes.
    """

    id: int
    frames: int
    sensors: int
    label: str = ""
    kind: str = FACE
    brim_index: int = -1
    arrays: dict[str, np.ndarray] = field(default_factory=dict)
    keyframes: dict[tuple[int, int], tuple[float, float, float, float]] = field(default_factory=dict)

    def __post_init__(self):
        for name, (dtype, _tail, fill) in POINT_FIELDS.items():
            if name not in self.arrays:
                self.arrays[name] = np.full(field_shape(name, self.frames, self.sensors), fill, dtype)

    # Attribute access to the arrays keeps algorithm code readable.
    @property
    def pos(self) -> np.ndarray:
        return self.arrays["pos"]

    @property
    def status(self) -> np.ndarray:
        return self.arrays["status"]

    @property
    def residual(self) -> np.ndarray:
        return self.arrays["residual"]

    @property
    def src(self) -> np.ndarray:
        return self.arrays["src"]

    @property
    def det(self) -> np.ndarray:
        return self.arrays["det"]

    @property
    def uv(self) -> np.ndarray:
        return self.arrays["uv"]

    @property
    def score(self) -> np.ndarray:
        return self.arrays["score"]

    @property
    def name(self) -> str:
        """The label, or ``Point_<id>`` when unlabelled (export names)."""
        return self.label or f"Point_{self.id}"

    def present(self) -> np.ndarray:
        """``(F,)`` bool: the point has a 3D position."""
        return self.status != ST_NONE

    def contributing(self) -> np.ndarray:
        """``(F,)`` number of sensors with a 2D sample."""
        return np.count_nonzero(self.src != SRC_NONE, axis=1)

    def slice_copy(self, start: int, stop: int) -> dict[str, np.ndarray]:
        """Copies of every array over frames ``[start, stop)`` (for undo)."""
        return {k: a[start:stop].copy() for k, a in self.arrays.items()}

    def restore_slice(self, start: int, saved: dict[str, np.ndarray]) -> None:
        """Write back what :meth:`slice_copy` returned."""
        for k, a in saved.items():
            self.arrays[k][start:start + len(a)] = a

    def clear_range(self, start: int, stop: int, sensors: list[int] | None = None) -> None:
        """Remove 3D data (and 2D data of ``sensors``; all when None) on ``[start, stop)``."""
        sl = slice(start, stop)
        if sensors is None:
            for name, (_dt, _tail, fill) in POINT_FIELDS.items():
                self.arrays[name][sl] = fill
        else:
            for name in ("src", "det", "uv", "score"):
                self.arrays[name][sl, sensors] = POINT_FIELDS[name][2]

    def nbytes(self) -> int:
        return sum(a.nbytes for a in self.arrays.values())
