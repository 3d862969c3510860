"""A few frames of the sample take rendered in memory, as a project with its true cameras.

Tests and benchmarks of image-based tools (the Target Tracker) need the images
and the truth of a handful of frames, not a whole encoded take: rendering 16
frames of two channels takes about a second, no ``.pico`` is written.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Clip:
    """Frames ``0 .. frames - 1`` of channels ``channels`` of a sample scene.

    Attributes
    ----------
    images : dict
        ``(channel, frame) -> (H, W) uint8``.
    uv : ndarray (F, 4, N, 2)
        True raw positions of the face markers (every channel; NaN for channels not rendered).
    visible, drawn : ndarray (F, 4, N) bool
        The renderer's flags (``docs/sample.md``).
    xyz : ndarray (F, N, 3)
        True 3D marker centres (mm, world frame).
    labels : list of str
    cameras : list of list of Camera
        The true cameras of every frame.
    """

    images: dict
    uv: np.ndarray
    visible: np.ndarray
    drawn: np.ndarray
    xyz: np.ndarray
    labels: list
    cameras: list
    width: int
    height: int

    def image(self, channel: int, frame: int) -> np.ndarray:
        """``images(sensor, frame)`` as the Target Tracker reads them."""
        return self.images[(channel, frame)]

    def marker(self, label: str) -> int:
        return self.labels.index(label)

    def project(self, sensors: int = 4):
        """An empty project of the clip: its frames, sensor sizes and the true cameras of every frame."""
        from ..core.project import Project
        from ..core.rig import CameraRig

        F = len(self.cameras)
        p = Project(F, sensors, 60.0, name="clip")
        for s in p.sensors:
            s.width, s.height = self.width, self.height
        rig = CameraRig(self.cameras[0][:sensors], F)
        for f in range(F):
            for s in range(sensors):
                rig.set_pose(s, f, self.cameras[f][s])
        p.rig = rig
        return p


def render_clip(markers: int = 40, frames: int = 16, seed: int = 1, channels=(0, 1)) -> Clip:
    """Render the first ``frames`` frames of ``channels`` of the sample scene (see ``build_scene``).

    Every take opens with a lip curl and both eyes closed on frames 6-8, so 16
    frames hold a whole blink.
    """
    from .render import leds_of, render_view
    from .scene import build_scene, frame_geometry, true_cameras

    scene = build_scene(markers=markers, frames=frames, seed=seed)
    N = len(scene.markers)
    uv = np.full((frames, 4, N, 2), np.nan)
    visible = np.zeros((frames, 4, N), bool)
    drawn = np.zeros((frames, 4, N), bool)
    xyz = np.zeros((frames, N, 3))
    images, cams_all = {}, []
    for f in range(frames):
        g = frame_geometry(scene, f)
        cams = true_cameras(scene, f)
        cams_all.append(cams)
        xyz[f] = g.points[:N]
        for c in channels:
            img, tr = render_view(scene, g, cams[c], c, f, leds=leds_of(cams))
            images[(c, f)] = img
            uv[f, c], visible[f, c], drawn[f, c] = tr.uv[:N], tr.visible[:N], tr.drawn[:N]
    return Clip(images, uv, visible, drawn, xyz, list(scene.markers.labels), cams_all, scene.width, scene.height)
