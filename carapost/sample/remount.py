"""A second take of the same face: the helmet put on again, and one camera knocked.

A ROM workflow (Initialize from ROM) needs a take of the same actor, marker
set and brim as the ROM take, but with its own motion and with the rig placed
a little differently.  Two changes, both rigid and deterministic:

- :func:`remount_head`: the helmet (camera bar and brim together) sits on the
  head shifted by a few millimetres and turned by a few degrees; in rig (and
  brim) coordinates the head moves by the inverse, about the face's centre.
  It is folded into the head slip of :class:`~carapost.sample.motion.Motion`,
  so every frame, the truth files and the renderer see it without a change.
- :func:`move_camera`: one camera moved relative to the others (and to the
  brim) on the camera bar.

Directions are drawn from a generator, magnitudes are exact.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np
from scipy.spatial.transform import Rotation

from .motion import HEAD_PIVOT, Motion
from .rig import RigGeometry

__all__ = ["rigid_move", "remount_head", "move_camera"]


def rigid_move(rng: np.random.Generator, shift_mm: float, rotation_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """A rotation of exactly ``rotation_deg`` about a random axis and a shift of exactly ``shift_mm``.

    Returns
    -------
    Q : ndarray (3, 3)
    d : ndarray (3,)
    """
    axis = rng.normal(size=3)
    shift = rng.normal(size=3)
    Q = Rotation.from_rotvec(np.radians(float(rotation_deg)) * axis / np.linalg.norm(axis)).as_matrix()
    return Q, float(shift_mm) * shift / np.linalg.norm(shift)


def remount_head(motion: Motion, Q: np.ndarray, d: np.ndarray, centre: np.ndarray) -> Motion:
    """The motion with the head moved by ``X -> Q (X - centre) + centre + d`` (rig mm) on every frame.

    The head slip is ``X_rig = head_R (p - HEAD_PIVOT) + HEAD_PIVOT + head_t``;
    composing the move after it gives ``head_R' = Q head_R`` and
    ``head_t' = Q (HEAD_PIVOT + head_t - centre) + centre + d - HEAD_PIVOT``.
    """
    head_R = np.einsum("ij,fjk->fik", Q, motion.head_R)
    head_t = (HEAD_PIVOT + motion.head_t - centre) @ Q.T + centre + d - HEAD_PIVOT
    return replace(motion, head_R=head_R, head_t=head_t)


def move_camera(rig: RigGeometry, channel: int, Q: np.ndarray, d: np.ndarray) -> RigGeometry:
    """The rig with camera ``channel`` turned by ``Q`` about its centre and its centre moved by ``d`` (rig mm)."""
    if not 0 <= int(channel) < len(rig.centres):
        raise ValueError(f"camera_move: no camera {channel} (cameras 0-{len(rig.centres) - 1})")
    centres, rotations = rig.centres.copy(), rig.rotations.copy()
    centres[channel] = centres[channel] + d
    # rotations are rig-to-camera: turning the camera by Q in the rig makes it R Q^T.
    rotations[channel] = rotations[channel] @ Q.T
    return replace(rig, centres=centres, rotations=rotations)
