"""A synthetic head-rig scene with ground truth for the calibration tests and benchmarks.

Four cameras on two caddies ~150 mm from a face-like marker cloud on a curved
surface ~140 mm wide, a planar brim above the brows, detections = true
projections + noise + a few false detections, and an XCP-like calibration whose
whole rig is displaced a few mm and 1-2 degrees from the truth.  Independent of
the blob detector and of :mod:`carapost.sample` (which renders images).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial.transform import Rotation

from ..brim import Brim
from ..camera import Camera
from ..detections import make_detections
from ..disc_image import disc_image_offsets
from ..project import Project
from ..rig import CameraRig

BRIM_MARKERS = np.array([
    (-74.2, 9.0), (-73.2, -8.6), (-61.3, 1.2), (-46.1, 12.0), (-42.7, -9.5), (-30.0, 10.5), (-29.5, -6.2),
    (-19.6, -13.9), (-12.2, 8.8), (-9.0, -7.3), (0.7, 1.5), (16.9, -12.8), (18.8, 11.1), (28.8, -8.4),
    (39.8, 11.5), (41.4, -7.7), (53.1, -12.6), (56.1, 4.5), (70.2, -8.0), (74.3, 8.2),
])
_TILT = np.radians(70.0)
BRIM_RIG_R = np.column_stack([(1.0, 0.0, 0.0), (0.0, np.cos(_TILT), np.sin(_TILT)),
                              (0.0, -np.sin(_TILT), np.cos(_TILT))])
BRIM_RIG_T = np.array([0.0, -91.0, -30.0])
_NOMINAL = (((47.0, -44.0, -156.0), (7.0, -24.0, 0.0)), ((55.0, -14.0, -156.0), (7.0, -24.0, 0.0)),
            ((-47.0, -44.0, -156.0), (-7.0, -24.0, 0.0)), ((-55.0, -14.0, -156.0), (-7.0, -24.0, 0.0)))


def _look_at(c, t, down=(0.0, 1.0, 0.0)):
    z = np.asarray(t, float) - c
    z /= np.linalg.norm(z)
    x = np.cross(down, z)
    x /= np.linalg.norm(x)
    return np.vstack([x, np.cross(z, x), z])


def face_surface(x, y):
    """Depth (rig z, mm) and normal of the face surface at rig ``(x, y)``."""
    def z(x, y):
        return (x ** 2 / 180.0 + (y - 10) ** 2 / 400.0
                - 22.0 * np.exp(-(x ** 2 + (y - 5) ** 2 / 2.0) / (2 * 12.0 ** 2)))
    h = 1e-3
    zz = z(x, y)
    dx = (z(x + h, y) - z(x - h, y)) / (2 * h)
    dy = (z(x, y + h) - z(x, y - h)) / (2 * h)
    n = np.stack([dx, dy, -np.ones_like(dx)], axis=-1)   # towards the cameras (-z)
    return zz, n / np.linalg.norm(n, axis=-1, keepdims=True)


def _layout(n: int, rng) -> np.ndarray:
    """``n`` marker positions (rig x, y) spread over a face-shaped region (dart throwing)."""
    spacing = np.sqrt(140 * 135 * 0.75 / n) * 0.85
    out = []
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 200000:
            spacing *= 0.95
            tries = 0
        p = rng.uniform([-70, -50], [70, 85])
        if (p[0] / 70) ** 2 + ((p[1] - 17) / 68) ** 2 > 1:
            continue
        if out and np.min(np.linalg.norm(np.array(out) - p, axis=1)) < spacing:
            continue
        out.append(p)
    return np.array(out)


@dataclass
class Scene:
    """A synthetic take and its truth.

    Attributes
    ----------
    project : Project
        Detections, XCP-like (displaced) rig and brim; no points.
    cameras : list of list of Camera
        True cameras per frame.
    face : ndarray (F, M, 3)
        True face markers, world mm.
    face_det : ndarray (F, S, M) int
        Index of each face marker's detection (-1 when not visible).
    brim_det : ndarray (F, S, B) int
    """

    project: Project
    cameras: list
    face: np.ndarray
    face_det: np.ndarray
    brim_det: np.ndarray
    brim: Brim
    extras: dict = field(default_factory=dict)

    def seeds(self, frame: int = 0, n_face: int = 8, n_brim: int = 5, click_px: float = 0.5, seed: int = 1) -> dict:
        """A ``seeds.json`` dict: brim and face clicks near true detections (CONTRACT section 3)."""
        rng = np.random.default_rng(seed)
        S = self.project.sensor_count
        out = {"frame": frame, "brim": [], "face": []}
        vis_b = np.all(self.brim_det[frame] >= 0, axis=0)
        cand = np.flatnonzero(vis_b)
        pick = cand[np.linspace(0, len(cand) - 1, min(n_brim, len(cand))).round().astype(int)]
        for b in pick:
            uv = {}
            for s in range(S):
                d = self.project.detections[s].frame(frame)[self.brim_det[frame, s, b]]
                uv[str(s)] = [float(d["x"]) + rng.normal(0, click_px), float(d["y"]) + rng.normal(0, click_px)]
            out["brim"].append({"index": int(b), "uv": uv})
        vis = self.face_det[frame] >= 0
        ok = (vis[0] & vis[1]) | (vis[2] & vis[3])
        cand = np.flatnonzero(ok)
        X = self.face[frame, cand]
        chosen = [int(np.argmin(np.abs(X[:, 0])) )]
        while len(chosen) < min(n_face, len(cand)):   # farthest-point sampling: spread over the face
            d = np.min(np.linalg.norm(X[:, None] - X[chosen][None], axis=-1), axis=1)
            chosen.append(int(np.argmax(d)))
        for j, c in enumerate(chosen):
            m = cand[c]
            uv = {}
            for s in range(S):
                i = self.face_det[frame, s, m]
                if i >= 0:
                    d = self.project.detections[s].frame(frame)[i]
                    uv[str(s)] = [float(d["x"]) + rng.normal(0, click_px), float(d["y"]) + rng.normal(0, click_px)]
            out["face"].append({"label": f"Seed_{j}", "uv": uv})
        return out


def make_scene(markers: int = 35, frames: int = 1, seed: int = 0, noise: float = 0.05, false_dets: int = 6,
               width: int = 1280, height: int = 720, brim_radius: float = 0.0) -> Scene:
    """Build a :class:`Scene` (see the module docstring).

    With ``brim_radius`` (mm) the brim's dots are discs of that radius: their detections are the centres
    of their images, off their centres' projections by the perspective offset
    (:func:`~carapost.core.disc_image.disc_image_offsets`), and the brim knows the radius.
    """
    rng = np.random.default_rng(seed)
    scale = width / 1280.0
    brim_w = np.column_stack([BRIM_MARKERS, np.zeros(len(BRIM_MARKERS))])
    brim = Brim("synthetic", brim_w, radius=brim_radius)
    to_world = lambda Xr: (Xr - BRIM_RIG_T) @ BRIM_RIG_R   # rig -> world (brim frame)
    intr, rig_pose = [], []
    for i, (c, t) in enumerate(_NOMINAL):
        c = np.array(c) + rng.normal(0, 1.2, 3)
        t = np.array(t) + rng.normal(0, 1.5, 3)
        roll = Rotation.from_euler("z", rng.normal(0, 0.8), degrees=True).as_matrix()
        rig_pose.append((roll @ _look_at(c, t), c))
        intr.append(dict(name=f"Cam{i}", sensor_size=(width, height), focal_length=525.0 * scale * (1 + rng.normal(0, .01)),
                         principal_point=np.array([width / 2, height / 2]) + rng.normal(0, 5 * scale, 2),
                         distortion_model="VICON_RADIAL",
                         distortion=(1.3e-7 / scale ** 2, 1.5e-14 / scale ** 4)))
    xy = _layout(markers, rng)
    zz, _ = face_surface(xy[:, 0], xy[:, 1])
    face_rig0 = np.column_stack([xy, zz])
    cams_f, face_f = [], []
    for f in range(frames):
        # Head motion inside the helmet and a little expression; bar flex moves cameras slightly.
        hm = Rotation.from_rotvec(rng.normal(0, 0.01, 3)).as_matrix() if f else np.eye(3)
        ht = rng.normal(0, 1.0, 3) if f else np.zeros(3)
        Xr = face_rig0 @ hm.T + ht + (rng.normal(0, 0.8, face_rig0.shape) if f else 0)
        face_f.append(to_world(Xr))
        cams = []
        for i, (Rr, cr) in enumerate(rig_pose):
            if f:
                Rr = Rotation.from_rotvec(rng.normal(0, 0.001, 3)).as_matrix() @ Rr
                cr = cr + rng.normal(0, 0.1, 3)
            cams.append(Camera(rotation=Rr @ BRIM_RIG_R, position=BRIM_RIG_R.T @ (cr - BRIM_RIG_T), **intr[i]))
        cams_f.append(cams)
    face = np.array(face_f)
    # XCP: frame 0's truth with the whole rig displaced (calibration error).
    cen = np.mean([c.position for c in cams_f[0]], axis=0)
    while True:
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        dR = Rotation.from_rotvec(np.radians(rng.uniform(1.0, 2.0)) * axis).as_matrix()
        dt = rng.normal(size=3)
        dt *= rng.uniform(1.5, 3.5) / np.linalg.norm(dt)
        moved = [np.linalg.norm(dR @ (c.position - cen) + cen + dt - c.position) for c in cams_f[0]]
        if 1.5 <= min(moved) and max(moved) <= 5.0:
            break
    xcp = [c.with_pose(c.rotation @ dR.T, dR @ (c.position - cen) + cen + dt) for c in cams_f[0]]
    S = 4
    proj = Project(frames, S, 60.0, name="synthetic")
    for s in range(S):
        proj.sensors[s].width, proj.sensors[s].height = width, height
    face_det = np.full((frames, S, markers), -1, int)
    brim_det = np.full((frames, S, len(brim_w)), -1, int)
    # Face normals in world for the visibility test.
    _, n_rig = face_surface(xy[:, 0], xy[:, 1])
    n_w = n_rig @ BRIM_RIG_R
    for f in range(frames):
        for s, cam in enumerate(cams_f[f]):
            uvf = cam.project(face[f])
            view = cam.position - face[f]
            view /= np.linalg.norm(view, axis=1, keepdims=True)
            facing = np.sum(view * n_w, axis=1) > 0.25
            inimg = np.all(np.isfinite(uvf), axis=1) & (uvf[:, 0] > 4) & (uvf[:, 0] < width - 4) & (uvf[:, 1] > 4) & (uvf[:, 1] < height - 4)
            vf = facing & inimg
            uvb = cam.project(brim_w) + disc_image_offsets(cam.project, brim_w, brim_radius)
            vb = np.all(np.isfinite(uvb), axis=1) & (uvb[:, 0] > 4) & (uvb[:, 0] < width - 4) & (uvb[:, 1] > 4) & (uvb[:, 1] < height - 4)
            pts = np.concatenate([uvf[vf], uvb[vb], rng.uniform([0, 0], [width, height], (false_dets, 2))])
            pts[: vf.sum() + vb.sum()] += rng.normal(0, noise, (vf.sum() + vb.sum(), 2))
            order = rng.permutation(len(pts))
            inv = np.empty_like(order)
            inv[order] = np.arange(len(order))
            pts = pts[order]
            face_det[f, s, np.flatnonzero(vf)] = inv[: vf.sum()]
            brim_det[f, s, np.flatnonzero(vb)] = inv[vf.sum(): vf.sum() + vb.sum()]
            n = len(pts)
            proj.detections[s].set_frame(f, make_detections(pts[:, 0], pts[:, 1], rng.uniform(7, 10, n),
                                                            rng.uniform(5, 7, n), rng.uniform(-90, 90, n),
                                                            rng.uniform(0.6, 1.0, n)))
    proj.rig = CameraRig(xcp, frames)
    proj.brim = brim
    return Scene(proj, cams_f, face, face_det, brim_det, brim)
