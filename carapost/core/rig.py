"""The camera rig of a take: fixed intrinsics per sensor and extrinsics per frame.

On a head-mounted rig the cameras move with the head, so every frame has its own
poses (solved from the calibration brim).  Poses live in arrays over the take;
a frame that has not been solved uses the nearest solved frame before it (or
after it), and failing that the calibration's pose.
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from .camera import Camera, matrix_to_quaternion, quaternion_to_matrix


class CameraRig:
    """Cameras of every sensor over the take.

    Parameters
    ----------
    cameras : list of Camera
        One per sensor: intrinsics and the calibration pose.
    frames : int
        Frames in the take.
    quat, position, solved : ndarray, optional
        Per-frame extrinsics ``(S, F, 4)`` (x y z w, world to camera), ``(S, F, 3)``
        camera centres in mm, and ``(S, F)`` bool of frames with a pose of their own.
    """

    def __init__(self, cameras: list[Camera], frames: int, quat=None, position=None, solved=None):
        self.cameras = list(cameras)
        self.frames = int(frames)
        s = len(self.cameras)
        if quat is None:
            quat = np.zeros((s, self.frames, 4))
            position = np.zeros((s, self.frames, 3))
            solved = np.zeros((s, self.frames), bool)
            for i, cam in enumerate(self.cameras):
                quat[i, :] = cam.quaternion()
                position[i, :] = cam.position
        self.quat = np.asarray(quat, np.float64)
        self.position = np.asarray(position, np.float64)
        self.solved = np.asarray(solved, bool)

    @property
    def sensors(self) -> int:
        return len(self.cameras)

    def source_frame(self, sensor: int, frame: int) -> int:
        """The frame whose pose ``frame`` uses (itself when solved), or -1 for the calibration pose."""
        row = self.solved[sensor]
        if row[frame]:
            return frame
        before = np.flatnonzero(row[:frame])
        if len(before):
            return int(before[-1])
        after = np.flatnonzero(row[frame:])
        return int(after[0] + frame) if len(after) else -1

    def camera(self, sensor: int, frame: int) -> Camera:
        """The camera of ``sensor`` on ``frame``."""
        src = self.source_frame(sensor, frame)
        base = self.cameras[sensor]
        if src < 0:
            return base
        return base.with_pose(quaternion_to_matrix(self.quat[sensor, src]), self.position[sensor, src].copy())

    def cameras_at(self, frame: int) -> list[Camera]:
        """Every sensor's camera on ``frame``."""
        return [self.camera(s, frame) for s in range(self.sensors)]

    def set_pose(self, sensor: int, frame: int, camera: Camera) -> None:
        """Store ``camera``'s pose as ``frame``'s own (callers go through a command)."""
        self.quat[sensor, frame] = matrix_to_quaternion(camera.rotation)
        self.position[sensor, frame] = camera.position
        self.solved[sensor, frame] = True

    def slice_copy(self, start: int, stop: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Copies of the extrinsics on ``[start, stop)`` for undo."""
        return (self.quat[:, start:stop].copy(), self.position[:, start:stop].copy(),
                self.solved[:, start:stop].copy())

    def restore_slice(self, start: int, saved) -> None:
        q, p, s = saved
        n = q.shape[1]
        self.quat[:, start:start + n] = q
        self.position[:, start:start + n] = p
        self.solved[:, start:start + n] = s

    def copy(self) -> "CameraRig":
        return CameraRig([replace(c) for c in self.cameras], self.frames, self.quat.copy(),
                         self.position.copy(), self.solved.copy())


def rig_from_keyframes(keyframes: list[list[tuple[int, Camera]]], frames: int) -> CameraRig:
    """A rig from per-camera keyframe lists (XCP: a KeyFrame is valid from FRAME until the next).

    Parameters
    ----------
    keyframes : list of list of (frame, Camera)
        One list per sensor, in frame order.
    frames : int
        Frames in the take.
    """
    cams = [kf[0][1] for kf in keyframes]
    rig = CameraRig(cams, frames)
    for s, kfs in enumerate(keyframes):
        if len(kfs) < 2:
            continue  # one pose for the whole take: the calibration pose, nothing solved
        starts = [max(0, min(frames, int(f))) for f, _ in kfs] + [frames]
        for (f, cam), start, stop in zip(kfs, starts, starts[1:]):
            if stop > start:
                rig.quat[s, start:stop] = cam.quaternion()
                rig.position[s, start:stop] = cam.position
                rig.solved[s, start:stop] = True
    return rig
