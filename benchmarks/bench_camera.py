"""Camera-model hot paths: batched triangulation and projection for one tracked frame.

A frame of facial tracking is ~160 markers seen by 4 head-mounted cameras; the
tracker triangulates and reprojects all of them every frame.
"""
from __future__ import annotations

import time

import numpy as np

from carapost.core.camera import Camera, triangulate_many

POINTS = 160
CAMERAS = 4


def _rig() -> list[Camera]:
    cams = []
    for i, c in enumerate([(-70, -60, -120), (70, -60, -120), (-60, 50, -115), (60, 50, -115)]):
        c = np.array(c, float)
        z = -c / np.linalg.norm(c)
        x = np.cross(z, [0.0, -1.0, 0.0])
        x /= np.linalg.norm(x)
        R = np.stack([x, np.cross(z, x), z])
        model, dist = (("VICON_RADIAL", [2.4e-7, -6e-14]) if i % 2 == 0
                       else ("VICON_RADIAL2", [641.7, 358.2, 3.1e-7, -1.5e-13, 4e-20]))
        cams.append(Camera(name=f"HMC{i}", focal_length=950.0 + 15 * i, principal_point=np.array([640.0, 360.0]),
                           distortion_model=model, distortion=np.array(dist), rotation=R, position=c))
    return cams


def _ms(fn, repeat: int = 7, number: int = 20) -> float:
    """Median over ``repeat`` runs of the mean time of ``number`` calls, in ms."""
    fn()  # warm-up
    runs = []
    for _ in range(repeat):
        t = time.perf_counter()
        for _ in range(number):
            fn()
        runs.append((time.perf_counter() - t) / number * 1e3)
    return float(np.median(runs))


def run(quick: bool = False) -> list[dict]:
    """Time ``triangulate_many`` and raw-pixel projection for 160 points x 4 cameras.

    One dict per measurement in the ``carapost bench`` format (``benchmark``,
    ``value``, ``unit``, ``target``, ``pass``), each also carrying ``name`` and
    the ``triangulate_many_ms`` / ``project_ms`` figures.
    """
    rng = np.random.default_rng(0)
    cams = _rig()
    X = rng.uniform(-35, 35, (POINTS, 3)) * np.array([1.0, 1.2, 0.5])
    uv = np.stack([c.project(X) for c in cams], axis=1) + rng.normal(0, 0.2, (POINTS, CAMERAS, 2))
    uv[rng.random((POINTS, CAMERAS)) < 0.1] = np.nan  # some occlusions, as in real frames
    repeat, number = (3, 5) if quick else (7, 20)
    tri_ms = _ms(lambda: triangulate_many(cams, uv), repeat, number)
    proj_ms = _ms(lambda: [c.project(X) for c in cams], repeat, number)
    common = {"points": POINTS, "cameras": CAMERAS, "triangulate_many_ms": round(tri_ms, 3),
              "project_ms": round(proj_ms, 3)}
    return [
        {"benchmark": "triangulate_many_160x4", "name": "camera.triangulate_many", "value": round(tri_ms, 3),
         "unit": "ms", "target": "< 2", "pass": tri_ms < 2.0, **common},
        {"benchmark": "project_160x4", "name": "camera.project", "value": round(proj_ms, 3),
         "unit": "ms", "target": "< 2", "pass": proj_ms < 2.0, **common},
    ]


if __name__ == "__main__":
    print(run())
