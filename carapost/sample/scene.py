"""A sample take as data: the face, its markers, the rig, the motion, the meshes, per-frame geometry.

:func:`build_scene` draws everything a take needs from its seed;
:func:`frame_geometry` poses the face for one frame and returns every surface
and marker in the world (brim) frame; :func:`true_cameras` gives the cameras
of a frame.  Rendering is in :mod:`.render`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from carapost.core.camera import Camera

from .face import (BAND, EXPRESSIONS, EYE_HALF, EYE_U, EYE_V, EYELID_A, EYELID_T_MM, FACE_U, FACE_V, MOUTH_HALF,
                   MOUTH_V, FaceBasis, eyelid_params, inside_face)
from .markers import SURF_FACE, SURF_LID_L, SURF_LID_R, MarkerSet, layout_markers
from .motion import HEAD_PIVOT, Motion, make_motion
from .remount import move_camera, remount_head, rigid_move
from .rig import (BRIM_MARKERS, BRIM_RADIUS, BRIM_RIG_R, BRIM_RIG_T, BRIM_SIZE, RigGeometry, calibration_error,
                  make_rig, world_camera)
from .texture import Atlas, make_atlas

__all__ = ["SURF_BRIM", "Mesh", "Scene", "FrameGeometry", "build_scene", "frame_geometry", "true_cameras",
           "calibration_cameras", "rng_for"]

SURF_BRIM = 3
_LID_NA, _LID_NT = 29, 13          # eyelid mesh resolution (across, down)
_EPS = 0.05                        # finite-difference step for tangents (mm or parameter units)


def rng_for(seed: int, *key: int) -> np.random.Generator:
    """An independent generator per purpose, so that changing one part of the take leaves the others."""
    return np.random.default_rng([int(seed) & 0xFFFFFFFF, *key])


def _face_grid():
    """Parameter grid of the skin: 2 mm, 1 mm around the eyes and lips, 0.25 mm across the lip band."""
    u = np.arange(FACE_U[0], FACE_U[1] + 1e-9, 2.0)
    parts = [np.arange(FACE_V[0], -46.0, 2.0), np.arange(-46.0, -21.0, 1.0), np.arange(-21.0, 19.0, 2.0),
             np.arange(19.0, MOUTH_V - BAND, 1.0), np.arange(MOUTH_V - BAND, MOUTH_V + BAND, 0.25),
             np.arange(MOUTH_V + BAND, 36.0, 1.0), np.arange(36.0, FACE_V[1] + 1e-9, 2.0)]
    v = np.unique(np.round(np.concatenate(parts), 6))
    return u, v


def _grid_tris(nr: int, nc: int, keep_cell=None) -> np.ndarray:
    """Two triangles per cell of an nr x nc vertex grid (row-major), optionally only some cells."""
    r, c = np.meshgrid(np.arange(nr - 1), np.arange(nc - 1), indexing="ij")
    a = r * nc + c
    cells = np.stack([a, a + 1, a + nc, a + nc + 1], axis=-1).reshape(-1, 4)
    if keep_cell is not None:
        cells = cells[keep_cell.ravel()]
    return np.concatenate([cells[:, [0, 1, 2]], cells[:, [1, 3, 2]]])


@dataclass
class Mesh:
    """Static topology and per-vertex attributes of everything drawn (face, band, lids, brim).

    Vertex blocks, in order: skin grid, lip-band duplicates, left lid, right
    lid, brim plate.  ``param`` is in mm: ``(u, v)`` on the skin,
    ``(side * a * EYE_HALF, t * EYELID_T_MM)`` on a lid (x is the offset in u), ``(x, y)`` on the brim.
    """

    u: np.ndarray
    v: np.ndarray
    n_grid: int
    band_src: np.ndarray
    lid_a: np.ndarray
    lid_t: np.ndarray
    brim_xy: np.ndarray
    tris: np.ndarray
    tri_surf: np.ndarray
    surf: np.ndarray
    param: np.ndarray
    atlas: np.ndarray
    basis: FaceBasis = field(repr=False)

    @property
    def atlas_T(self) -> np.ndarray:
        """Texel coordinates, planar (2, V)."""
        return self._planar("atlas")

    @property
    def param_T(self) -> np.ndarray:
        """Surface parameters, planar (2, V)."""
        return self._planar("param")

    def _planar(self, name):
        key = "_" + name + "_T"
        if key not in self.__dict__:
            self.__dict__[key] = np.ascontiguousarray(getattr(self, name).T)
        return self.__dict__[key]


def _build_mesh() -> Mesh:
    u, v = _face_grid()
    nr, nc = len(v), len(u)
    U, V = np.meshgrid(u, v)
    ins = inside_face(U, V)
    keep = ins[:-1, :-1] & ins[1:, :-1] & ins[:-1, 1:] & ins[1:, 1:]
    tris_grid = _grid_tris(nr, nc, keep)
    # Triangles of the lip band get vertices of their own, textured from the band's
    # region of the atlas (teeth, mouth) rather than the skin's.
    cu = U.ravel()[tris_grid].mean(axis=1)
    cv = V.ravel()[tris_grid].mean(axis=1)
    in_band = (np.abs(cv - MOUTH_V) < BAND) & (np.abs(cu) < MOUTH_HALF)
    band_src = np.unique(tris_grid[in_band])
    remap = np.full(nr * nc, -1)
    remap[band_src] = nr * nc + np.arange(len(band_src))
    tris_grid = tris_grid.copy()
    tris_grid[in_band] = remap[tris_grid[in_band]]
    # Eyelids.
    A, T = np.meshgrid(np.linspace(-EYELID_A, EYELID_A, _LID_NA), np.linspace(0.0, 1.0, _LID_NT))
    lid_tris = _grid_tris(_LID_NT, _LID_NA)
    # Brim plate, 4 mm cells.
    bx = np.linspace(-BRIM_SIZE[0] / 2, BRIM_SIZE[0] / 2, 42)
    by = np.linspace(-BRIM_SIZE[1] / 2, BRIM_SIZE[1] / 2, 11)
    BX, BY = np.meshgrid(bx, by)
    brim_tris = _grid_tris(len(by), len(bx))
    g, b, nl = nr * nc, len(band_src), A.size
    tris = np.concatenate([tris_grid, lid_tris + g + b, lid_tris + g + b + nl, brim_tris + g + b + 2 * nl])
    surf_v = np.concatenate([np.zeros(g + b), np.full(nl, SURF_LID_L), np.full(nl, SURF_LID_R),
                             np.full(BX.size, SURF_BRIM)]).astype(np.int8)
    tri_surf = surf_v[tris[:, 0]]
    uu, vv = U.ravel(), V.ravel()
    param = np.concatenate([np.column_stack([uu, vv]), np.column_stack([uu[band_src], vv[band_src]]),
                            np.column_stack([A.ravel() * EYE_HALF, T.ravel() * EYELID_T_MM]),
                            np.column_stack([-A.ravel() * EYE_HALF, T.ravel() * EYELID_T_MM]),
                            np.column_stack([BX.ravel(), BY.ravel()])])
    atlas = np.concatenate([np.column_stack(Atlas.face(uu, vv)),
                            np.column_stack(Atlas.band(uu[band_src], vv[band_src])),
                            np.column_stack(Atlas.lid(1, A.ravel(), T.ravel())),
                            np.column_stack(Atlas.lid(-1, A.ravel(), T.ravel())),
                            np.column_stack(Atlas.brim(BX.ravel(), BY.ravel()))])
    # The lid parameter a grows away from the nose on both eyes, so the right lid's
    # param is flipped above: param x is then the offset in u (mm, image right) on both.
    return Mesh(u=u, v=v, n_grid=g, band_src=band_src, lid_a=A.ravel(), lid_t=T.ravel(),
                brim_xy=np.column_stack([BX.ravel(), BY.ravel()]), tris=tris.astype(np.int64),
                tri_surf=tri_surf, surf=surf_v, param=param.astype(np.float32), atlas=atlas.astype(np.float32),
                basis=FaceBasis(uu, vv))


@dataclass
class Scene:
    """Everything a sample take is drawn from (a function of its parameters and seed).

    Attributes
    ----------
    width, height, frames : int
    rate : float
        Frames per second.
    seed : int
    white : bool
        White markers (on a black brim) instead of black ones (on a white brim).
    noise, blur : float
        Sensor noise (grey levels, standard deviation) and optical blur (Gaussian sigma, px).
    markers : MarkerSet
    rig : RigGeometry
    motion : Motion
    atlas : Atlas
    mesh : Mesh
    calib_dR, calib_dt : ndarray
        The placement error of ``calibration.xcp`` (world frame, about the camera centroid).
    paint : ndarray, shape (P,)
        Albedo of each marker's paint (face markers, then the brim's printed dots).
    motion_seed, rig_move, camera_move :
        The second-take options of :func:`build_scene` (``None``, ``(0, 0)``, ``None``: the seed's own take).
    perspective_dots : bool
        Dots drawn as the images of their discs under perspective (:mod:`.render`); False: under the
        projection's linear map at each centre (the takes of carapost before session 24).
    """

    width: int
    height: int
    frames: int
    rate: float
    seed: int
    white: bool
    noise: float
    blur: float
    markers: MarkerSet
    rig: RigGeometry
    motion: Motion
    atlas: Atlas
    mesh: Mesh
    calib_dR: np.ndarray
    calib_dt: np.ndarray
    paint: np.ndarray
    marker_basis: FaceBasis = field(repr=False, default=None)
    motion_seed: int | None = None
    rig_move: tuple = (0.0, 0.0)
    camera_move: tuple | None = None
    perspective_dots: bool = True

    @property
    def raster_scale(self) -> int:
        """Full-resolution pixels per raster pixel (surfaces are rasterised coarser than markers).

        3 at 960 px and more: the surfaces are smooth at that scale (~1 mm per raster
        pixel on the face), and rasterising is the largest cost of an image.
        """
        return 3 if self.width >= 960 else 1

    @property
    def n_brim(self) -> int:
        return len(BRIM_MARKERS)


# Visibility test points: the centre and 8 points on a circle 1.3 radii out.
_PHI = np.linspace(0.0, 2 * np.pi, 8, endpoint=False)
_RING = np.concatenate([[[0.0, 0.0]], 1.3 * np.column_stack([np.cos(_PHI), np.sin(_PHI)])])   # (9, 2)


def build_scene(markers: int = 100, frames: int = 120, seed: int = 0, white: bool = False, width: int = 1280,
                height: int = 720, rate: float = 60.0, noise: float = 2.0, blur: float = 0.8,
                motion_seed: int | None = None, rig_move=(0.0, 0.0), camera_move=None,
                perspective_dots: bool = True) -> Scene:
    """Draw a sample take.

    Parameters
    ----------
    markers : int
        Painted face markers (35-160 intended).
    frames : int
    seed : int
    white : bool
    width, height : int
        Image size (even numbers).
    rate : float
    noise : float
        Sensor noise, grey levels.
    blur : float
        Optical blur, Gaussian sigma in pixels.
    motion_seed : int, optional
        Seed of the motion (expressions, gaze, slip, flex) instead of ``seed``: another take of the
        same face, markers, rig and brim (:mod:`.remount`).
    rig_move : (float, float)
        ``(mm, degrees)``: the helmet (cameras and brim) put on the head again, shifted and turned
        relative to the face (random directions, exact magnitudes).
    camera_move : (int, float, float), optional
        ``(channel, mm, degrees)``: that camera moved relative to the rest of the rig and the brim.
    perspective_dots : bool
        Draw each dot as its disc's image under perspective, centred a few hundredths of a pixel off
        the projection of its centre as a real lens does (:mod:`.render`).  False draws it as before
        session 24: the image under the projection's linear map at the centre, centred on it.

    Returns
    -------
    Scene
    """
    if frames < 1:
        raise ValueError(f"a take needs at least one frame, not {frames}")
    if width < 64 or height < 64 or width % 2 or height % 2:
        raise ValueError(f"image size {width}x{height}: need even sizes of at least 64")
    ms = layout_markers(int(markers), rng_for(seed, 1))
    motion = make_motion(rng_for(seed if motion_seed is None else motion_seed, 2), int(frames), rate)
    rig = make_rig(rng_for(seed, 3), int(width), int(height))
    # The directions of a move come from the second take's own seed, so that two takes differ.
    move_seed = seed if motion_seed is None else motion_seed
    atlas = make_atlas(rng_for(seed, 4), bool(white), ms.p[ms.surface == SURF_FACE])
    centres_w = (rig.centres - BRIM_RIG_T) @ BRIM_RIG_R
    dR, dt = calibration_error(rng_for(seed, 5), centres_w)
    if camera_move is not None:
        ch, mm, deg = camera_move
        rig = move_camera(rig, int(ch), *rigid_move(rng_for(move_seed, 9), mm, deg))
    face = ms.surface == SURF_FACE
    # Skin markers: centre, u +- eps, v +- eps, then the 8 ring points.
    r = ms.radius[face, None]
    pu = ms.p[face, 0:1] + np.array([0, _EPS, -_EPS, 0, 0])[None, :]
    pv = ms.p[face, 1:2] + np.array([0, 0, 0, _EPS, -_EPS])[None, :]
    ring_u = ms.p[face, 0:1] + r * _RING[1:, 0][None, :]
    ring_v = ms.p[face, 1:2] + r * _RING[1:, 1][None, :]
    mb = FaceBasis(np.concatenate([pu, ring_u], axis=1).ravel(), np.concatenate([pv, ring_v], axis=1).ravel())
    if rig_move[0] or rig_move[1]:
        # About the neutral face's centre (its markers' mean), in rig (= head rest) coordinates.
        centre = mb.pose(np.zeros(len(EXPRESSIONS))).reshape(int(face.sum()), 13, 3)[:, 0].mean(axis=0)
        motion = remount_head(motion, *rigid_move(rng_for(move_seed, 8), *rig_move), centre)
    # Paint: black (albedo ~0.05) or white (~0.9), a little uneven from dot to dot.
    mean, sd = (0.82, 0.02) if white else (0.05, 0.012)
    paint = np.clip(mean + sd * rng_for(seed, 7).standard_normal(len(ms)), 0.01, 0.98)
    paint = np.concatenate([paint, np.full(len(BRIM_MARKERS), 0.85 if white else 0.04)])
    return Scene(width=int(width), height=int(height), frames=int(frames), rate=float(rate), seed=int(seed),
                 white=bool(white), noise=float(noise), blur=float(blur), markers=ms, rig=rig, motion=motion,
                 atlas=atlas, mesh=_build_mesh(), calib_dR=dR, calib_dt=dt, paint=paint, marker_basis=mb,
                 motion_seed=motion_seed, rig_move=tuple(float(v) for v in rig_move),
                 camera_move=None if camera_move is None else (int(camera_move[0]), float(camera_move[1]),
                                                               float(camera_move[2])),
                 perspective_dots=bool(perspective_dots))


@dataclass
class FrameGeometry:
    """One frame, in the world (brim) frame, mm.

    Attributes
    ----------
    verts, normals : ndarray, shape (V, 3)
        Mesh vertices and unit normals (pointing out of the surface, towards the cameras).
    points : ndarray, shape (P, 3)
        Marker centres: the face markers, then the brim markers.
    axes : ndarray, shape (P, 2, 3)
        Two orthogonal unit tangents of each marker's disc.
    normal : ndarray, shape (P, 3)
        Outward normal of each marker's disc.
    radius : ndarray, shape (P,)
    surf : ndarray, shape (P,)
        Surface each marker is on.
    param : ndarray, shape (P, 2)
        Its surface parameters (mm metric of :class:`Mesh`).
    ring : ndarray, shape (P, 9, 3)
        Visibility test points: the centre and 8 surface points 1.3 radii out.
    ring_param : ndarray, shape (P, 9, 2)
    eyes : ndarray, shape (2, 3)
        Cornea centres (left, right) for the eye glints.
    """

    verts: np.ndarray
    normals: np.ndarray
    points: np.ndarray
    axes: np.ndarray
    normal: np.ndarray
    radius: np.ndarray
    surf: np.ndarray
    param: np.ndarray
    ring: np.ndarray
    ring_param: np.ndarray
    eyes: np.ndarray


def _unit(a, axis=-1):
    n = np.linalg.norm(a, axis=axis, keepdims=True)
    return a / np.where(n > 0, n, 1.0)


def _grid_normals(p: np.ndarray, nr: int, nc: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Outward normals of a posed parameter grid (rows v, columns u)."""
    g = p.reshape(nr, nc, 3)
    du = np.gradient(g, u, axis=1)
    dv = np.gradient(g, v, axis=0)
    # u runs image-right, v image-down: du x dv points into the head; outward is the opposite.
    return _unit(-np.cross(du, dv)).reshape(-1, 3)


def _grid_sample(mesh: "Mesh", field: np.ndarray, u, v) -> np.ndarray:
    """Bilinear interpolation of a per-grid-vertex field (e.g. posed positions) at skin parameters."""
    gu, gv = mesh.u, mesh.v
    j = np.clip(np.searchsorted(gu, u) - 1, 0, len(gu) - 2)
    i = np.clip(np.searchsorted(gv, v) - 1, 0, len(gv) - 2)
    fx = ((u - gu[j]) / (gu[j + 1] - gu[j]))[:, None]
    fy = ((v - gv[i]) / (gv[i + 1] - gv[i]))[:, None]
    nc = len(gu)
    a = i * nc + j
    return (field[a] * (1 - fx) * (1 - fy) + field[a + 1] * fx * (1 - fy)
            + field[a + nc] * (1 - fx) * fy + field[a + nc + 1] * fx * fy)


def _lid_points(mesh: "Mesh", grid: np.ndarray, gnorm: np.ndarray, side: int, a, t, closure: float) -> np.ndarray:
    """Posed eyelid points (head coordinates) at lid parameters ``(a, t)``.

    The lid lies over the skin (interpolated from the posed skin grid, so it
    follows every expression) at its stand-off along the skin's normal.
    """
    uu, vv, off = eyelid_params(side, np.ravel(a), np.ravel(t), closure)
    p = _grid_sample(mesh, grid, uu, vv)
    n = _unit(_grid_sample(mesh, gnorm, uu, vv))
    return p + off[:, None] * n


def _to_world_from_head(motion: Motion, f: int, p: np.ndarray) -> np.ndarray:
    rig = (p - HEAD_PIVOT) @ motion.head_R[f].T + HEAD_PIVOT + motion.head_t[f]
    return (rig - BRIM_RIG_T) @ BRIM_RIG_R


def _dir_to_world(motion: Motion, f: int, d: np.ndarray) -> np.ndarray:
    return d @ motion.head_R[f].T @ BRIM_RIG_R


def frame_geometry(scene: Scene, f: int) -> FrameGeometry:
    """Pose the face for frame ``f`` and express every surface and marker in the world frame."""
    mo, mesh, ms = scene.motion, scene.mesh, scene.markers
    w = mo.weights[f]
    nr, nc = len(mesh.v), len(mesh.u)
    grid = mesh.basis.pose(w)
    gnorm = _grid_normals(grid, nr, nc, mesh.u, mesh.v)
    verts = [grid, grid[mesh.band_src]]
    norms = [gnorm, gnorm[mesh.band_src]]
    closure = {1: w[EXPRESSIONS.index("blink_L")], -1: w[EXPRESSIONS.index("blink_R")]}
    for side in (1, -1):
        p = _lid_points(mesh, grid, gnorm, side, mesh.lid_a, mesh.lid_t, closure[side])
        verts.append(p)
        norms.append(_grid_normals(p, _LID_NT, _LID_NA, np.linspace(-EYELID_A, EYELID_A, _LID_NA) * side,
                                   np.linspace(0, 1, _LID_NT)))
    head_v = np.concatenate(verts)
    head_n = np.concatenate(norms)
    nb = len(mesh.brim_xy)
    v_world = np.concatenate([_to_world_from_head(mo, f, head_v),
                              np.column_stack([mesh.brim_xy, np.zeros(nb)])])
    n_world = np.concatenate([_dir_to_world(mo, f, head_n), np.tile([0.0, 0.0, -1.0], (nb, 1))])

    # Markers on the skin: posed centre, tangents, ring.
    face = np.flatnonzero(ms.surface == SURF_FACE)
    q = scene.marker_basis.pose(w).reshape(len(face), 13, 3)
    P = len(ms) + scene.n_brim
    points = np.zeros((P, 3))
    axes = np.zeros((P, 2, 3))
    normal = np.zeros((P, 3))
    ring = np.zeros((P, 9, 3))
    ring_param = np.zeros((P, 9, 2))
    surf = np.concatenate([ms.surface, np.full(scene.n_brim, SURF_BRIM)]).astype(np.int8)
    radius = np.concatenate([ms.radius, np.full(scene.n_brim, BRIM_RADIUS)])
    param = np.zeros((P, 2))
    e1 = _unit(q[:, 1] - q[:, 2])
    n = _unit(-np.cross(q[:, 1] - q[:, 2], q[:, 3] - q[:, 4]))
    points[face] = q[:, 0]
    axes[face, 0] = e1
    axes[face, 1] = np.cross(n, e1)
    normal[face] = n
    ring[face, 0] = q[:, 0]
    ring[face, 1:] = q[:, 5:]
    param[face] = ms.p[face]
    ring_param[face] = ms.p[face, None, :] + ms.radius[face, None, None] * _RING[None]
    # Markers on the eyelids (their skin parameters move with the blink).
    for side, sid in ((1, SURF_LID_L), (-1, SURF_LID_R)):
        idx = np.flatnonzero(ms.surface == sid)
        if idx.size == 0:
            continue
        a0, t0 = ms.p[idx, 0], ms.p[idx, 1]
        r = ms.radius[idx]
        # Lid parameters: u = side * (EYE_U + a * EYE_HALF), so a mm sideways is
        # side / EYE_HALF in a; t spans roughly EYELID_T_MM mm.
        zero5 = np.zeros(5)
        da = np.concatenate([[0, _EPS, -_EPS, 0, 0], _RING[1:, 0] * 0])[None, :] + \
            np.concatenate([zero5, _RING[1:, 0]])[None, :] * (side * r[:, None] / EYE_HALF)
        dt = np.concatenate([[0, 0, 0, _EPS, -_EPS], np.zeros(8)])[None, :] + \
            np.concatenate([zero5, _RING[1:, 1]])[None, :] * (r[:, None] / EYELID_T_MM)
        A = a0[:, None] + da
        T = t0[:, None] + dt
        pts = _lid_points(mesh, grid, gnorm, side, A, T, closure[side]).reshape(len(idx), 13, 3)
        e1 = _unit(pts[:, 1] - pts[:, 2]) * side
        n = _unit(-np.cross(e1, pts[:, 3] - pts[:, 4]))
        points[idx] = pts[:, 0]
        axes[idx, 0] = e1
        axes[idx, 1] = np.cross(n, e1)
        normal[idx] = n
        ring[idx, 0] = pts[:, 0]
        ring[idx, 1:] = pts[:, 5:]
        param[idx] = np.column_stack([a0 * EYE_HALF * side, t0 * EYELID_T_MM])
        ring_param[idx] = np.stack([A[:, [0] + list(range(5, 13))] * EYE_HALF * side,
                                    T[:, [0] + list(range(5, 13))] * EYELID_T_MM], axis=-1)
    nf = len(ms)
    points[:nf] = _to_world_from_head(mo, f, points[:nf])
    ring[:nf] = _to_world_from_head(mo, f, ring[:nf].reshape(-1, 3)).reshape(nf, 9, 3)
    axes[:nf] = _dir_to_world(mo, f, axes[:nf].reshape(-1, 3)).reshape(nf, 2, 3)
    normal[:nf] = _dir_to_world(mo, f, normal[:nf])
    # Brim markers: fixed in the world frame, facing the cameras (-z).
    bm = np.column_stack([BRIM_MARKERS, np.zeros(scene.n_brim)])
    points[nf:] = bm
    axes[nf:, 0] = (1.0, 0.0, 0.0)
    axes[nf:, 1] = (0.0, 1.0, 0.0)
    normal[nf:] = (0.0, 0.0, -1.0)
    param[nf:] = BRIM_MARKERS
    ring[nf:] = bm[:, None, :] + BRIM_RADIUS * np.concatenate([_RING, np.zeros((9, 1))], axis=1)[None]
    ring_param[nf:] = BRIM_MARKERS[:, None, :] + BRIM_RADIUS * _RING[None]
    # Cornea centres: 7.8 mm behind the front of the eye, offset by the gaze.
    g = mo.gaze[f]
    ec = []
    for side in (1, -1):
        front = _grid_sample(mesh, grid, np.array([side * EYE_U + g[0]]), np.array([EYE_V + g[1]]))[0]
        ec.append(front + np.array([0.0, 0.0, 7.8]))
    eyes = _to_world_from_head(mo, f, np.array(ec))
    return FrameGeometry(verts=v_world, normals=n_world, points=points, axes=axes, normal=normal, radius=radius,
                         surf=surf, param=param, ring=ring, ring_param=ring_param, eyes=eyes)


def _rig_pose(scene: Scene, f: int, c: int) -> tuple[np.ndarray, np.ndarray]:
    """Rig-to-camera rotation and centre (rig mm) of camera ``c`` on frame ``f``."""
    mo, rig = scene.motion, scene.rig
    cen = rig.centroid
    R, C = rig.rotations[c], rig.centres[c]
    caddy = 0 if c < 2 else 1
    Rj = mo.bar_R[f] @ mo.caddy_R[f, caddy]
    C = (C - cen) @ Rj.T + cen + mo.bar_t[f] + mo.caddy_t[f, caddy]
    return R @ Rj.T, C


def true_cameras(scene: Scene, f: int) -> list[Camera]:
    """The four true cameras on frame ``f`` (world frame)."""
    out = []
    for c in range(4):
        R, C = _rig_pose(scene, f, c)
        out.append(world_camera(scene.rig.intrinsics[c], R, C))
    return out


def calibration_cameras(scene: Scene) -> list[Camera]:
    """The cameras of ``calibration.xcp``: the rig at rest, placed a few mm and a degree or two off.

    Relative poses are those of the nominal rig (right to the caddies' flex,
    ~0.01 mm); the whole rig is moved by ``calib_dR, calib_dt`` about the camera centroid.
    """
    cams = [world_camera(scene.rig.intrinsics[c], scene.rig.rotations[c], scene.rig.centres[c]) for c in range(4)]
    c0 = np.mean([c.position for c in cams], axis=0)
    out = []
    for cam in cams:
        pos = scene.calib_dR @ (cam.position - c0) + c0 + scene.calib_dt
        out.append(cam.with_pose(cam.rotation @ scene.calib_dR.T, pos))
    return out
