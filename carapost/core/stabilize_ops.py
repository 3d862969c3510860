"""Project commands: Process > Stabilize Data [Manual] / [Assisted] and Align Data; stabilised positions.

The result of a stabilisation is kept *beside* the raw data: ``project.stabilization``
(a :class:`~carapost.core.stabilize.Stabilization` or None) holds one raw-to-stabilised
transform per frame; the points' positions are never changed, so the 2D data,
the cameras and every reprojection stay as they were, and stabilising again
starts from the raw data (the guide: "stabilization operates on the original,
raw data").  Align Data composes a further rigid transform onto the stabilised
result, so a later stabilisation undoes it, as the guide warns.

The functions compute without changing the project and return a
:class:`SetStabilization` command carrying ``report`` (the error figures) and
``summary`` (one line for the log); run it through the document's undo stack.
Views and exports read :func:`stabilized_positions`.
"""
from __future__ import annotations

import numpy as np

from .commands import Command
from .errors import CaraError
from .points import BRIM, FACE, ST_NONE
from .stabilize import (Stabilization, align_transform, apply_transforms, compose, solve_assisted, solve_manual)

__all__ = ["SetStabilization", "stabilize_manual", "stabilize_assisted", "align_data", "stabilized_positions",
           "stabilization_transform", "stabilize_array", "describe", "resolve_points"]


class SetStabilization(Command):
    """Replace the project's stabilisation (None: remove it)."""

    def __init__(self, stabilization: Stabilization | None, name: str, summary: str = "", report: dict | None = None):
        self.new = stabilization
        self.name = name
        self.summary = summary
        self.report = report or {}
        self._old: Stabilization | None = None

    def do(self, project) -> None:
        self._old = project.stabilization
        project.stabilization = self.new

    def undo(self, project) -> None:
        project.stabilization = self._old

    def nbytes(self) -> int:
        return sum(s.transforms.nbytes for s in (self.new, self._old) if s is not None) + 256


# ------------------------------------------------------------------- gathering
def _range(project, start, end) -> tuple[int, int]:
    a0, a1 = project.active_range
    return project.check_range(a0 if start is None else int(start), a1 if end is None else int(end))


def _base(project, base_frame, start: int, end: int) -> int:
    b = start if base_frame is None else int(base_frame)
    if not start <= b <= end:
        raise CaraError(f"the base frame {b} is outside the frames being stabilised ({start}-{end}); "
                        "go to a frame of the active range")
    return b


def _positions(project, ids, start: int, end: int) -> np.ndarray:
    """``(n, P, 3)`` float64 raw positions of ``ids`` on ``start..end``, NaN where absent."""
    out = np.full((end - start + 1, len(ids), 3), np.nan)
    for j, pid in enumerate(ids):
        p = project.point(pid)
        have = p.status[start:end + 1] != ST_NONE
        out[have, j] = p.pos[start:end + 1][have]
    return out


def _name(project, pid: int) -> str:
    return project.point(pid).name


def _require_gap_free(project, ids, start: int, end: int, what: str) -> None:
    for pid in ids:
        missing = np.flatnonzero(project.point(pid).status[start:end + 1] == ST_NONE)
        if len(missing):
            raise CaraError(f"{what}: point {_name(project, pid)} has no 3D data on frame {start + missing[0]}; "
                            f"the stable points must be gap-free over frames {start}-{end} "
                            "(fill the gaps or choose other points)")


def _unique_ids(project, point_ids) -> list[int]:
    ids = list(dict.fromkeys(int(p) for p in point_ids))
    for pid in ids:
        project.point(pid)                          # a CaraError names an unknown id
    return ids


def resolve_points(project, items) -> list[int]:
    """Point ids from ids or labels (scripts name points by label)."""
    out = []
    for it in items:
        if isinstance(it, str):
            p = project.point_by_label(it)
            if p is None:
                raise CaraError(f"no point labelled {it!r}")
            out.append(p.id)
        else:
            out.append(project.point(int(it)).id)
    return out


def _parameters(project) -> dict:
    props = project.properties
    return {k: props[f"stabilization.{k}"] for k in ("use_brim_points", "base_frame_weighting",
                                                     "inter_frame_weighting", "stable_points_percent",
                                                     "max_processing_iterations")}


def _full_take(project, transforms: np.ndarray, start: int, end: int) -> np.ndarray:
    full = np.full((project.frame_count, 3, 4), np.nan)
    full[start:end + 1] = transforms
    return full


def describe(errors: dict) -> str:
    """The error figures as the log shows them."""
    return (f"stabilisation error {errors['weighted']:.3f} mm (base frame {errors['base_frame']:.3f} mm, "
            f"inter frame {errors['inter_frame']:.3f} mm, over {errors['stable_points']:.1f} stable points "
            "per frame)")


def _stabilization(project, method, result, ids, base, start, end) -> Stabilization:
    done = np.isfinite(result.transforms[:, 0, 0])
    usage = result.stable[done].mean(axis=0) if done.any() else np.zeros(len(ids))
    return Stabilization(_full_take(project, result.transforms, start, end), method, base, (start, end),
                         np.asarray(ids, np.int64), usage.astype(np.float32),
                         {k: float(v) for k, v in result.errors.items()},
                         _parameters(project))


