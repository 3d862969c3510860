"""Initialize from ROM on rendered sample takes, scored against their truth.

The ROM workflow as a user runs it on two ``carapost sample`` takes of the same
face (the second written with ``motion_seed`` and ``rig_move`` or
``camera_move``, see :mod:`carapost.sample.remount`):

1. :func:`make_rom`: the ROM take processed like ``carapost process`` up to
   Initialize 3D (seeds.json, brim.svg, calibration.xcp), then labelled as a
   user labels a ROM: each face point takes the label of the marker whose
   detections it holds (the sample's truth stands in for the user's eye);
   points on no marker are deleted.  Saved as a ``.cara``.
2. :func:`second_take`: the other take as a fresh import, blobs detected on one frame.
3. Load ROM and Initialize from ROM (``carapost.api.CaraProcess``), optionally
   after Solve ROM Camera From Correspondences (:func:`click_brim_correspondences`
   makes the clicks a user makes: brim markers of one channel and their detections).
4. :func:`score`: markers initialised with their right label against the markers
   that can be: seen by two or more cameras, the faint ones left out
   (:data:`carapost.core.blobs.synth.FAINT`: paint on a dense black brow that
   barely changes the image; no detector finds those).

Used by ``tests/test_rom_rendered.py`` and ``benchmarks/bench_rom.py``.
"""
from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from carapost.core.points import BRIM, FACE, SRC_DETECTION, ST_NONE

__all__ = ["TakeTruth", "load_truth", "make_rom", "second_take", "score", "click_brim_correspondences",
           "SCORE_TOL_MM", "OWNER_TOL_PX"]

#: A point is on its marker when it is this close to the marker's true centre (mm).
SCORE_TOL_MM = 1.5
#: A detection belongs to a marker when its centre is this close to the marker's true image (px).
OWNER_TOL_PX = 1.5


@dataclass
class TakeTruth:
    """What a sample folder's truth says about one frame.

    Attributes
    ----------
    labels : list of str
        Face marker labels (marker order).
    xyz : ndarray (M, 3)
        True face marker centres (world = brim frame, mm).
    uv : ndarray (S, P, 2)
        True image centres of every marker, face then brim (raw pixels).
    visible : ndarray (S, P) bool
    scorable : ndarray (M,) bool
        Face markers seen, and not faint, in two or more cameras.
    faint : ndarray (M,) int
        Cameras in which each face marker is visible but faint.
    cameras : list of Camera
        The true cameras of the frame.
    """

    labels: list
    xyz: np.ndarray
    uv: np.ndarray
    visible: np.ndarray
    scorable: np.ndarray
    faint: np.ndarray
    cameras: list


def load_truth(folder, frame: int, scene_kw: dict | None = None) -> TakeTruth:
    """The truth of ``frame`` of the sample take in ``folder``.

    ``scene_kw`` are the :func:`~carapost.sample.scene.build_scene` arguments
    the take was written with (``markers``, ``frames``, ``seed``, ``motion_seed``,
    ...): the frame is rendered again with and without paint to find the faint dots.
    """
    from carapost.core.blobs.synth import FAINT, paint_contrast

    from .render import leds_of, render_view
    from .scene import build_scene, frame_geometry, true_cameras

    t = np.load(Path(folder) / "truth.npz")
    labels = [str(s) for s in t["labels"]]
    M = len(labels)
    vis = np.asarray(t["visible"][frame], bool)            # (S, P)
    sc = build_scene(**(scene_kw or {}))
    g = frame_geometry(sc, frame)
    cams = true_cameras(sc, frame)
    good = vis.copy()
    for c in range(len(cams)):
        img, tr = render_view(sc, g, cams[c], c, frame, leds=leds_of(cams))
        bare, _ = render_view(sc, g, cams[c], c, frame, leds=leds_of(cams), markers=False)
        idx = np.flatnonzero(tr.visible)
        paint = paint_contrast(img, bare, tr.uv[idx], tr.axes[idx], sc.white)
        faint = (paint < FAINT * np.median(paint)) & (tr.axes[idx, 1] >= 1.5)
        good[c, idx[faint]] = False
    faint_count = np.count_nonzero(vis[:, :M] & ~good[:, :M], axis=0)
    return TakeTruth(labels, np.asarray(t["face_xyz"][frame], float), np.asarray(t["uv"][frame], float), vis,
                     np.count_nonzero(good[:, :M], axis=0) >= 2, faint_count, cams)


def _owners(project, frame: int, truth: TakeTruth) -> list[np.ndarray]:
    """Per sensor, the true marker (face then brim index) of each detection, -1 none."""
    out = []
    for s in range(project.sensor_count):
        rec = project.detections[s].frame(frame)
        own = np.full(len(rec), -1)
        if len(rec):
            xy = np.column_stack([rec["x"], rec["y"]]).astype(float)
            d = np.linalg.norm(xy[:, None] - truth.uv[s][None], axis=2)
            d = np.where(truth.visible[s][None], d, np.inf)
            near = d.min(axis=1) <= OWNER_TOL_PX
            own[near] = d.argmin(axis=1)[near]
        out.append(own)
    return out


