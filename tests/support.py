"""Test helpers: synthetic projects and the real files of ../shared/data.

A module of its own (not conftest.py) so that test folders with their own
conftest.py can still import it.
"""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


def shared_file(*parts: str) -> Path:
    """A file of ../shared/data, or skip the test when that folder is absent (a clone elsewhere)."""
    p = SHARED_DATA.joinpath(*parts)
    if not p.exists():
        pytest.skip(f"{p} is absent: ../shared is not beside this clone")
    return p


def make_project(frames: int = 50, sensors: int = 4, points: int = 6, seed: int = 0, with_rig: bool = False):
    """A small project with detections on every frame and partly tracked points."""
    from carapost.core.detections import make_detections
    from carapost.core.points import SRC_DETECTION, ST_RECONSTRUCTED
    from carapost.core.project import Project

    rng = np.random.default_rng(seed)
    p = Project(frames, sensors, 60.0, name="unit")
    for s in range(sensors):
        for f in range(0, frames, 3):
            n = int(rng.integers(0, 12))
            p.detections[s].set_frame(f, make_detections(rng.uniform(0, 1280, n), rng.uniform(0, 720, n),
                                                         rng.uniform(6, 12, n), rng.uniform(4, 6, n),
                                                         rng.uniform(-90, 90, n), rng.uniform(0.4, 1, n)))
    for i in range(points):
        pt = p.new_point(label=f"M{i}" if i % 2 == 0 else "")
        a, b = sorted(rng.integers(0, frames, 2))
        pt.pos[a:b + 1] = rng.normal(0, 30, (b + 1 - a, 3))
        pt.status[a:b + 1] = ST_RECONSTRUCTED
        pt.residual[a:b + 1] = rng.uniform(0, 0.5, b + 1 - a)
        pt.src[a:b + 1, :2] = SRC_DETECTION
        pt.det[a:b + 1, :2] = 0
        pt.uv[a:b + 1, :2] = rng.uniform(0, 700, (b + 1 - a, 2, 2))
        pt.score[a:b + 1, :2] = 1.0
        p.add_point(pt)
    p.labels = [f"M{i}" for i in range(0, points, 2)] + ["Spare"]
    if with_rig:
        from carapost.core.camera import Camera
        from carapost.core.rig import CameraRig

        cams = []
        for s in range(sensors):
            ang = np.deg2rad(-30 + 20 * s)
            R = np.array([[np.cos(ang), 0, -np.sin(ang)], [0, 1, 0], [np.sin(ang), 0, np.cos(ang)]])
            centre = -R.T @ np.array([0, 0, 300.0])
            cams.append(Camera(name=f"cam{s}", sensor_size=(1280, 720), focal_length=1400.0,
                               principal_point=np.array([640.0, 360.0]), distortion_model="VICON_RADIAL",
                               distortion=np.array([1e-8, 1e-15]), rotation=R, position=centre))
        p.rig = CameraRig(cams, frames)
    return p


def make_export_project():
    """(project, a, b, c) for export tests: 20 frames at 60 fps, three points.

    ``a`` "Nose_Tip": every frame, sensors 0, 2, 3, interpolated on frame 5 and
    single-sensor (sensor 1) on frame 6; ``b`` unlabelled, frames 3-7 only; ``c``
    "Brim_0", a brim point on every frame.
    """
    from carapost.core.points import BRIM, SRC_DETECTION, SRC_NONE, ST_INTERPOLATED, ST_RECONSTRUCTED, ST_SINGLE

    p = make_project(frames=20, points=3)
    a, b, c = p.points.values()
    for pt in (a, b, c):
        pt.clear_range(0, 20)
    a.label, b.label, c.label = "Nose_Tip", "", "Brim_0"
    c.kind = BRIM
    a.pos[:] = np.array([10.0, 20.0, 30.0]) + np.arange(20)[:, None]
    a.status[:] = ST_RECONSTRUCTED
    a.residual[:] = 0.5
    a.src[:, [0, 2, 3]] = SRC_DETECTION
    a.status[5] = ST_INTERPOLATED
    a.src[5] = SRC_NONE
    a.status[6] = ST_SINGLE
    a.src[6] = SRC_NONE
    a.src[6, 1] = SRC_DETECTION
    b.pos[3:8] = [1.25, -2.5, 3.75]
    b.status[3:8] = ST_RECONSTRUCTED
    b.residual[3:8] = 0.25
    b.src[3:8, :2] = SRC_DETECTION
    c.pos[:] = [-80, 5, 0]
    c.status[:] = ST_RECONSTRUCTED
    c.src[:] = SRC_DETECTION
    c.residual[:] = 0.1
    return p, a, b, c