# ----------------------------------------------------------------- commands
def stabilize_manual(project, point_ids, base_frame: int | None = None, start: int | None = None,
                     end: int | None = None) -> SetStabilization:
    """Stabilize Data [Manual]: map the chosen points of every frame onto the base frame.

    Parameters
    ----------
    project : Project
    point_ids : list of int
        At least three points, gap-free over the range, that expressions do
        not move (forehead, nose bridge, temples).
    base_frame : int, optional
        The frame the others are mapped onto (the GUI passes the current
        frame); default the start of the range.
    start, end : int, optional
        Inclusive range; default the active range.

    Returns
    -------
    SetStabilization
        ``report``: ``base_frame``, ``inter_frame``, ``weighted`` errors (mm,
        measured as for an assisted stabilisation so the two compare),
        ``stable_points``, ``frames``, ``points``.

    Raises
    ------
    CaraError
        Fewer than three points, a point with a gap, a base frame outside the range.
    """
    start, end = _range(project, start, end)
    base = _base(project, base_frame, start, end)
    ids = _unique_ids(project, point_ids or [])
    if len(ids) < 3:
        raise CaraError(f"Stabilize Data [Manual] needs at least three selected points (got {len(ids)})")
    _require_gap_free(project, ids, start, end, "Stabilize Data [Manual]")
    props = project.properties
    # The error figures are over the Stable Points Percent of every face point, as assisted measures them.
    others = [p.id for p in project.face_points() if p.id not in ids]
    x = _positions(project, ids + others, start, end)
    result = solve_manual(x, base - start, range(len(ids)), float(props["stabilization.stable_points_percent"]),
                          float(props["stabilization.base_frame_weighting"]),
                          float(props["stabilization.inter_frame_weighting"]))
    stab = _stabilization(project, "manual", result, ids, base, start, end)
    stab.usage = stab.usage[:len(ids)]
    report = dict(result.errors, frames=end - start + 1, points=len(ids), base_frame_index=base)
    summary = (f"Stabilize Data [Manual]: frames {start}-{end} onto frame {base} from {len(ids)} points; "
               + describe(result.errors))
    return SetStabilization(stab, "Stabilize Data [Manual]", summary, report)


def stabilize_assisted(project, point_ids=None, base_frame: int | None = None, start: int | None = None,
                       end: int | None = None, progress=None) -> SetStabilization:
    """Stabilize Data [Assisted]: pick the most stable points and the transforms together.

    Starts from the selected points (at least three, gap-free) and lets every
    face point (and the brim's with ``stabilization.use_brim_points``) contribute
    when it is among the Stable Points Percent most stable on a frame; the
    Stabilization Parameters weigh base-frame against inter-frame error and
    bound the iterations (see :func:`carapost.core.stabilize.solve_assisted`).

    Parameters
    ----------
    project : Project
    point_ids : list of int, optional
        The user's selection; None or empty: start from every candidate point.
    base_frame, start, end : int, optional
        As :func:`stabilize_manual`.
    progress : Progress, optional
        One step per iteration; a cancel leaves the project untouched.

    Returns
    -------
    SetStabilization
        ``report`` as :func:`stabilize_manual`'s plus ``iterations``,
        ``converged``, ``candidates`` and ``most_used`` (the ids of the points
        used on the most frames).
    """
    start, end = _range(project, start, end)
    base = _base(project, base_frame, start, end)
    ids = _unique_ids(project, point_ids or [])
    if 0 < len(ids) < 3:
        raise CaraError(f"Stabilize Data [Assisted] needs at least three selected points (got {len(ids)}), "
                        "or none to start from every point")
    _require_gap_free(project, ids, start, end, "Stabilize Data [Assisted]")
    props = project.properties
    kinds = (FACE, BRIM) if props["stabilization.use_brim_points"] else (FACE,)
    candidates = ids + [p.id for p in project.points.values() if p.kind in kinds and p.id not in ids
                        and p.status[base] != ST_NONE]
    if len(candidates) < 3:
        raise CaraError(f"Stabilize Data [Assisted]: fewer than three points have 3D data on the base frame {base}")
    x = _positions(project, candidates, start, end)
    iterations = int(props["stabilization.max_processing_iterations"])
    if progress is not None:
        progress.start(iterations, "Stabilize Data [Assisted]")
    result = solve_assisted(x, base - start, range(len(ids)) if ids else None,
                            stable_fraction=float(props["stabilization.stable_points_percent"]),
                            base_weight=float(props["stabilization.base_frame_weighting"]),
                            inter_weight=float(props["stabilization.inter_frame_weighting"]),
                            max_iterations=iterations, progress=progress)
    stab = _stabilization(project, "assisted", result, candidates, base, start, end)
    unstable = int(np.count_nonzero(~np.isfinite(result.transforms[:, 0, 0])))
    order = np.argsort(-stab.usage, kind="stable")
    report = dict(result.errors, frames=end - start + 1, points=len(candidates), candidates=len(candidates),
                  iterations=result.iterations, converged=result.converged, base_frame_index=base,
                  unstabilised_frames=unstable, most_used=[int(candidates[i]) for i in order[:10]])
    summary = (f"Stabilize Data [Assisted]: frames {start}-{end} onto frame {base}, {len(candidates)} candidate "
               f"points, {result.iterations} iteration(s){'' if result.converged else ' (not converged)'}; "
               + describe(result.errors))
    if unstable:
        summary += f"; {unstable} frame(s) had fewer than three points and are not stabilised"
    return SetStabilization(stab, "Stabilize Data [Assisted]", summary, report)


