"""Moving synthetic takes with ground truth for the tracking tests and benchmark.

Extends :func:`carapost.core.calib.synthetic.make_scene` (one frame's rig,
brim and face layout) over time: slow head motion inside the helmet with
sudden rig slips, fast jaw opening and closing, blinks (eye markers jump
and vanish for a few frames), per-camera occlusions, whole-marker occlusions
(a hand over the face) and a little bar flex of every camera.  Detections are
the true projections plus noise, with a per-marker blob size, and a few false
detections per image.  No images: patch matching is tested separately.
"""
from __future__ import annotations

import numpy as np
from scipy.spatial.transform import Rotation

from ..calib.synthetic import BRIM_RIG_R, BRIM_RIG_T, Scene, face_surface, make_scene
from ..detections import make_detections
from ..disc_image import disc_image_offsets
from ..project import Project
from ..rig import CameraRig


def _smooth(rng, frames, dims, sigma):
    """Smooth unit-ish noise (Gaussian-filtered white noise)."""
    from scipy.ndimage import gaussian_filter1d

    x = gaussian_filter1d(rng.normal(size=(frames + 6 * int(sigma), dims)), sigma, axis=0)
    x = x[3 * int(sigma):3 * int(sigma) + frames]
    # Scale by the filter's theoretical output std, not the sample's: over a take shorter than a few
    # sigma the sample std is tiny and dividing by it blew slow drift up into huge jumps.
    return x * np.sqrt(2.0 * np.sqrt(np.pi) * sigma)


def _pulses(rng, frames, count, attack, hold):
    """A 0..1 track with ``count`` open-hold-close pulses (smoothstep ramps of ``attack`` frames)."""
    a = np.zeros(frames)
    if count == 0:
        return a
    starts = np.sort(rng.choice(np.arange(5, max(6, frames - attack * 2 - hold - 2)), count, replace=False))
    t = np.arange(frames)
    for s in starts:
        up = np.clip((t - s) / attack, 0, 1)
        down = np.clip((t - s - attack - hold) / attack, 0, 1)
        r = up - down
        a = np.maximum(a, r * r * (3 - 2 * r))
    return a