#: A rendered take small enough for end-to-end tests whose seeds the pipeline resolves today
#: (blob.black_threshold=0.1; see the README's quick start): 35 markers, 4 frames, seed 3.
SMALL_TAKE = dict(markers=35, frames=4, seed=3)
SMALL_TAKE_SET = {"blob.black_threshold": 0.1}


def write_small_take(folder, take: str = "Sample") -> Path:
    """Render :data:`SMALL_TAKE` into ``folder`` (``<take>_0..3.pico`` and its truth files); returns the folder."""
    from carapost.sample import write_sample

    write_sample(folder, take=take, workers=1, **SMALL_TAKE)
    return Path(folder)


def copy_take(src, dst, take: str, extra=("calibration.xcp", "brim.svg", "seeds.json")) -> Path:
    """Copy the take of folder ``src`` into ``dst`` as ``<take>_0..3.pico`` with the files ``extra``; returns ``dst``."""
    import shutil

    src, dst = Path(src), Path(dst)
    dst.mkdir(parents=True, exist_ok=True)
    for f in sorted(src.glob("*_[0-9].pico")):
        shutil.copy2(f, dst / f"{take}_{f.stem.rsplit('_', 1)[1]}.pico")
    for name in extra:
        shutil.copy2(src / name, dst / name)
    return dst


def remove_marker_detection(sc, f, s, m):
    """Delete marker ``m``'s detection in sensor ``s`` on frame ``f`` of a synthetic take (indices kept in step)."""
    table = sc.project.detections[s]
    rec = table.frame(f)
    i = sc.face_det[f, s, m]
    keep = np.ones(len(rec), bool)
    keep[i] = False
    table.set_frame(f, rec[keep])
    row = sc.face_det[f, s]
    row[row > i] -= 1
    row[m] = -1
    sc.brim_det[f, s][sc.brim_det[f, s] > i] -= 1


def supersampled_dot(rng, size: int, angle: float, semi, ss: int = 8):
    """Where an elliptical dot lies on an ``ss``-times supersampled ``size`` px square, for exact area coverage.

    The dot's centre is drawn within half a pixel of the square's middle; ``semi`` are its semi-axes (px),
    ``angle`` its major axis's direction (degrees).  Returns the sample grid ``(xx, yy)``, the dot's mask on
    it, and the true centre; :func:`area_mean` takes an image on that grid down to pixels.
    """
    yy, xx = (np.mgrid[0:size * ss, 0:size * ss] + 0.5) / ss - 0.5
    cx, cy = size / 2 + rng.uniform(-0.5, 0.5), size / 2 + rng.uniform(-0.5, 0.5)
    t = np.deg2rad(angle)
    u = (xx - cx) * np.cos(t) + (yy - cy) * np.sin(t)
    v = -(xx - cx) * np.sin(t) + (yy - cy) * np.cos(t)
    return xx, yy, (u / semi[0]) ** 2 + (v / semi[1]) ** 2 <= 1, np.array([cx, cy])


def area_mean(img: np.ndarray, ss: int = 8) -> np.ndarray:
    """A supersampled image (:func:`supersampled_dot`) taken down to pixels by the mean of each pixel's samples."""
    n = img.shape[0] // ss
    return img.reshape(n, ss, n, ss).mean((1, 3))