def align_data(project, point_ids, frame: int) -> SetStabilization:
    """Align Data: put the face data into the frame three selected points define.

    The first point becomes the origin, the second lies on the +X axis, the
    third in the XY plane on the +Y side (Z completes a right-handed frame), as
    those points are on ``frame``.  The alignment is applied on top of the
    stabilisation (or alone when the take is not stabilised): raw positions,
    cameras and reprojections do not change, and stabilising again removes it.

    Parameters
    ----------
    project : Project
    point_ids : list of int
        Exactly three points, in selection order.
    frame : int
        The frame whose positions define the axes (the current frame).

    Returns
    -------
    SetStabilization
    """
    ids = _unique_ids(project, point_ids or [])
    if len(ids) != 3:
        raise CaraError(f"Align Data needs exactly three selected points (got {len(ids)})")
    frame = project.clamp_frame(frame)
    old = project.stabilization
    if old is not None and not np.isfinite(old.transforms[frame, 0, 0]):
        a, b = old.frame_range
        raise CaraError(f"Align Data: frame {frame} is not stabilised (frames {a}-{b} are); "
                        "go to a stabilised frame")
    pts = stabilized_positions(project, frame, ids)
    for pid, p in zip(ids, pts):
        if not np.isfinite(p).all():
            raise CaraError(f"Align Data: point {_name(project, pid)} has no 3D data on frame {frame}")
    a = align_transform(*pts)
    if old is None:
        stab = Stabilization(np.broadcast_to(a, (project.frame_count, 3, 4)).copy(), "none", -1,
                             (0, project.frame_count - 1), alignment=a)
    else:
        stab = Stabilization(compose(a, old.transforms), old.method, old.base_frame, old.frame_range,
                             old.point_ids, old.usage, dict(old.errors), dict(old.parameters),
                             a if old.alignment is None else compose(a, old.alignment))
    n = [_name(project, i) for i in ids]
    summary = (f"Align Data: origin at {n[0]}, X axis towards {n[1]}, XY plane through {n[2]} "
               f"(their positions on frame {frame})")
    return SetStabilization(stab, "Align Data", summary, {"alignment": a.tolist(), "frame": frame})


# ------------------------------------------------------------------ reading
def stabilization_transform(project, frame: int) -> np.ndarray | None:
    """The ``(3, 4)`` raw-to-stabilised transform of ``frame``; None when the frame is not stabilised."""
    s = project.stabilization
    if s is None:
        return None
    t = np.asarray(s.transforms[int(frame)], np.float64)
    return t if np.isfinite(t).all() else None


def stabilize_array(project, positions: np.ndarray, start: int) -> np.ndarray:
    """Raw ``(n, P, 3)`` positions of frames ``start..start+n-1`` moved by the project's stabilisation.

    NaN on frames the stabilisation does not cover; unchanged when the project
    has none.
    """
    s = project.stabilization
    x = np.asarray(positions, np.float64)
    if s is None:
        return x.copy()
    t = np.asarray(s.transforms[start:start + len(x)], np.float64)
    return apply_transforms(t, x)


def stabilized_positions(project, frames, point_ids=None) -> np.ndarray:
    """Stabilised (and aligned) 3D positions, for the views and exports.

    Parameters
    ----------
    project : Project
    frames : int or slice
        One frame, or a slice of frames (step 1).
    point_ids : list of int, optional
        Columns, in this order; default every point in project order.

    Returns
    -------
    ndarray
        ``(P, 3)`` for one frame, ``(n, P, 3)`` for a slice; float64 mm, NaN where
        the point has no 3D sample or the frame is not stabilised.  Without a
        stabilisation these are the raw positions, so a view can call this
        whatever the project holds.
    """
    ids = list(project.points) if point_ids is None else list(point_ids)
    single = not isinstance(frames, slice)
    if single:
        f = int(frames)
        if not 0 <= f < project.frame_count:
            raise CaraError(f"frame {f} is outside the take (0-{project.frame_count - 1})")
        start, stop = f, f + 1
    else:
        start, stop, step = frames.indices(project.frame_count)
        if step != 1:
            raise CaraError("stabilized_positions takes a slice of consecutive frames")
        stop = max(stop, start)
    x = stabilize_array(project, _positions(project, ids, start, stop - 1), start) if stop > start \
        else np.zeros((0, len(ids), 3))
    return x[0] if single else x
