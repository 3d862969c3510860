"""Test helpers for Initialize from ROM: a ROM take and a second take of the same face, with truth.

The ROM is a synthetic take (:func:`carapost.core.tracking.synthetic_take.make_take`)
whose project is built from its ground truth: true cameras on every frame,
labelled face points and brim points attached to their true detections on the
ROM frame, and sticks.  The second take has the same face and brim with every
camera moved (``rig_move``), its own head motion and noise, and no cameras,
brim or points: Initialize from ROM must bring them all.
"""
from __future__ import annotations

import numpy as np

from carapost.core.points import BRIM, FACE, SRC_DETECTION, ST_RECONSTRUCTED
from carapost.core.project import Stick
from carapost.core.rig import CameraRig
from carapost.core.tracking.synthetic_take import make_take

MARKERS = 35
SEED = 3


def take(rig_move=(0.0, 0.0), frames: int = 4, motion_seed: int | None = None, markers: int = MARKERS):
    """A short synthetic take of the test face (no blinks, occlusions or hidden markers)."""
    return make_take(markers, frames, seed=SEED, blinks=0, occlusion_rate=0.0, hidden_markers=0, slips=0,
                     motion_seed=motion_seed, rig_move=rig_move)


def label(m: int) -> str:
    return f"M{m:02d}"


def rom_project(scene, frame: int = 0):
    """The ROM's project from its truth (see the module docstring)."""
    pr = scene.project
    F, S = pr.frame_count, pr.sensor_count
    rig = CameraRig([c.copy() for c in scene.cameras[0]], F)
    for f in range(F):
        for s in range(S):
            rig.set_pose(s, f, scene.cameras[f][s])
    pr.rig = rig
    for m in range(scene.face.shape[1]):
        p = pr.new_point(FACE, label=label(m))
        _attach(pr, p, frame, scene.face_det[frame, :, m], scene.face[frame, m])
        pr.add_point(p)
        pr.labels.append(p.label)
    for b in range(len(scene.brim)):
        if np.count_nonzero(scene.brim_det[frame, :, b] >= 0) == 0:
            continue
        p = pr.new_point(BRIM, brim_index=b)
        _attach(pr, p, frame, scene.brim_det[frame, :, b], scene.brim.markers[b])
        pr.add_point(p)
    ids = [p.id for p in pr.points.values() if p.kind == FACE]
    pr.sticks = [Stick(a, b) for a, b in zip(ids[:-1], ids[1:])][:10]
    return pr


def _attach(pr, p, frame, dets, X):
    for s, d in enumerate(dets):
        if d >= 0:
            rec = pr.detections[s].frame(frame)[d]
            p.src[frame, s] = SRC_DETECTION
            p.det[frame, s] = d
            p.uv[frame, s] = (rec["x"], rec["y"])
            p.score[frame, s] = 1.0
    p.pos[frame] = X
    p.status[frame] = ST_RECONSTRUCTED
    p.residual[frame] = 0.0


def bare(scene):
    """The second take as a fresh import: detections only (no cameras, brim or points)."""
    scene.project.rig = None
    scene.project.brim = None
    return scene.project


def score(project, scene, frame: int, tol_mm: float = 1.5) -> dict:
    """How many true markers got a point with their label within ``tol_mm`` (and how many are wrong)."""
    truth = scene.face[frame]
    good = wrong = 0
    for p in project.face_points():
        if p.status[frame] == 0:
            continue
        if not p.label.startswith("M"):
            wrong += 1
            continue
        d = np.linalg.norm(p.pos[frame] - truth[int(p.label[1:])])
        good += d <= tol_mm
        wrong += d > tol_mm
    return {"correct": int(good), "wrong": int(wrong), "fraction": good / truth.shape[0]}


def visible_detection(scene, frame: int, sensor: int, marker: int, brim: bool = False) -> int:
    """The detection index of a true marker (face or brim) in one channel."""
    table = scene.brim_det if brim else scene.face_det
    return int(table[frame, sensor, marker])