def _open_take(folder, take: str, frame: int, xcp: bool):
    from carapost.core.blob_ops import detect_blobs_range
    from carapost.io.imports import import_xcp
    from carapost.io.take import project_from_input

    pr = project_from_input(str(Path(folder) / f"{take}_0.pico"), None)
    if xcp:
        import_xcp(pr, Path(folder) / "calibration.xcp", lambda s: None).do(pr)
    detect_blobs_range(pr, frame, frame, workers=1).do(pr)
    return pr


def make_rom(folder, scene_kw: dict, take: str = "Sample", log=lambda s: None):
    """The ROM project of the sample take in ``folder`` (see the module docstring), and a report.

    Returns
    -------
    project : Project
    report : dict
        ``frame``, ``points`` (labelled face points), ``markers`` (scorable markers of the frame),
        ``deleted`` (points on no marker or sharing one).
    """
    from carapost.core.edits import DeletePoints, SetLabels
    from carapost.core.pipeline import process_to_init3d
    from carapost.io.brim_svg import read_brim_svg

    folder = Path(folder)
    seeds = json.loads((folder / "seeds.json").read_text())
    frame = int(seeds.get("frame", 0))
    pr = _open_take(folder, take, frame, xcp=True)
    process_to_init3d(pr, seeds, read_brim_svg(folder / "brim.svg"), log=log)
    truth = load_truth(folder, frame, scene_kw)
    owner = _owners(pr, frame, truth)
    M = len(truth.labels)
    marker_of, junk = {}, []
    for p in list(pr.points.values()):
        if p.kind != FACE or p.status[frame] == ST_NONE:
            continue
        held = {int(owner[s][p.det[frame, s]]) for s in range(pr.sensor_count)
                if p.src[frame, s] == SRC_DETECTION and 0 <= p.det[frame, s] < len(owner[s])}
        m = next(iter(held)) if len(held) == 1 else -1
        if 0 <= m < M and m not in marker_of.values() \
                and np.linalg.norm(p.pos[frame] - truth.xyz[m]) <= SCORE_TOL_MM:
            marker_of[p.id] = m
        else:
            junk.append(p.id)
    if junk:
        DeletePoints(junk).do(pr)
    SetLabels(list(truth.labels)).do(pr)
    for pid, m in marker_of.items():
        pr.points[pid].label = truth.labels[m]
    initialised = len(marker_of)
    added = _add_missed(pr, frame, truth, owner, set(marker_of.values()))
    return pr, {"frame": frame, "points": initialised + added, "initialised": initialised, "added": added,
                "markers": int(truth.scorable.sum()), "deleted": len(junk)}


def _add_missed(pr, frame: int, truth: TakeTruth, owner: list, have: set) -> int:
    """Points for the markers Initialize 3D left, where the detector found them in two or more channels.

    What a user completing a ROM does (Create Points From Detections, merge,
    reconstruct): each such marker gets a labelled point on its free
    detections, triangulated with the frame's cameras.  Returns how many.
    """
    from carapost.core.edits import AddPoints
    from carapost.core.points import ST_RECONSTRUCTED
    from carapost.core.tracking.geometry import RigState, triangulate

    S, M = pr.sensor_count, len(truth.labels)
    held = [set() for _ in range(S)]
    for p in pr.points.values():
        for s in range(S):
            if p.src[frame, s] == SRC_DETECTION:
                held[s].add(int(p.det[frame, s]))
    rig = RigState(pr.rig.cameras_at(frame))
    new = []
    for m in range(M):
        if m in have or not truth.scorable[m]:
            continue
        dets = {s: int(np.flatnonzero(owner[s] == m)[0]) for s in range(S)
                if np.count_nonzero(owner[s] == m) == 1 and int(np.flatnonzero(owner[s] == m)[0]) not in held[s]}
        if len(dets) < 2:
            continue
        uv = np.full((1, S, 2), np.nan)
        for s, d in dets.items():
            rec = pr.detections[s].frame(frame)[d]
            uv[0, s] = rig.correct(s, np.array([[rec["x"], rec["y"]]], float))[0]
        X = triangulate(rig, uv, np.all(np.isfinite(uv), axis=-1))[0]
        if not np.all(np.isfinite(X)):
            continue
        p = pr.new_point(FACE, label=truth.labels[m], point_id=pr.next_point_id + len(new))
        for s, d in dets.items():
            rec = pr.detections[s].frame(frame)[d]
            p.src[frame, s], p.det[frame, s], p.uv[frame, s] = SRC_DETECTION, d, (rec["x"], rec["y"])
            p.score[frame, s] = 1.0
        p.pos[frame], p.status[frame], p.residual[frame] = X, ST_RECONSTRUCTED, 0.0
        new.append(p)
    if new:
        AddPoints(new, name="Create Points From Detections").do(pr)
    return len(new)


