"""Track Forwards/Backwards [Sequence]/[Single Frame]: the project-level operations.

:func:`track` reads the project, runs :class:`.engine.FrameTracker` frame by
frame and returns ONE command holding every frame tracked (the points' data
and the cameras), so that a whole run undoes in one step.  Nothing in the
project changes until the caller pushes that command.  On cancel the frames
done so far make the command (``command.cancelled`` is True).
"""
from __future__ import annotations

from dataclasses import replace

import numpy as np

from scipy.spatial.transform import Rotation

from ..commands import Command, CompoundCommand
from ..edits import AddPoints, SetCameraPoses, SetFrameDetections, SetPointData
from ..errors import CaraError
from ..points import BRIM, FACE, SRC_DETECTION, SRC_NONE, ST_NONE, ST_RECONSTRUCTED, ST_SINGLE
from ..progress import Cancelled, Progress, frame_payload
from .engine import FrameTracker
from .geometry import RigState
from .missing_views import appended
from .params import TrackingParams
from .patch import PatchPool

#: Threads for patch matching (the target machine has 2 cores).
DEFAULT_WORKERS = 2
#: Frames decoded ahead of the tracker, of the cameras it is reading, in the frame cache's worker threads.
PREFETCH_FRAMES = 4


def _image_source(images):
    if images is None:
        return None
    if callable(images):
        return images
    if hasattr(images, "image"):
        return images.image
    raise CaraError("images must be a TakeFrames or a callable (sensor, frame) -> image")


def _detections(project, frames, images, progress):
    """Frame detections, running blob detection (as part of the command) on frames that have none."""
    S = project.sensor_count
    missing = sorted({f for f in frames for s in range(S)
                      if not project.detections[s].detected[f] and project.detections[s].count(f) == 0})
    cells, cmd = {}, None
    if missing:
        try:
            from ..blob_ops import detect_blobs_range
        except ImportError:  # pragma: no cover - blob detection not installed
            detect_blobs_range = None
        if detect_blobs_range is None or images is None:
            raise CaraError(f"frames {missing[0]}-{missing[-1]} have no blob detections: run Process > Detect "
                            "Blobs first (tracking runs it itself only when the take's images are available)")
        cmd = detect_blobs_range(project, missing[0], missing[-1], progress=progress)
        cells = dict(cmd.cells)
        if progress is not None:
            progress.start(len(frames), "Tracking")

    def recs(f):
        return [cells[(s, f)] if (s, f) in cells else project.detections[s].frame(f) for s in range(S)]
    return recs, cmd


