"""The head-mounted rig: four cameras on two caddies, the calibration brim, and their poses.

Rig coordinates are the head coordinates of :mod:`.face` at rest (``X``
image-right, ``Y`` down, ``Z`` into the face, mm).  The helmet carries both the
camera bar and the brim, so they are fixed in rig coordinates apart from a
small per-frame flex of the camera bar; the head slips inside the helmet.

The world frame is the brim's (CONTRACT section 4): brim marker ``i`` sits at
``(x_i, y_i, 0)``.  In rig coordinates the brim is a plate above the brows,
tilted to face down towards the cameras.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from carapost.core.camera import Camera

__all__ = ["BRIM_MARKERS", "BRIM_RADIUS", "BRIM_SIZE", "BRIM_RIG_R", "BRIM_RIG_T", "CHANNEL_NAMES",
           "RigGeometry", "make_rig", "brim_svg", "calibration_error", "world_camera", "look_at"]

#: Brim marker centres in the brim frame (mm): 20 dots in a pattern with no symmetry,
#: so that no rotation or mirror image of it matches itself.
BRIM_MARKERS = np.array([
    (-74.2, 9.0), (-73.2, -8.6), (-61.3, 1.2), (-46.1, 12.0), (-42.7, -9.5), (-30.0, 10.5), (-29.5, -6.2),
    (-19.6, -13.9), (-12.2, 8.8), (-9.0, -7.3), (0.7, 1.5), (16.9, -12.8), (18.8, 11.1), (28.8, -8.4),
    (39.8, 11.5), (41.4, -7.7), (53.1, -12.6), (56.1, 4.5), (70.2, -8.0), (74.3, 8.2),
])
BRIM_RADIUS = 1.75                  # mm
BRIM_SIZE = (164.0, 38.0)           # plate width, height (mm), centred on the brim origin

# The brim plate in rig coordinates, a visor over the brows: its x axis is the rig
# X; its y axis runs back towards the forehead and a little down (tilted by
# _BRIM_TILT from the rig Y axis), so the cameras below see its underside obliquely.
_BRIM_TILT = np.radians(70.0)
BRIM_RIG_R = np.column_stack([(1.0, 0.0, 0.0),
                              (0.0, np.cos(_BRIM_TILT), np.sin(_BRIM_TILT)),
                              (0.0, -np.sin(_BRIM_TILT), np.cos(_BRIM_TILT))])   # brim -> rig
BRIM_RIG_T = np.array([0.0, -91.0, -30.0])                                       # brim origin in rig

CHANNEL_NAMES = ("L_Upper", "L_Lower", "R_Upper", "R_Lower")

# Nominal camera centres and aim points in rig coordinates: channels 0-1 on the
# left caddy (subject's left = image right), 2-3 on the right one.
_NOMINAL = (
    ((47.0, -44.0, -156.0), (7.0, -24.0, 0.0)),
    ((55.0, -14.0, -156.0), (7.0, -24.0, 0.0)),
    ((-47.0, -44.0, -156.0), (-7.0, -24.0, 0.0)),
    ((-55.0, -14.0, -156.0), (-7.0, -24.0, 0.0)),
)
_FOCAL_1280 = 525.0        # focal length (px) at 1280 px image width
_W0_1280 = 1.3e-7          # VICON_RADIAL w0 at 1280 px width (barrel: ~7 % at the corners)
_W1_1280 = 1.5e-14


def look_at(centre, target, down=(0.0, 1.0, 0.0)) -> np.ndarray:
    """Rotation (rig to camera) of a camera at ``centre`` looking at ``target``, image y along ``down``."""
    z = np.asarray(target, float) - np.asarray(centre, float)
    z /= np.linalg.norm(z)
    x = np.cross(down, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.vstack([x, y, z])


@dataclass
class RigGeometry:
    """Nominal cameras of one rig (rig coordinates) and their intrinsics.

    Attributes
    ----------
    centres : ndarray, shape (4, 3)
        Camera centres, rig mm.
    rotations : ndarray, shape (4, 3, 3)
        Rig-to-camera rotations.
    intrinsics : list of dict
        ``Camera`` keyword arguments (name, device_id, sensor_size,
        focal_length, principal_point, distortion_model, distortion).
    """

    centres: np.ndarray
    rotations: np.ndarray
    intrinsics: list

    @property
    def centroid(self) -> np.ndarray:
        return self.centres.mean(axis=0)


def make_rig(rng: np.random.Generator, width: int, height: int) -> RigGeometry:
    """The nominal rig, with the small differences every real rig has.

    Parameters
    ----------
    rng : numpy.random.Generator
    width, height : int
        Image size; the focal length and distortion scale with the width so that
        the field of view is the same at any size.
    """
    scale = width / 1280.0
    centres, rots, intr = [], [], []
    for i, (c, t) in enumerate(_NOMINAL):
        c = np.array(c) + rng.normal(0.0, 1.2, 3)
        t = np.array(t) + rng.normal(0.0, 1.5, 3)
        roll = Rotation.from_euler("z", rng.normal(0.0, 0.8), degrees=True).as_matrix()
        centres.append(c)
        rots.append(roll @ look_at(c, t))
        f = _FOCAL_1280 * scale * (1.0 + rng.normal(0.0, 0.01))
        pp = np.array([width / 2.0, height / 2.0]) + rng.normal(0.0, 5.0 * scale, 2)
        w0 = _W0_1280 / scale ** 2 * (1.0 + rng.normal(0.0, 0.08))
        w1 = _W1_1280 / scale ** 4 * (1.0 + rng.normal(0.0, 0.2))
        intr.append(dict(name=CHANNEL_NAMES[i], device_id=f"CARA{int(rng.integers(10000, 99999))}-{i}",
                         sensor_size=(width, height), focal_length=f, principal_point=pp,
                         distortion_model="VICON_RADIAL", distortion=(w0, w1)))
    return RigGeometry(np.array(centres), np.array(rots), intr)


def world_camera(intrinsics: dict, rot_rig: np.ndarray, centre_rig: np.ndarray) -> Camera:
    """A :class:`Camera` in the world (brim) frame from its rig-frame pose.

    Rig points are ``X_rig = BRIM_RIG_R X_world + BRIM_RIG_T``, so the world-to-camera
    rotation is ``R_rig BRIM_RIG_R`` and the centre is ``BRIM_RIG_R^T (C_rig - BRIM_RIG_T)``.
    """
    return Camera(rotation=rot_rig @ BRIM_RIG_R, position=BRIM_RIG_R.T @ (centre_rig - BRIM_RIG_T),
                  **intrinsics)


def calibration_error(rng: np.random.Generator, centres_world: np.ndarray):
    """A whole-rig placement error like that of a calibration capture.

    The cameras' poses relative to each other are what a calibration gets
    right; where the whole rig sits relative to the brim is off by a few
    millimetres and a degree or two.  Drawn until every camera centre moves
    1.5-5 mm and the rotation is 0.8-2.5 degrees.

    Returns
    -------
    dR : ndarray, shape (3, 3)
        Rotation applied about the camera centroid.
    dt : ndarray, shape (3,)
        Translation (mm) applied after it.
    """
    c0 = centres_world.mean(axis=0)
    while True:
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        ang = rng.uniform(0.8, 2.5)
        dR = Rotation.from_rotvec(np.radians(ang) * axis).as_matrix()
        dt = rng.normal(size=3)
        dt *= rng.uniform(1.5, 4.0) / np.linalg.norm(dt)
        moved = np.linalg.norm((centres_world - c0) @ dR.T + c0 + dt - centres_world, axis=1)
        if np.all((moved >= 1.5) & (moved <= 5.0)):
            return dR, dt


def brim_svg() -> str:
    """The brim as SVG (CONTRACT section 4): one ``<circle>`` per marker, viewBox units = mm."""
    w, h = BRIM_SIZE
    lines = [
        '<?xml version="1.0" encoding="UTF-8"?>',
        f'<svg xmlns="http://www.w3.org/2000/svg" width="{w:g}mm" height="{h:g}mm" '
        f'viewBox="{-w / 2:g} {-h / 2:g} {w:g} {h:g}">',
        "  <title>carapost sample calibration brim</title>",
        f'  <rect x="{-w / 2:g}" y="{-h / 2:g}" width="{w:g}" height="{h:g}" rx="4" '
        'fill="white" stroke="black" stroke-width="0.3"/>',
    ]
    for x, y in BRIM_MARKERS:
        lines.append(f'  <circle cx="{x:g}" cy="{y:g}" r="{BRIM_RADIUS:g}" fill="black"/>')
    lines.append("</svg>")
    return "\n".join(lines) + "\n"