def make_take(markers: int = 35, frames: int = 300, seed: int = 0, noise: float = 0.05, false_dets: int = 6,
              jaw_mm: float = 14.0, jaw_frames: int = 5, blinks: int = 4, occlusion_rate: float = 0.01,
              hidden_markers: int = 3, slips: int = 2, head_mm: float = 2.0, rig_move: tuple = (0.0, 0.0),
              motion_seed: int | None = None, brim_radius: float = 0.0) -> Scene:
    """Build a moving :class:`Scene` (``scene.extras`` holds ``sizes`` and the event tracks).

    Parameters
    ----------
    markers, frames, seed, noise, false_dets
        As :func:`make_scene`.
    jaw_mm, jaw_frames
        Jaw opening (mm at the chin) and the frames it takes (fast: 14 mm in 5 frames is ~10 px/frame).
    blinks
        Blinks: markers within 12 mm of an eye drop 3 mm and are hidden for 2 frames.
    occlusion_rate
        Fraction of marker-sensor pairs that start a 5-40 frame occlusion per 100 frames.
    hidden_markers
        Markers hidden in every camera for 10-30 frames (re-acquisition).
    slips
        Rig slips: the head jumps 1.5 mm inside the helmet over 3 frames.
    head_mm
        Amplitude of the slow head motion.
    rig_move
        ``(mm, degrees)``: every camera moved rigidly, relative to the face and brim, by a shift and a
        rotation about the face's centre in random directions (the helmet put on again: a second take
        of the same face for Initialize from ROM).
    motion_seed
        Seed of the motion, events and detection noise (default from ``seed``); the face and rig
        layout always come from ``seed``.
    brim_radius
        As :func:`make_scene`: brim dots of this radius (mm), detected at their images' centres.
    """
    base = make_scene(markers, frames=1, seed=seed, noise=noise, false_dets=false_dets, brim_radius=brim_radius)
    rng = np.random.default_rng(seed + 1000 if motion_seed is None else motion_seed)
    S = 4
    cams0 = base.cameras[0]
    if rig_move[0] or rig_move[1]:
        mrng = np.random.default_rng(seed + 2000)
        axis, shift = mrng.normal(size=3), mrng.normal(size=3)
        dR = Rotation.from_rotvec(np.radians(rig_move[1]) * axis / np.linalg.norm(axis)).as_matrix()
        c = base.face[0].mean(axis=0)
        d = rig_move[0] * shift / np.linalg.norm(shift)
        cams0 = [cam.with_pose(cam.rotation @ dR.T, dR @ (cam.position - c) + c + d) for cam in cams0]
    brim = base.brim
    # Rest positions in rig coordinates (world = (Xr - T) @ R).
    Xr0 = base.face[0] @ BRIM_RIG_R.T + BRIM_RIG_T
    to_world = lambda Xr: (Xr - BRIM_RIG_T) @ BRIM_RIG_R
    _, n_rig = face_surface(Xr0[:, 0], Xr0[:, 1])
    # Motion tracks.
    rot = _smooth(rng, frames, 3, 25) * 0.015                 # rad
    trans = _smooth(rng, frames, 3, 25) * head_mm
    for _ in range(slips):
        s0 = int(rng.integers(10, max(11, frames - 10)))
        step = rng.normal(size=3)
        step *= 1.5 / np.linalg.norm(step)
        ramp = np.clip((np.arange(frames) - s0) / 3.0, 0, 1)
        trans += ramp[:, None] * step
    rot -= rot[0]
    trans -= trans[0]
    jaw = _pulses(rng, frames, max(1, frames // 100), jaw_frames, 15)
    w_jaw = np.clip((Xr0[:, 1] - 30.0) / 35.0, 0, 1) ** 1.2
    eyes = np.array([[-30.0, 2.0], [30.0, 2.0]])
    d_eye = np.min(np.linalg.norm(Xr0[:, None, :2] - eyes[None], axis=2), axis=1)
    eye_m = d_eye < 12.0
    blink = _pulses(rng, frames, blinks, 2, 1) if blinks else np.zeros(frames)
    jaw[0] = blink[0] = 0
    face = np.empty((frames, markers, 3))
    cams_f = []
    flex_r = _smooth(rng, frames, 3 * S, 10) * 0.0007
    flex_t = _smooth(rng, frames, 3 * S, 10) * 0.08
    for f in range(frames):
        Xr = Xr0.copy()
        Xr[:, 1] += jaw[f] * jaw_mm * w_jaw
        Xr[:, 2] += jaw[f] * 0.3 * jaw_mm * w_jaw
        Xr[eye_m, 1] += blink[f] * 3.0
        Rh = Rotation.from_rotvec(rot[f]).as_matrix()
        c = Xr0.mean(axis=0)
        Xr = (Xr - c) @ Rh.T + c + trans[f]
        face[f] = to_world(Xr)
        cams = []
        for s, cam in enumerate(cams0):
            if f == 0:
                cams.append(cam)
                continue
            dR = Rotation.from_rotvec(flex_r[f, 3 * s:3 * s + 3] - flex_r[0, 3 * s:3 * s + 3]).as_matrix()
            cams.append(cam.with_pose(dR @ cam.rotation, cam.position + flex_t[f, 3 * s:3 * s + 3]
                                      - flex_t[0, 3 * s:3 * s + 3]))
        cams_f.append(cams)
    # Visibility: facing the camera, in the image, not occluded.
    hidden = np.zeros((frames, S, markers), bool)
    n_events = int(occlusion_rate * markers * S * frames / 100.0)
    for _ in range(n_events):
        m, s = int(rng.integers(markers)), int(rng.integers(S))
        f0 = int(rng.integers(1, frames))
        hidden[f0:f0 + int(rng.integers(5, 41)), s, m] = True
    for _ in range(hidden_markers):
        m = int(rng.integers(markers))
        f0 = int(rng.integers(5, max(6, frames - 40)))
        hidden[f0:f0 + int(rng.integers(10, 31)), :, m] = True
    blinking = (blink > 0.5)
    hidden[np.ix_(blinking, np.arange(S), np.flatnonzero(eye_m))] = True
    sizes = np.column_stack([rng.uniform(7, 10, markers), rng.uniform(5, 7, markers)])
    bsizes = np.column_stack([rng.uniform(7, 10, len(brim)), rng.uniform(5, 7, len(brim))])
    width, height = cams0[0].sensor_size
    proj = Project(frames, S, 60.0, name="synthetic take")
    for s in range(S):
        proj.sensors[s].width, proj.sensors[s].height = width, height
    face_det = np.full((frames, S, markers), -1, int)
    brim_det = np.full((frames, S, len(brim)), -1, int)
    n_w = n_rig @ BRIM_RIG_R
    for f in range(frames):
        Rh = Rotation.from_rotvec(rot[f]).as_matrix()
        nf = n_w @ (BRIM_RIG_R.T @ Rh @ BRIM_RIG_R).T
        for s, cam in enumerate(cams_f[f]):
            uvf = cam.project(face[f])
            view = cam.position - face[f]
            view /= np.linalg.norm(view, axis=1, keepdims=True)
            facing = np.sum(view * nf, axis=1) > 0.25
            inimg = (np.all(np.isfinite(uvf), axis=1) & (uvf[:, 0] > 4) & (uvf[:, 0] < width - 4)
                     & (uvf[:, 1] > 4) & (uvf[:, 1] < height - 4))
            vf = facing & inimg & ~hidden[f, s]
            uvb = cam.project(brim.markers) + disc_image_offsets(cam.project, brim.markers, brim.radius)
            vb = (np.all(np.isfinite(uvb), axis=1) & (uvb[:, 0] > 4) & (uvb[:, 0] < width - 4)
                  & (uvb[:, 1] > 4) & (uvb[:, 1] < height - 4))
            nfd = false_dets
            pts = np.concatenate([uvf[vf], uvb[vb], rng.uniform([0, 0], [width, height], (nfd, 2))])
            nt = vf.sum() + vb.sum()
            pts[:nt] += rng.normal(0, noise, (nt, 2))
            sz = np.concatenate([sizes[vf], bsizes[vb], np.column_stack([rng.uniform(7, 10, nfd),
                                                                          rng.uniform(5, 7, nfd)])])
            sz *= rng.normal(1.0, 0.03, sz.shape)
            order = rng.permutation(len(pts))
            inv = np.empty_like(order)
            inv[order] = np.arange(len(order))
            pts, sz = pts[order], sz[order]
            face_det[f, s, np.flatnonzero(vf)] = inv[:vf.sum()]
            brim_det[f, s, np.flatnonzero(vb)] = inv[vf.sum():nt]
            n = len(pts)
            proj.detections[s].set_frame(f, make_detections(pts[:, 0], pts[:, 1], sz[:, 0], sz[:, 1],
                                                            rng.uniform(-90, 90, n), rng.uniform(0.6, 1.0, n)))
    proj.rig = CameraRig(list(base.project.rig.cameras), frames)
    proj.brim = brim
    return Scene(proj, cams_f, face, face_det, brim_det, brim,
                 extras={"sizes": sizes, "jaw": jaw, "blink": blink, "hidden": hidden, "eye_markers": eye_m})


def initialise(scene: Scene, frame: int = 0, seed: int = 0, stack=None):
    """Brim solve + Initialize 3D on ``frame`` through the headless pipeline (returns its commands)."""
    from ..pipeline import process_to_init3d

    pr = scene.project
    pr.properties.set("initialize_3d.max_allowed_depth", 60.0 if scene.face.shape[1] <= 60 else 16.0)
    return process_to_init3d(pr, scene.seeds(frame=frame, n_face=8, n_brim=5, seed=seed), log=lambda s: None,
                             stack=stack)