def track(project, start_frame: int, direction: int = +1, end_frame: int | None = None, point_ids=None,
          single_frame: bool = False, images=None, progress: Progress | None = None,
          params: TrackingParams | None = None, workers: int = DEFAULT_WORKERS) -> Command:
    """Track points from ``start_frame`` towards ``end_frame``.

    Parameters
    ----------
    project : Project
        With cameras (an imported XCP) and points with 3D positions on ``start_frame``
        (Initialize 3D); the calibration brim, when set, drives the per-frame camera solve.
    start_frame : int
        The frame whose points are tracked (it is not changed).
    direction : {+1, -1}
        Forwards or backwards.
    end_frame : int, optional
        Last frame to track (inclusive); default the end (start) of the active range.
    point_ids : iterable of int, optional
        Points to track; default all.  Points without a 3D position on
        ``start_frame`` cannot be tracked and are left as they are.
    single_frame : bool
        Track one frame only (Ctrl+W).
    images : TakeFrames or callable, optional
        Images for patch matching and patch tracking (``images(sensor, frame)``);
        without them only blob matching runs.
    progress : Progress, optional
        One step per frame; on cancel the frames done so far are returned.
        When it is :attr:`~carapost.core.progress.Progress.publishing`, each
        frame's results (face points, then brim points, and the frame's
        cameras) are published as they are found.
    params : TrackingParams, optional
        Default: the project's Tracking Parameters.
    workers : int
        Threads for patch matching.

    Returns
    -------
    Command
        Not yet applied.  Attributes: ``report`` (dict: frames, tracked points,
        per-frame counts), ``cancelled`` (bool), ``summary`` (a log line).

    Raises
    ------
    CaraError
        Without cameras, without points to track, or with frames lacking detections
        that cannot be detected here.
    """
    if project.rig is None:
        raise CaraError("no camera calibration is loaded: the cameras have no intrinsics (File > Import XCP)")
    if direction not in (1, -1):
        raise CaraError("direction must be +1 (forwards) or -1 (backwards)")
    start = project.clamp_frame(start_frame)
    if single_frame:
        end = start + direction
    elif end_frame is None:
        end = project.active_range[1] if direction > 0 else project.active_range[0]
    else:
        end = int(end_frame)
    end = project.clamp_frame(end)
    frames = list(range(start + direction, end + direction, direction)) if (end - start) * direction > 0 else []
    params = params or TrackingParams.from_project(project)
    S = project.sensor_count
    wanted = set(project.points) if point_ids is None else set(point_ids)
    face = [q for q in project.points.values() if q.id in wanted and q.kind == FACE
            and q.status[start] != ST_NONE and np.all(np.isfinite(q.pos[start]))]
    brim = project.brim.markers if project.brim is not None and len(project.brim) else np.zeros((0, 3))
    brim_pts = {q.brim_index: q for q in project.points.values()
                if q.kind == BRIM and q.id in wanted and 0 <= q.brim_index < len(brim)}
    if not face and not brim_pts:
        raise CaraError(f"no points to track on frame {start}: initialise them first (Process > Initialize 3D)")
    left_out = len(list(project.face_points())) - len(face)
    unmade = bool(params.add_points_for_new_markers and left_out and not single_frame)
    if params.add_points_for_new_markers and (single_frame or left_out):
        # A face point left out (not selected, or without a position on the start frame) is not where the
        # tracker could see it: its marker would be given a second point.
        params = replace(params, add_points_for_new_markers=False)
    name = ("Track Forwards" if direction > 0 else "Track Backwards") + \
        (" [Single Frame]" if single_frame else " [Sequence]")
    if progress is not None:
        progress.start(len(frames), name)
    recs_of, detect_cmd = _detections(project, frames, images, progress)
    # Start state from the project.
    X0 = np.array([q.pos[start] for q in face], float).reshape(-1, 3)
    uv0 = np.full((len(face), S, 2), np.nan)
    size0 = np.full((len(face), S, 2), np.nan)
    recs0 = recs_of(start)
    for i, q in enumerate(face):
        for s in range(S):
            if q.src[start, s] != SRC_NONE:
                uv0[i, s] = q.uv[start, s]
            d = q.det[start, s]
            if q.src[start, s] == SRC_DETECTION and 0 <= d < len(recs0[s]):
                size0[i, s] = (recs0[s][d]["major"], recs0[s][d]["minor"])
    pool = PatchPool(workers)
    source = _image_source(images)
    # A take's images are H.264 (.pico): decoding a camera's frame costs more than tracking it, and the
    # decoder lets other threads run, so the next frames of the cameras the last two frames both needed
    # (patches, appearance checks) are decoded while this one is tracked.  Only those: a camera whose
    # images are not needed for a GOP is not decoded at all (a 35-marker take read 99 of 320 camera-frames).
    ahead = getattr(images, "prefetch", None)
    read: set[int] = set()                # the sensors whose images the last frame's tracking read
    if ahead is not None:
        def image(s, f, source=source):
            read.add(int(s))
            return source(s, f)
        source = image
    tracker = FrameTracker(RigState(project.rig.cameras_at(start)), X0, uv0, size0, brim, params,
                           images=source, pool=pool, start_frame=start,
                           brim_radius=project.brim.radius if len(brim) else None,
                           learned_centres=bool(project.properties["blob.learned_centres"]))
    results, cancelled = [], False
    face_ids = np.array([q.id for q in face], np.int64)
    brim_ids = np.array([q.id for q in brim_pts.values()], np.int64)
    brim_idx = np.array(list(brim_pts), np.int64)
    before: set[int] = set()
    try:
        for f in frames:
            if progress is not None:
                progress.check()
            steady = sorted(read & before)          # always empty where the images cannot prefetch
            if steady:
                ahead(f, PREFETCH_FRAMES, direction, sensors=steady)
            before = read.copy()
            read.clear()
            results.append(tracker.step(f, recs_of(f)))
            # A return on the frame before that this frame did not confirm is taken back (engine step 9).
            taken_back = results[-1].retract is not None and len(results) > 1
            if taken_back:
                results[-2].take_back(results[-1].retract)
            if progress is not None:
                if progress.publishing:
                    if taken_back:
                        _publish(progress, results[-2], face_ids, brim_ids, brim_idx, brim)
                    _publish(progress, results[-1], face_ids, brim_ids, brim_idx, brim)
                progress.step(1)
    except Cancelled:
        cancelled = True
    fill: dict = {}
    try:
        if not cancelled:
            fill = _back_fill(project, results, start, direction, recs_of, params, source, pool, brim, len(face),
                              progress)
    except Cancelled:
        cancelled = True
    finally:
        pool.close()
    cmd = _command(project, name, face, brim_pts, brim, results, detect_cmd, recs_of, fill)
    cmd.cancelled = cancelled
    if unmade:
        cmd.summary += (f"; no points made for new markers: {left_out} face point(s) not tracked (not selected, "
                        f"or without a position on frame {start})")
    return cmd


