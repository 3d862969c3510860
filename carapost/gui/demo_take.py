"""A small synthetic take for the GUI's tests, benchmark and screenshot (Qt-free).

Four cameras of a head rig look at markers on a face-like surface; every frame
carries the markers' projections as detections (blob detection comes later),
plus a few stray detections, and :class:`ArraySource` renders matching grey
images (dark discs on skin) so the views have something to show.
"""
from __future__ import annotations

import itertools

import numpy as np

from ..core.camera import Camera
from ..core.detections import make_detections
from ..core.project import Project
from ..core.rig import CameraRig

_uids = itertools.count(10_000_000)


def rig_cameras(sensors: int = 4, width: int = 1280, height: int = 720) -> list[Camera]:
    """Cameras on an arc 300 mm in front of the origin, looking at it."""
    cams = []
    for s in range(sensors):
        ang = np.deg2rad(-27 + 18 * s)
        tilt = np.deg2rad(-6 if s % 2 else 6)
        Ry = np.array([[np.cos(ang), 0, -np.sin(ang)], [0, 1, 0], [np.sin(ang), 0, np.cos(ang)]])
        Rx = np.array([[1, 0, 0], [0, np.cos(tilt), -np.sin(tilt)], [0, np.sin(tilt), np.cos(tilt)]])
        R = Rx @ Ry
        centre = -R.T @ np.array([0, 0, 300.0])
        cams.append(Camera(name=f"cam{s}", sensor_size=(width, height), focal_length=1100.0,
                           principal_point=np.array([width / 2, height / 2]), distortion_model="none",
                           rotation=R, position=centre))
    return cams


def face_markers(n: int, seed: int = 0) -> np.ndarray:
    """``(n, 3)`` marker positions (mm) on an ellipsoidal face patch facing the cameras."""
    rng = np.random.default_rng(seed)
    u = rng.uniform(-0.9, 0.9, n)
    v = rng.uniform(-1.0, 1.0, n)
    x, y = 70 * u, 95 * v
    z = -40 * (1 - np.clip(u ** 2 * 0.6 + v ** 2 * 0.4, 0, 1))   # bulging towards the cameras (-z)
    return np.stack([x, y, z], axis=1)


def marker_track(base: np.ndarray, frames: int) -> np.ndarray:
    """``(frames, n, 3)``: small smooth motion of every marker (expressions)."""
    t = np.arange(frames)[:, None, None]
    phase = np.arange(len(base))[None, :, None] * 0.37
    return base[None] + 2.0 * np.sin(t / 9.0 + phase) * np.array([1.0, 0.6, 0.3])


def make_demo_take(frames: int = 30, markers: int = 40, sensors: int = 4, strays: int = 3, seed: int = 0,
                   width: int = 1280, height: int = 720, noise: float = 0.0) -> tuple[Project, np.ndarray]:
    """A rigged take whose detections are the markers' projections.

    Returns
    -------
    project : Project
        Detections on every frame: marker ``i`` is detection ``i`` in every sensor
        (marker order; its centre is the projection plus Gaussian ``noise`` in
        pixels), followed by ``strays`` random ones.
    truth : ndarray (frames, markers, 3)
        The markers' 3D positions.
    """
    rng = np.random.default_rng(seed + 1)
    p = Project(frames, sensors, 60.0, name="demo")
    for s in p.sensors:
        s.width, s.height = width, height
    p.rig = CameraRig(rig_cameras(sensors, width, height), frames)
    truth = marker_track(face_markers(markers, seed), frames)
    for f in range(frames):
        for s in range(sensors):
            uv = p.rig.camera(s, f).project(truth[f])
            if noise:
                uv = uv + rng.normal(0, noise, uv.shape)
            sx, sy = rng.uniform(40, width - 40, strays), rng.uniform(40, height - 40, strays)
            x = np.concatenate([uv[:, 0], sx])
            y = np.concatenate([uv[:, 1], sy])
            n = len(x)
            p.detections[s].set_frame(f, make_detections(x, y, rng.uniform(9, 12, n), rng.uniform(7, 9, n),
                                                         rng.uniform(-40, 40, n), rng.uniform(0.6, 1.0, n)))
    return p, truth


class ArraySource:
    """A channel rendered on demand: grey skin with a dark disc per detection (the FrameSource interface)."""

    kind = "synthetic"

    def __init__(self, project: Project, sensor: int):
        self.project, self.sensor = project, sensor
        s = project.sensors[sensor]
        self.width, self.height, self.frame_count = s.width, s.height, project.frame_count
        self.frame_rate = project.frame_rate
        self.uid = next(_uids)
        yy, xx = np.mgrid[0:self.height, 0:self.width]
        shade = 150 + 40 * np.exp(-(((xx - self.width / 2) / (0.45 * self.width)) ** 2
                                    + ((yy - self.height / 2) / (0.5 * self.height)) ** 2))
        self._base = shade.astype(np.uint8)

    def read(self, index: int) -> np.ndarray:
        img = self._base.copy()
        rec = self.project.detections[self.sensor].frame(index)
        h, w = img.shape
        for x, y, a in zip(rec["x"].astype(float), rec["y"].astype(float), rec["minor"].astype(float)):
            r = max(2.0, a / 2)
            x0, x1 = max(0, int(x - r)), min(w, int(x + r) + 2)
            y0, y1 = max(0, int(y - r)), min(h, int(y + r) + 2)
            if x1 <= x0 or y1 <= y0:
                continue
            gy, gx = np.ogrid[y0:y1, x0:x1]
            img[y0:y1, x0:x1][(gx - x) ** 2 + (gy - y) ** 2 <= r * r] = 35
        return img

    def gop_start(self, index: int) -> int:
        return int(index)

    def read_range(self, start: int, stop: int):
        for i in range(max(0, start), min(stop, self.frame_count)):
            yield i, self.read(i)

    def close(self) -> None:
        pass
