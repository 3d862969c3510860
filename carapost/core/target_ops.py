"""The Target Tracker's commands: the Tracker pane's buttons and the Edit menu's keyframe items.

Each function reads the project, computes the result and returns ONE undoable
command named after the control; nothing changes until the caller runs it
(``Document.run``).  A cancelled run (:class:`~carapost.core.progress.Cancelled`)
returns nothing, so the project is untouched; ``should_stop`` (the Tracker
pane's Pause) instead ends a run early and keeps the frames done.

Sensors: a point is tracked (or keyed) in every channel where it has a 2D
sample on the current frame (the guide: "all camera views which have a 2D point
in the currently active frame"), restricted to the Selection pane's explicit
channel selection when there is one (``channels``).

3D: after tracking, every frame written is reconstructed from the point's 2D
samples in all its channels with that frame's cameras; a frame seen in one
channel only is put on that channel's ray at the depth of the point's 3D
position on the frame before it (Allow Single Sensor Tracking).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable, Iterable, Sequence

import numpy as np

from .commands import Command, CompoundCommand
from .editing import DEFAULT_KEYFRAME_BOX, SetKeyframes, _check_frame, _check_points, _named
from .edits import SetPointData
from .errors import CaraError
from .points import (POINT_FIELDS, SRC_DETECTION, SRC_KEYFRAME, SRC_NONE, SRC_TARGET, ST_NONE, ST_RECONSTRUCTED,
                     ST_SINGLE, Point)
from .progress import Progress, frame_payload
from .target_tracker import STOP_EDGE, STOP_FLAT, STOP_SCORE, Box, Keyframe, SensorTracker

#: Tracker pane buttons: mode -> (title, direction, single frame).
TRACK_MODES = {
    "back_to_start": ("Track Back To Start", -1, False),
    "back_one": ("Track Back One Frame", -1, True),
    "forward_one": ("Track Forward One Frame", 1, True),
    "forward_to_end": ("Track Forward To End", 1, False),
}

#: Why a channel's track ended, for the log.
_STOP_TEXT = {STOP_SCORE: "match below the Break Threshold", STOP_EDGE: "left the image",
              STOP_FLAT: "keyframe pattern has no texture", "existing": "reached existing 2D data"}

_2D = ("src", "det", "uv", "score")


# ===================================================================== helpers
def _channels(project, channels: Iterable[int] | None) -> list[int]:
    chans = list(range(project.sensor_count)) if not channels else sorted({int(c) for c in channels})
    bad = [c for c in chans if not 0 <= c < project.sensor_count]
    if bad:
        raise CaraError(f"the take has no channel {bad[0]}")
    return chans


def _has_2d(p: Point, frame: int, s: int) -> bool:
    return p.src[frame, s] != SRC_NONE and bool(np.all(np.isfinite(p.uv[frame, s])))


def keyframe_box(project, p: Point, frame: int, s: int) -> Box:
    """The box of a new keyframe of ``p`` in sensor ``s`` on ``frame``.

    The box the user last adjusted (the point's nearest keyframe in that
    sensor) wins; else one sized from the attached blob (pattern two blob
    diameters wide, the guide's lower bound, comparison region twice that);
    else :data:`~carapost.core.editing.DEFAULT_KEYFRAME_BOX`.
    """
    same = [(abs(f - frame), box) for (f, ss), box in p.keyframes.items() if ss == s]
    if same:
        return tuple(float(v) for v in min(same, key=lambda t: t[0])[1])
    d = int(p.det[frame, s])
    if p.src[frame, s] == SRC_DETECTION and 0 <= d < project.detections[s].count(frame):
        major = float(project.detections[s].frame(frame)[d]["major"])
        half = float(np.clip(round(major), 4, 40))
        return (half, half, max(2 * half, half + 8), max(2 * half, half + 8))
    return DEFAULT_KEYFRAME_BOX


@dataclass
class _Rows:
    """Copies of the points' arrays over a frame span, edited in place, then one SetPointData."""

    project: object
    lo: int
    hi: int
    rows: dict[int, dict[str, np.ndarray]] = field(default_factory=dict)
    changed: dict[int, list[int]] = field(default_factory=dict)     # pid -> frames written, in order

    def row(self, pid: int) -> dict[str, np.ndarray]:
        if pid not in self.rows:
            p = self.project.point(pid)
            self.rows[pid] = {k: a[self.lo:self.hi + 1].copy() for k, a in p.arrays.items()}
        return self.rows[pid]

    def mark(self, pid: int, frame: int) -> None:
        fr = self.changed.setdefault(pid, [])
        if not fr or fr[-1] != frame:
            fr.append(frame)

    def set_2d(self, pid: int, frame: int, s: int, src: int, uv, score: float) -> None:
        r = self.row(pid)
        i = frame - self.lo
        r["src"][i, s], r["det"][i, s], r["uv"][i, s], r["score"][i, s] = src, -1, uv, score
        self.mark(pid, frame)

    def command(self, name: str) -> SetPointData | None:
        """The changed frames of every point (only the span between its first and last change)."""
        updates = []
        for pid, frames in self.changed.items():
            if not frames:
                continue
            a, b = min(frames) - self.lo, max(frames) - self.lo
            updates.append((pid, self.lo + a, {k: v[a:b + 1] for k, v in self.rows[pid].items()}))
        return SetPointData(updates, name=name) if updates else None


def _rebuild_3d(project, rows: _Rows, todo: dict[int, Sequence[int]], direction: int, allow_single: bool) -> None:
    """Reconstruct the 3D samples of ``todo`` (``pid -> frames``) from the rows' 2D samples.

    Frames are visited in ``direction`` order, all points of a frame at once.
    Two or more channels: triangulated with the frame's cameras (one batched
    call per frame).  One channel: with ``allow_single``, the point on its ray
    nearest the 3D position of the frame before (in ``direction``), else of the
    nearest frame with 3D; without it the frame's 3D is left as it was unless
    it rested on 2D data that has gone (then it is removed).
    """
    from .camera import reprojection_errors, triangulate_many

    if project.rig is None:
        return
    by_frame: dict[int, list[int]] = {}
    for pid, frames in todo.items():
        for f in frames:
            by_frame.setdefault(int(f), []).append(pid)
    lo = rows.lo
    for f in sorted(by_frame, key=lambda f: f * direction):
        i = f - lo
        cams = project.rig.cameras_at(f)
        multi, single, rest = [], [], []
        for pid in by_frame[f]:
            r = rows.row(pid)
            valid = (r["src"][i] != SRC_NONE) & np.all(np.isfinite(r["uv"][i]), axis=1)
            n = int(np.count_nonzero(valid))
            (multi if n >= 2 else single if n == 1 and allow_single else rest).append((pid, valid, n))
        if multi:
            uv = np.array([np.where(v[:, None], rows.row(pid)["uv"][i], np.nan) for pid, v, _n in multi], np.float64)
            X = triangulate_many(cams, uv)
            err = reprojection_errors(cams, X, uv)
            for k, (pid, _v, n) in enumerate(multi):
                if np.all(np.isfinite(X[k])):
                    r = rows.row(pid)
                    r["pos"][i], r["status"][i] = X[k], ST_RECONSTRUCTED
                    r["residual"][i] = float(np.sqrt(np.nanmean(err[k] ** 2)))
                else:
                    rest.append((pid, _v, n))
        for pid, valid, n in single:
            r = rows.row(pid)
            ref = _reference_3d(project, rows, pid, f, direction)
            s = int(np.flatnonzero(valid)[0])
            if ref is not None:
                o, d = cams[s].ray(r["uv"][i, s].astype(np.float64))
                t = float(np.dot(ref - o, d))
                if t > 0:
                    r["pos"][i], r["residual"][i], r["status"][i] = o + t * d, 0.0, ST_SINGLE
                    continue
            rest.append((pid, valid, n))
        for pid, _valid, n in rest:
            r = rows.row(pid)
            if (r["status"][i] == ST_RECONSTRUCTED and n < 2) or (r["status"][i] == ST_SINGLE and n < 1):
                r["pos"][i], r["residual"][i], r["status"][i] = np.nan, np.nan, ST_NONE


def _reference_3d(project, rows: _Rows, pid: int, f: int, direction: int) -> np.ndarray | None:
    r = rows.row(pid)
    prev = f - direction
    if rows.lo <= prev <= rows.hi and r["status"][prev - rows.lo] != ST_NONE:
        X = r["pos"][prev - rows.lo].astype(np.float64)
        if np.all(np.isfinite(X)):
            return X
    p = project.point(pid)
    have = np.flatnonzero((p.status != ST_NONE) & np.all(np.isfinite(p.pos), axis=1))
    if not len(have):
        return None
    return p.pos[have[np.argmin(np.abs(have - f))]].astype(np.float64)


def _publish(progress: Progress, rows: _Rows, ids: list[int], f: int) -> None:
    """Hand frame ``f`` of the tracked points (their rows as they will be committed) to the progress listener."""
    i = f - rows.lo
    r = [rows.row(pid) for pid in ids]

    def col(key):
        return np.array([row[key][i] for row in r])

    progress.publish(f, frame_payload(np.array(ids, np.int64), col("status"), col("src"), col("uv"), col("score"),
                                      pos=col("pos"), residual=col("residual"), det=col("det")))


class _Images:
    """``images(sensor, frame)`` with the few frames in use kept (patterns and the frame tracked)."""

    def __init__(self, images):
        fn = getattr(images, "image", images)
        if not callable(fn):
            raise CaraError("images must be a TakeFrames or a callable (sensor, frame) -> image")
        self.fn = fn
        self.cache: dict[tuple[int, int], np.ndarray] = {}

    def get(self, s: int, f: int) -> np.ndarray:
        key = (s, f)
        if key not in self.cache:
            if len(self.cache) > 64:
                self.cache.clear()
            img = np.asarray(self.fn(s, f))
            self.cache[key] = img if img.ndim == 2 else img[..., 0]
        return self.cache[key]


# ===================================================================== tracking
def track_targets(project, frame: int, mode: str, images, point_ids: Sequence[int],
                  channels: Iterable[int] | None = None, progress: Progress | None = None,
                  should_stop: Callable[[], bool] | None = None,
                  on_frame: Callable[[int], None] | None = None) -> Command:
    """Track the selected points with the Target Tracker (the Tracker pane's <, |<, >|, >).

    Parameters
    ----------
    project : Project
    frame : int
        The current frame: tracking starts from the points' 2D samples here.
    mode : str
        A key of :data:`TRACK_MODES`: ``back_to_start``, ``back_one``,
        ``forward_one`` or ``forward_to_end`` (to the active range's start / end).
    images : TakeFrames or callable
        ``images(sensor, frame) -> (H, W) uint8``.
    point_ids : sequence of int
        The selected points.
    channels : iterable of int, optional
        Explicitly selected channels (default: all).
    progress : Progress, optional
        One step per frame; a cancel raises Cancelled (nothing is kept).
        When it is :attr:`~carapost.core.progress.Progress.publishing`, each
        frame's samples of the tracked points (2D and 3D) are published.
    should_stop : callable, optional
        Polled every frame; when it returns True the run ends there and the
        frames done are kept (the Pause button).
    on_frame : callable, optional
        ``on_frame(frame)`` after each frame tracked (Update 2D View Every Frame).

    Returns
    -------
    Command
        Not applied.  ``report``: ``frames`` tracked, ``last`` frame reached,
        ``stops`` {(point, channel): (frame, reason)}, ``stopped_by``.

    Notes
    -----
    The Tracker settings (``tracker.*`` properties) apply: Break Threshold;
    Overwrite Existing Tracks (off: a channel stops where it reaches 2D data it
    did not write); Automatically Add Keyframes (a keyframe on the start frame
    where a channel has none there or behind it); Stop On Next Keyframe (the
    run stops before a frame holding a keyframe of any selected point in any
    channel; off, keyframes are passed through unchanged and re-anchor the
    track); Stop after N Frames (< and > only); Allow Single Sensor Tracking.

    Raises
    ------
    CaraError
        For an unknown mode, no selected point, no 2D sample to start from, or
        when not a single frame could be tracked (with the reason).
    """
    if mode not in TRACK_MODES:
        raise CaraError(f"unknown tracking mode {mode!r} (one of {', '.join(TRACK_MODES)})")
    name, direction, single = TRACK_MODES[mode]
    frame = _check_frame(project, frame)
    ids = _check_points(project, point_ids, name)
    chans = _channels(project, channels)
    if images is None:
        raise CaraError(f"{name} needs the take's images: no channel has media (Edit > Relocate Files)")
    imgs = _Images(images)
    props = project.properties
    threshold = float(props["tracker.break_threshold"])
    overwrite = bool(props["tracker.overwrite_existing_tracks"])
    auto_keys = bool(props["tracker.automatically_add_keyframes"])
    stop_on_key = bool(props["tracker.stop_on_next_keyframe"])
    allow_single = bool(props["tracker.allow_single_sensor_tracking"])

    a, b = project.active_range
    end = frame + direction if single else (b if direction > 0 else a)
    frames = list(range(frame + direction, end + direction, direction)) if (end - frame) * direction > 0 else []
    if not single and props["tracker.stop_after_n_frames"]:
        frames = frames[:int(props["tracker.n_frames"])]
    frames = [f for f in frames if 0 <= f < project.frame_count]
    if not frames:
        where = "end" if direction > 0 else "start"
        raise CaraError(f"{name}: frame {frame} is at the {where} of the active range ({a}-{b}): nothing to track")

    span = (min(frame, frames[-1]), max(frame, frames[-1]))
    rows = _Rows(project, *span)
    new_keys: dict[int, dict] = {}
    trackers: dict[tuple[int, int], SensorTracker] = {}
    for pid in ids:
        p = project.point(pid)
        keys = dict(p.keyframes)
        for s in chans:
            if not _has_2d(p, frame, s):
                continue
            behind = [f for (f, ss) in keys if ss == s and (f - frame) * direction <= 0]
            if auto_keys and not behind:
                keys[(frame, s)] = keyframe_box(project, p, frame, s)
                rows.set_2d(pid, frame, s, SRC_KEYFRAME, p.uv[frame, s], 1.0)
            # An automatic keyframe keeps the sample's position, so the project's uv serve for every key.
            kfs = [Keyframe(f, (float(p.uv[f, s, 0]), float(p.uv[f, s, 1])), tuple(box))
                   for (f, ss), box in keys.items() if ss == s and np.all(np.isfinite(p.uv[f, s]))]
            trackers[(pid, s)] = SensorTracker(lambda fr, s=s: imgs.get(s, fr), frame, p.uv[frame, s], direction, kfs,
                                               threshold, keyframe_box(project, p, frame, s))
        if keys != p.keyframes:
            new_keys[pid] = keys
    if not trackers:
        raise CaraError(f"{name}: the selected point(s) have no 2D sample on frame {frame}"
                        + (f" in channel(s) {', '.join(map(str, chans))}" if channels else "")
                        + ": add a keyframe first (Edit > Edit Target Track)")
    key_frames = {f for pid in ids for (f, _s) in (new_keys.get(pid) or project.point(pid).keyframes)}

    tracked_ids = list(dict.fromkeys(pid for pid, _s in trackers))
    if progress is not None:
        progress.start(len(frames), name)
    stops: dict[tuple[int, int], tuple[int, str]] = {}
    stopped_by, last, done = "", frame, 0
    for f in frames:
        if progress is not None:
            progress.check()
        if should_stop is not None and should_stop():
            stopped_by = "paused"
            break
        if stop_on_key and f in key_frames:
            stopped_by = f"keyframe on frame {f}"
            break
        any_written = False
        for (pid, s), tr in trackers.items():
            if tr.stopped:
                continue
            p = project.point(pid)
            if not overwrite and (f, s) not in p.keyframes and p.src[f, s] != SRC_NONE:
                tr.stopped = "existing"
                stops[(pid, s)] = (f, "existing")
                continue
            st = tr.step()
            if st.stop:
                stops[(pid, s)] = (f, st.stop)
                continue
            any_written = True
            if not st.keyframe:
                rows.set_2d(pid, f, s, SRC_TARGET, st.uv, st.score)
        if not any_written:
            stopped_by = "every channel stopped"
            break
        last, done = f, done + 1
        # 3D frame by frame, in tracking order: the same result as all frames at the end, but the
        # frame is complete now for a live display
        _rebuild_3d(project, rows, {pid: [f] for pid, fr in rows.changed.items() if fr and fr[-1] == f},
                    direction, allow_single)
        if progress is not None:
            if progress.publishing:
                _publish(progress, rows, tracked_ids, f)
            progress.step(1, f"frame {f}")
        if on_frame is not None:
            on_frame(f)
    if not done:
        why = "; ".join(f"point {pid} channel {s}: {_STOP_TEXT.get(r, r)}" for (pid, s), (_f, r) in stops.items())
        raise CaraError(f"{name}: nothing tracked from frame {frame}"
                        + (f" ({why})" if why else f" ({stopped_by})" if stopped_by else ""))

    cmds: list[Command] = []
    data = rows.command("Target Tracked Points")
    if data is not None:
        cmds.append(data)
    cmds += [SetKeyframes(pid, keys, name="Add Keyframes") for pid, keys in new_keys.items()]
    cmd = CompoundCommand(name, cmds)
    cmd.report = {"frames": done, "first": frames[0], "last": last, "stops": stops, "stopped_by": stopped_by,
                  "keyframes_added": sum(len(k) - len(project.point(pid).keyframes) for pid, k in new_keys.items())}
    chan_stops = ", ".join(f"point {pid} ch {s} on frame {f} ({_STOP_TEXT.get(r, r)})"
                           for (pid, s), (f, r) in sorted(stops.items()))
    cmd.summary = (f"{name}: {len(ids)} point(s), {len(trackers)} channel track(s), frames "
                   f"{frames[0]}-{last} ({done} frame(s))"
                   + (f"; stopped: {chan_stops}" if chan_stops else "")
                   + (f"; {stopped_by}" if stopped_by and stopped_by != "every channel stopped" else ""))
    cmd.select_after = None
    return cmd


# ===================================================================== keyframes
def _key_samples(project, todo: dict[int, list[tuple[int, int]]], name: str) -> Command:
    """Turn the 2D samples ``{pid: [(frame, sensor)]}`` into keyframes, as one command."""
    if not any(todo.values()):
        raise CaraError(f"{name}: nothing to key")
    frames = [f for pairs in todo.values() for f, _s in pairs]
    rows = _Rows(project, min(frames), max(frames))
    cmds: list[Command] = []
    n = 0
    for pid, pairs in todo.items():
        p = project.point(pid)
        keys = dict(p.keyframes)
        for f, s in pairs:
            keys[(f, s)] = keys.get((f, s)) or keyframe_box(project, p, f, s)
            if rows.row(pid)["src"][f - rows.lo, s] != SRC_KEYFRAME:
                rows.set_2d(pid, f, s, SRC_KEYFRAME, p.uv[f, s], 1.0)
            n += 1
        if keys != p.keyframes:
            cmds.append(SetKeyframes(pid, keys))
    data = rows.command("Keyframe Samples")
    if data is not None:
        cmds.insert(0, data)
    if not cmds:
        raise CaraError(f"{name}: the samples are keyframes already")
    cmd = CompoundCommand(name, cmds)
    cmd.count = n
    return cmd


def add_keyframes(project, point_ids: Sequence[int], frame: int, channels: Iterable[int] | None = None) -> Command:
    """Tracker pane > Add Keyframe To Current Frame.

    Every selected point gets a keyframe on ``frame`` in each channel where it
    has a 2D sample (restricted to ``channels`` when given); an attached
    detection becomes a keyframe at the same place.

    Raises
    ------
    CaraError
        Without points, or when none has a 2D sample there.
    """
    name = "Add Keyframe To Current Frame"
    frame = _check_frame(project, frame)
    ids = _check_points(project, point_ids, name)
    chans = _channels(project, channels)
    todo = {pid: [(frame, s) for s in chans if _has_2d(project.point(pid), frame, s)] for pid in ids}
    if not any(todo.values()):
        raise CaraError(f"{name}: the selected point(s) have no 2D sample on frame {frame}; place one with "
                        "Edit > Edit Target Track")
    cmd = _key_samples(project, todo, name)
    return _named(cmd, f"{name}: {cmd.count} keyframe(s) on frame {frame}, {len(ids)} point(s)", ids)


def gap_borders(p: Point) -> list[tuple[int, int]]:
    """``(last frame before, first frame after)`` of each gap in the point's 2D tracking.

    A gap is a run of frames without a 2D sample in any channel between the
    point's first and last frames with one (interpolated 3D does not count as
    tracked).
    """
    have = np.flatnonzero(np.any(p.src != SRC_NONE, axis=1))
    if len(have) < 2:
        return []
    jumps = np.flatnonzero(np.diff(have) > 1)
    return [(int(have[j]), int(have[j + 1])) for j in jumps]


def gaps_to_keys(project, point_ids: Sequence[int], channels: Iterable[int] | None = None) -> Command:
    """Edit > Gaps To Keys: keyframes on both sides of every gap of the selected points.

    On the last frame before and the first frame after each gap, every channel
    with a 2D sample there (restricted to ``channels``) becomes a keyframe: the
    two keyframes a Track back across the gap needs.

    Raises
    ------
    CaraError
        Without points, or when the points have no gaps.
    """
    name = "Gaps To Keys"
    ids = _check_points(project, point_ids, name)
    chans = _channels(project, channels)
    todo, gaps = {}, 0
    for pid in ids:
        p = project.point(pid)
        borders = gap_borders(p)
        gaps += len(borders)
        frames = sorted({f for pair in borders for f in pair})
        todo[pid] = [(f, s) for f in frames for s in chans if _has_2d(p, f, s)]
    if not gaps:
        raise CaraError(f"{name}: the selected point(s) have no gaps in their tracking")
    cmd = _key_samples(project, todo, name)
    return _named(cmd, f"{name}: {cmd.count} keyframe(s) around {gaps} gap(s) of {len(ids)} point(s)", ids)


def _keys_on(project, pid: int, frame: int, channels, name: str) -> list[int]:
    p = project.point(pid)
    chans = _channels(project, channels)
    keyed = [s for s in chans if (frame, s) in p.keyframes]
    if not keyed:
        raise CaraError(f"{name}: point {pid} has no keyframe on frame {frame}"
                        + (f" in channel(s) {', '.join(map(str, chans))}" if channels else ""))
    return keyed


def nudge_keyframe(project, pid: int, frame: int, steps: dict[int, tuple[float, float]]) -> Command:
    """Nudge (Ctrl+Shift+arrow): move the point's keyframes on ``frame`` by a step per channel.

    Parameters
    ----------
    steps : dict
        ``channel -> (dx, dy)`` in raw pixels (the GUI turns the arrow on
        screen into each view's image direction).  Channels without a keyframe
        there are left alone, as long as one has one.

    The frame's 3D sample is reconstructed from the moved 2D samples.

    Raises
    ------
    CaraError
        When the point has no keyframe in those channels on ``frame``.
    """
    name = "Nudge Keyframe"
    frame = _check_frame(project, frame)
    keyed = _keys_on(project, pid, frame, list(steps), name)
    p = project.point(pid)
    rows = _Rows(project, frame, frame)
    for s in keyed:
        rows.set_2d(pid, frame, s, SRC_KEYFRAME, p.uv[frame, s] + np.asarray(steps[s], np.float32), 1.0)
    _rebuild_3d(project, rows, {pid: [frame]}, 1, bool(project.properties["tracker.allow_single_sensor_tracking"]))
    cmd = rows.command(name)
    moves = ", ".join(f"channel {s} by ({steps[s][0]:+g}, {steps[s][1]:+g}) px" for s in keyed)
    return _named(cmd, f"{name}: point {pid}, frame {frame}, {moves}", [pid])


def set_keyframe_box(project, pid: int, frame: int, channels: Iterable[int] | None, box: Box) -> Command:
    """Resize the pattern and comparison region of the point's keyframes on ``frame`` (half sizes, px).

    Raises
    ------
    CaraError
        Without a keyframe there, or when the comparison region is smaller than the pattern.
    """
    name = "Edit Keyframe Box"
    box = tuple(float(v) for v in box)
    if len(box) != 4 or min(box) < 1 or box[2] < box[0] or box[3] < box[1]:
        raise CaraError(f"{name}: the half sizes must be at least 1 px and the comparison region must contain "
                        f"the pattern (got {box})")
    keyed = _keys_on(project, pid, frame, channels, name)
    keys = dict(project.point(pid).keyframes)
    for s in keyed:
        keys[(frame, s)] = box
    return _named(SetKeyframes(pid, keys, name=name), f"{name}: point {pid}, frame {frame}, pattern "
                  f"{2 * box[0]:g}x{2 * box[1]:g}, region {2 * box[2]:g}x{2 * box[3]:g} px", [pid])


def clear_tracked(project, point_ids: Sequence[int], start: int, end: int) -> Command:
    """Tracker pane > Clear Tracked Points: the Target Tracker's 2D samples and keyframes of the points.

    On ``start..end`` (the active range) the target-tracked samples and
    keyframes of the selected points go; blob detections stay.  Frames that lose
    2D support are re-triangulated from what remains (or lose their 3D).

    Raises
    ------
    CaraError
        Without points, or when they have no target-tracked data there.
    """
    name = "Clear Tracked Points"
    ids = _check_points(project, point_ids, name)
    start, end = project.check_range(start, end)
    rows = _Rows(project, start, end)
    cmds: list[Command] = []
    n = 0
    for pid in ids:
        p = project.point(pid)
        tt = np.isin(p.src[start:end + 1], (SRC_TARGET, SRC_KEYFRAME))
        keys = {k: v for k, v in p.keyframes.items() if not start <= k[0] <= end}
        if not tt.any() and keys == p.keyframes:
            continue
        r = rows.row(pid)
        fr = np.flatnonzero(tt.any(axis=1))
        for k in _2D:
            r[k][tt] = POINT_FIELDS[k][2]
        for i in fr:
            rows.mark(pid, start + int(i))
        n += int(np.count_nonzero(tt))
        _rebuild_3d(project, rows, {pid: [start + int(i) for i in fr]}, 1, False)
        if keys != p.keyframes:
            cmds.append(SetKeyframes(pid, keys))
    data = rows.command(name)
    if data is not None:
        cmds.insert(0, data)
    if not cmds:
        raise CaraError(f"{name}: the selected point(s) have no target-tracked data in frames {start}-{end}")
    return _named(CompoundCommand(name, cmds), f"{name}: {n} sample(s) of {len(ids)} point(s), frames {start}-{end}",
                  ids)


__all__ = ["TRACK_MODES", "track_targets", "add_keyframes", "gaps_to_keys", "gap_borders", "nudge_keyframe",
           "set_keyframe_box", "clear_tracked", "keyframe_box"]
