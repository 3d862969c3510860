"""A take with rig slip and expressions, as 3D points with ground truth (stabilisation tests and benchmark).

The face layout is :func:`carapost.core.calib.synthetic.make_scene`'s.  Over time
the head moves inside the rig (a slow drift plus sudden slips, rotation and
translation) and the face makes expressions: jaw opening, smiles and brow raises
move the lower face, the cheeks and the brows by several millimetres, while the
forehead, the nose bridge and the temples stay rigid on the skull.  Positions
are in the brim (world) frame like a tracked take's; no images or detections.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from .calib.synthetic import BRIM_MARKERS, BRIM_RIG_R, BRIM_RIG_T, make_scene
from .points import BRIM, ST_NONE, ST_RECONSTRUCTED
from .project import Project
from .stabilize import kabsch


@dataclass
class SlipTake:
    """A synthetic take for stabilisation, with its truth.

    Attributes
    ----------
    project : Project
        Face points (ids ``face_ids``, in marker order) and, optionally, brim points.
    truth : ndarray (F, 3, 4)
        The stabilising transforms onto frame 0 (raw to stabilised, world mm).
    rigid : ndarray (M,) bool
        Markers no expression moves.
    gap_free : ndarray (M,) bool
        Markers with a sample on every frame.
    neutral : ndarray (F, M, 3)
        Where the markers would be without expression and noise (the slip alone).
    face_ids, brim_ids : list of int
    """

    project: Project
    truth: np.ndarray
    rigid: np.ndarray
    gap_free: np.ndarray
    neutral: np.ndarray
    face_ids: list
    brim_ids: list


def _activity(rng, frames: int, count: int, min_len: int = 20, max_len: int = 80) -> np.ndarray:
    """A 0..1 track of ``count`` smooth bumps (raised cosines), zero on frame 0."""
    t = np.arange(frames)
    a = np.zeros(frames)
    for _ in range(count):
        width = rng.integers(min_len, max_len + 1)
        c = rng.uniform(1, frames)
        u = np.clip((t - c) / (width / 2), -1, 1)
        a = np.maximum(a, rng.uniform(0.5, 1.0) * 0.5 * (1 + np.cos(np.pi * u)))
    a[0] = 0.0
    return a


def _drift(rng, frames: int, dims: int, sigma: float) -> np.ndarray:
    """Smooth unit-scale noise (Gaussian-filtered white noise)."""
    from scipy.ndimage import gaussian_filter1d

    x = gaussian_filter1d(rng.normal(size=(frames + 6 * int(sigma), dims)), sigma, axis=0)
    x = x[3 * int(sigma):3 * int(sigma) + frames]
    return x / (x.std(axis=0, keepdims=True) + 1e-12)


def make_slip_take(markers: int = 40, frames: int = 300, seed: int = 0, slips: int = 3, slip_mm: float = 2.0,
                   slip_deg: float = 1.5, drift_mm: float = 0.5, expression_mm: float = 6.0,
                   noise_mm: float = 0.03, gappy_fraction: float = 0.25, brim: bool = True) -> SlipTake:
    """Build a :class:`SlipTake` (see the module docstring).

    Parameters
    ----------
    markers, frames, seed
        Face markers, frames, random seed.
    slips, slip_mm, slip_deg
        Sudden rig slips (over 3 frames) and their size.
    drift_mm
        Slow head drift inside the rig (the rotation drift is 0.3 degrees per mm).
    expression_mm
        Largest expression displacement.
    noise_mm
        Reconstruction noise (per coordinate).
    gappy_fraction
        Fraction of markers given one 5-30 frame gap (never on frame 0).
    brim
        Add the brim's points (fixed in the world frame).
    """
    rng = np.random.default_rng(seed)
    rest_w = make_scene(markers, frames=1, seed=seed).face[0]
    xr0 = rest_w @ BRIM_RIG_R.T + BRIM_RIG_T            # rig coordinates: x right, y down the face
    x, y = xr0[:, 0], xr0[:, 1]
    # Expression fields (rig mm per unit activity).
    jaw = np.clip((y - 25) / 40, 0, 1)[:, None] * np.array([0.0, 1.0, 0.3])
    smile = (np.clip((np.abs(x) - 15) / 30, 0, 1) * np.clip((y - 15) / 20, 0, 1))[:, None] \
        * np.column_stack([0.6 * np.sign(x), -0.5 * np.ones_like(x), -0.3 * np.ones_like(x)])
    brow = ((y > -25) & (y < 10) & (np.abs(x) > 12) & (np.abs(x) < 50))[:, None] * np.array([0.0, -0.6, -0.2])
    fields = np.stack([jaw, smile, brow]) * expression_mm             # (3, M, 3)
    rigid = ~np.any(fields != 0, axis=(0, 2))
    acts = np.stack([_activity(rng, frames, max(1, frames // 60)) for _ in range(3)], axis=1)  # (F, 3)
    # Head pose in the rig: drift plus slips; identity on frame 0 (the neutral base frame).
    trans = _drift(rng, frames, 3, 40) * drift_mm
    rot = _drift(rng, frames, 3, 40) * np.radians(0.3 * drift_mm)
    for _ in range(slips):
        s0 = int(rng.integers(5, max(6, frames - 5)))
        ramp = np.clip((np.arange(frames) - s0) / 3.0, 0, 1)[:, None]
        d = rng.normal(size=3)
        trans += ramp * d / np.linalg.norm(d) * slip_mm
        a = rng.normal(size=3)
        rot += ramp * a / np.linalg.norm(a) * np.radians(slip_deg)
    trans -= trans[0]
    rot -= rot[0]
    rh = Rotation.from_rotvec(rot).as_matrix()                       # (F, 3, 3)
    centre = xr0.mean(axis=0)

    def to_world(xr):
        return (xr - BRIM_RIG_T) @ BRIM_RIG_R

    def posed(xr):   # (F, M, 3) rig -> head pose of each frame, in the world
        return to_world(np.einsum("fij,fmj->fmi", rh, xr - centre) + centre + trans[:, None])

    neutral = posed(np.broadcast_to(xr0, (frames,) + xr0.shape))
    face = posed(xr0[None] + np.einsum("fk,kmi->fmi", acts, fields))
    face += rng.normal(0, noise_mm, face.shape)
    truth = kabsch(neutral, np.broadcast_to(neutral[0], neutral.shape))
    present = np.ones((frames, markers), bool)
    gappy = rng.random(markers) < gappy_fraction
    for m in np.flatnonzero(gappy):
        n = int(rng.integers(5, 31))
        f0 = int(rng.integers(1, max(2, frames - n)))
        present[f0:f0 + n, m] = False
    project = Project(frames, 4, 60.0, name="slip take")
    face_ids = []
    for m in range(markers):
        pt = project.new_point(label=f"F{m:03d}")
        pt.pos[:] = np.where(present[:, m, None], face[:, m], np.nan)
        pt.status[:] = np.where(present[:, m], ST_RECONSTRUCTED, ST_NONE)
        pt.residual[present[:, m]] = 0.2
        project.add_point(pt)
        face_ids.append(pt.id)
    brim_ids = []
    if brim:
        for i, (bx, by) in enumerate(BRIM_MARKERS):
            pt = project.new_point(kind=BRIM, label=f"Brim_{i}", brim_index=i)
            pt.pos[:] = np.array([bx, by, 0.0]) + rng.normal(0, noise_mm, (frames, 3))
            pt.status[:] = ST_RECONSTRUCTED
            project.add_point(pt)
            brim_ids.append(pt.id)
    return SlipTake(project, truth, rigid, ~gappy, neutral, face_ids, brim_ids)