#: A point made while tracking (engine step 10) is then tracked back from the frame it was made on towards
#: the start frame, over the frames where its marker was in view but not yet sure enough to make a point,
#: until it has been lost this many frames in a row.
BACK_FILL_LOST = 10


def _back_fill(project, results, start, direction, recs_of, params, source, pool, brim, n_face,
               progress) -> dict:
    """The frames before the new points were made, tracked back from the last frame one was made on.

    Every point takes part (the new points' neighbours predict them), but only the new points' rows of
    the frames before each was made are used (:func:`_command`).  Returns frame -> FrameResult; a cancel
    meanwhile raises :class:`Cancelled` and leaves the run without them.
    """
    fill: dict = {}
    made = [i for i, r in enumerate(results) if r.new]
    if not made:
        return fill
    r0 = results[made[-1]]
    S = project.sensor_count
    rig = RigState(project.rig.cameras_at(start))
    rig.R, rig.C = r0.R.copy(), r0.C.copy()
    recs0 = appended(recs_of(r0.frame), r0.found)
    size0 = np.full(r0.uv.shape, np.nan)
    for s in range(S):
        use = (r0.src[:, s] == SRC_DETECTION) & (r0.det[:, s] >= 0)
        size0[use, s, 0] = recs0[s]["major"][r0.det[use, s]]
        size0[use, s, 1] = recs0[s]["minor"][r0.det[use, s]]
    # Without Search Missing Views: its dots would be a second set of records for frames the run already tracked.
    tracker = FrameTracker(rig, r0.X, r0.uv, size0, brim,
                           replace(params, add_points_for_new_markers=False, search_missing_views=False),
                           images=source, pool=pool, start_frame=r0.frame,
                           brim_radius=project.brim.radius if len(brim) else None)
    new_rows = np.arange(n_face, len(r0.status))
    lost = np.zeros(len(new_rows), int)
    prev = None
    for f in range(r0.frame - direction, start, -direction):
        if progress is not None:
            progress.check()
        res = tracker.step(f, recs_of(f))
        if res.retract is not None and prev is not None:
            prev.take_back(res.retract)
        fill[f] = prev = res
        lost = np.where(res.status[new_rows] != ST_NONE, 0, lost + 1)
        if np.all(lost >= BACK_FILL_LOST):
            break
    return fill