def second_take(folder, frame: int, take: str = "Sample", xcp: bool = False):
    """The take in ``folder`` as a fresh import with blobs detected on ``frame`` (its XCP imported when ``xcp``)."""
    return _open_take(folder, take, frame, xcp)


def click_brim_correspondences(process, truth: TakeTruth, frame: int, sensor: int, n: int = 4) -> int:
    """Add ``n`` 2D-to-ROM correspondences in ``sensor``: ROM brim points and their true detections.

    The brim markers clicked are spread along the brim (as a user picks them),
    among those the channel sees and the detector found.  Returns how many were added.
    """
    from carapost.core import rom_ops

    pr = process.project
    rom = rom_ops.loaded_rom(pr).rom
    brim_ids = {q.brim_index: q.id for q in rom.points.values() if q.kind == BRIM}
    M = len(truth.labels)
    owner = _owners(pr, frame, truth)[sensor]
    found = {int(m) - M: d for d, m in enumerate(owner) if m >= M}
    usable = [b for b in sorted(brim_ids) if b in found]
    if not usable:
        return 0
    pick = [usable[i] for i in np.unique(np.linspace(0, len(usable) - 1, n).round().astype(int))]
    for b in pick:
        process.add_rom_correspondence(brim_ids[b], sensor, found[b], frame)
    return len(pick)


def score(project, truth: TakeTruth, frame: int) -> dict:
    """Initialize from ROM's result on ``frame`` against the truth.

    Returns
    -------
    dict
        ``markers`` (scorable), ``correct`` (scorable markers with a point of their label within
        :data:`SCORE_TOL_MM`), ``fraction``, ``wrong`` (labelled points farther than that from
        their marker), ``unlabelled`` (face points without a label), ``missed`` (labels of scorable
        markers not initialised), ``camera_error_mm`` (largest camera centre error).
    """
    index = {lab: m for m, lab in enumerate(truth.labels)}
    correct = set()
    wrong = unlabelled = 0
    for p in project.face_points():
        if p.status[frame] == ST_NONE:
            continue
        m = index.get(p.label)
        if m is None:
            unlabelled += 1
        elif np.linalg.norm(p.pos[frame] - truth.xyz[m]) <= SCORE_TOL_MM:
            correct.add(m)
        else:
            wrong += 1
    want = set(np.flatnonzero(truth.scorable).tolist())
    good = len(correct & want)
    cam_err = float("nan")
    if project.rig is not None and bool(np.all(project.rig.solved[:, frame])):
        cam_err = max(float(np.linalg.norm(np.asarray(c.position) - t.position))
                      for c, t in zip(project.rig.cameras_at(frame), truth.cameras))
    return {"markers": len(want), "correct": good, "fraction": good / max(len(want), 1), "wrong": wrong,
            "unlabelled": unlabelled, "missed": sorted(truth.labels[m] for m in want - correct),
            "camera_error_mm": cam_err}


def initialize(rom_path, folder, scene_kw: dict, frame: int = 0, solve_channel: int | None = None,
               clicks: int = 4) -> dict:
    """Load ROM and Initialize from ROM on ``frame`` of the take in ``folder``, scored.

    With ``solve_channel``, first ``clicks`` brim correspondences in that channel
    and Solve ROM Camera From Correspondences (a user's fix for a moved camera).

    Returns
    -------
    dict
        :func:`score`'s figures plus ``report`` (Initialize from ROM's), ``error`` (its CaraError
        text, or ""), ``warnings`` (log lines), ``solve`` (the Solve ROM Camera log line), ``seconds``
        (Initialize from ROM alone), ``process``.
    """
    import logging

    from carapost.api import CaraProcess
    from carapost.core import rom_ops
    from carapost.core.errors import CaraError

    truth = load_truth(folder, frame, scene_kw)
    p = CaraProcess.from_project(second_take(folder, frame))
    p.load_rom(rom_path)
    lines: list[str] = []
    handler = logging.Handler(logging.WARNING)
    handler.emit = lambda rec: lines.append(rec.getMessage())
    logger = logging.getLogger("carapost")
    logger.addHandler(handler)
    out = {"report": {}, "error": "", "solve": "", "process": p}
    try:
        if solve_channel is not None:
            click_brim_correspondences(p, truth, frame, solve_channel, clicks)
            cmd = rom_ops.solve_rom_camera_from_correspondences(p.project, solve_channel)
            p.document.run(cmd)
            out["solve"] = cmd.summary
        t0 = time.perf_counter()
        try:
            out["report"] = p.initialize_from_rom(frame)
        except CaraError as e:
            out["error"] = str(e)
        out["seconds"] = time.perf_counter() - t0
    finally:
        logger.removeHandler(handler)
    out["warnings"] = lines
    out.update(score(p.project, truth, frame))
    return out