def _brim_rows(res, idx: np.ndarray, brim) -> dict[str, np.ndarray]:
    """Point arrays ``(frames, markers, ...)`` of brim markers ``idx`` over the frames of ``res``.

    Their 3D stays on the brim; their 2D samples are the detections the frame's camera solve used.
    """
    det = np.array([r.brim_det[idx] for r in res], np.int32)
    seen = det >= 0
    nobs = np.count_nonzero(seen, axis=-1)
    e = np.array([r.brim_err[idx] for r in res])
    with np.errstate(invalid="ignore"):
        resid = np.sqrt(np.nansum(e ** 2, axis=-1) / np.maximum(nobs, 1))
    return {
        "pos": np.where((nobs > 0)[..., None], brim[idx][None].astype(np.float32), np.nan).astype(np.float32),
        "status": np.where(nobs >= 2, ST_RECONSTRUCTED, np.where(nobs == 1, ST_SINGLE, ST_NONE)).astype(np.uint8),
        "residual": np.where(nobs > 0, resid, np.nan).astype(np.float16),
        "src": np.where(seen, SRC_DETECTION, SRC_NONE).astype(np.uint8),
        "det": det,
        "uv": np.array([r.brim_uv[idx] for r in res], np.float32),
        "score": np.array([r.brim_score[idx] for r in res], np.float16),
    }


def _publish(progress: Progress, r, face_ids: np.ndarray, brim_ids: np.ndarray, brim_idx: np.ndarray,
             brim) -> None:
    """Hand frame ``r``'s results (face points, then brim points) to the progress listener."""
    if len(brim_idx):
        b = {k: v[0] for k, v in _brim_rows([r], brim_idx, brim).items()}
        ids = np.concatenate([face_ids, brim_ids])

        def cat(face, key):
            return np.concatenate([face, b[key]])
    else:
        ids = face_ids

        def cat(face, _key):
            return face
    n = len(face_ids)      # new points (rows past the face points) are not in the project until the end
    progress.publish(r.frame, frame_payload(
        ids, cat(r.status[:n], "status"), cat(r.src[:n], "src"), cat(r.uv[:n], "uv"), cat(r.score[:n], "score"),
        pos=cat(r.X[:n], "pos"), residual=cat(r.residual[:n], "residual"), det=cat(r.det[:n], "det"),
        cameras=(r.R, r.C)))


def _command(project, name, face, brim_pts, brim, results, detect_cmd, recs_of, fill=None) -> Command:
    S = project.sensor_count
    cmds: list[Command] = []
    if detect_cmd is not None:
        cmds.append(detect_cmd)
    # The dots Search Missing Views found, after each frame's own records (the samples' ``det`` count them so).
    found = {(s, r.frame): rec for r in results if r.found is not None
             for s, rec in enumerate(appended(recs_of(r.frame), r.found)) if len(r.found[s])}
    if found:
        cmds.append(SetFrameDetections(found, name="Search Missing Views"))
    n = len(results)
    per_frame = []
    if n:
        order = sorted(range(n), key=lambda k: results[k].frame)
        res = [results[k] for k in order]
        lo = res[0].frame
        # Each field stacked once over the frames (frames, points, ...) and cut per point: 160 points x 7
        # fields of per-frame Python lists cost ~1 ms a frame.  The casts are the same element by element.
        fields = {"pos": ("X", np.float32), "status": ("status", np.uint8), "residual": ("residual", np.float16),
                  "src": ("src", np.uint8), "det": ("det", np.int32), "uv": ("uv", np.float32),
                  "score": ("score", np.float16)}
        rows = max(len(r.status) for r in res)
        fill = fill or {}
        stacked = {k: np.array([_padded(getattr(r, a), rows, k, getattr(fill.get(r.frame), a, None)) for r in res],
                               dt) for k, (a, dt) in fields.items()}
        # Points for markers no point followed (engine step 10): the rows after the face points.
        nid = project.next_point_id
        new = [project.new_point(FACE, point_id=nid + j) for j in range(rows - len(face))]
        if new:
            cmds.append(AddPoints(new, name="Add Points For New Markers"))
        updates = [(q.id, lo, {k: np.ascontiguousarray(v[:, i]) for k, v in stacked.items()})
                   for i, q in enumerate(face + new)]
        if brim_pts:
            rows = _brim_rows(res, np.array(list(brim_pts), np.int64), brim)
            for j, q in enumerate(brim_pts.values()):
                updates.append((q.id, lo, {k: np.ascontiguousarray(v[:, j]) for k, v in rows.items()}))
        cmds.append(SetPointData(updates, name="Tracked Points"))
        # One batched conversion (per-matrix calls cost ~0.5 ms a frame); w >= 0 as Camera.quaternion.
        Rs = np.array([[r.R[s] for r in res] for s in range(S)]).reshape(-1, 3, 3)
        quat = Rotation.from_matrix(Rs).as_quat()
        quat[quat[:, 3] < 0] *= -1
        quat = quat.reshape(S, n, 4)
        pos = np.array([[r.C[s] for r in res] for s in range(S)])
        cmds.append(SetCameraPoses(lo, quat, pos, np.ones((S, n), bool), name="Tracked Cameras"))
        per_frame = [int(np.count_nonzero(r.status != ST_NONE)) for r in res]
    cmd = CompoundCommand(name, cmds)
    frames = [r.frame for r in results]
    added = sum(r.new for r in results)
    dots = sum(len(a) for r in results if r.found is not None for a in r.found)
    cmd.report = {"frames": n, "first": frames[0] if frames else None, "last": frames[-1] if frames else None,
                  "points": len(face), "new_points": added, "tracked_per_frame": per_frame, "found_dots": dots}
    mean = float(np.mean(per_frame)) / max(1, len(face) + added) if per_frame else 0.0
    cmd.summary = (f"{name}: {n} frames, {len(face)} face points, {100 * mean:.1f}% of point-frames tracked"
                   + (f" (frames {frames[0]}-{frames[-1]})" if frames else "")
                   + (f"; {added} new points for markers no point followed" if added else "")
                   + (f"; {dots} dots found by Search Missing Views" if dots else ""))
    return cmd


_EMPTY = {"X": np.nan, "status": ST_NONE, "residual": np.nan, "src": SRC_NONE, "det": -1, "uv": np.nan,
          "score": np.nan}


def _padded(a: np.ndarray, rows: int, key: str, back: np.ndarray | None = None) -> np.ndarray:
    """``a`` with rows appended up to ``rows`` (frames before a new point was made): from ``back``, the frame
    tracked back (:func:`_back_fill`), where it has them, else empty."""
    if len(a) == rows:
        return a
    pad = np.full((rows - len(a),) + a.shape[1:], _EMPTY["X" if key == "pos" else key], a.dtype)
    if back is not None:
        have = back[len(a):rows]
        pad[:len(have)] = have
    return np.concatenate([a, pad])


def track_forwards_sequence(project, frame: int, **kw) -> Command:
    """Process > Track Forwards [Sequence]: from ``frame`` to the end of the active range."""
    return track(project, frame, +1, **kw)


def track_backwards_sequence(project, frame: int, **kw) -> Command:
    """Process > Track Backwards [Sequence]: from ``frame`` to the start of the active range."""
    return track(project, frame, -1, **kw)


def track_single_frame(project, frame: int, direction: int = +1, **kw) -> Command:
    """Track [Single Frame] (Ctrl+W): the points of ``frame`` into the next (+1) or previous (-1) frame."""
    return track(project, frame, direction, single_frame=True, **kw)


def warm_up() -> float:
    """Load (or compile into numba's disk cache) the tracker's compiled kernels; returns the seconds it took.

    The first tracking in a process loads them, ~0.6 s on a 2-core machine (the first after installing
    carapost, or after a kernel changed, compiles them: ~11 s).  This tracks a small synthetic take
    (35 points, 15 frames, with the jaw jerking open, so that the vote and the weighted median run) and
    every kernel meets the array types and layouts real tracking gives it (~1.1 s in all); call it where
    that first wait must not fall on a timed step (the tracking benchmark does).
    """
    import time

    from .synthetic_take import initialise, make_take

    t = time.perf_counter()
    scene = make_take(35, 16, seed=0, blinks=1, slips=0)
    initialise(scene, 0)
    track(scene.project, 0, +1)
    return time.perf_counter() - t
