"""carapost's scripting API, after the guide's PyCara (CONTRACT section 6).

- :class:`CaraProcess` creates and processes projects (the Process menu, headless).
- :class:`CaraExport` reads a ``.cara``: points, labels, 2D tracks, detections, cameras, brim, timecode.
- :class:`Pico` reads a ``.pico``: metadata and frames.
- :class:`DebugServices` sets the log level.

Every processing call pushes one command on the project's undo stack, exactly as
the GUI's menu items do; ``help(CaraProcess.detect_blobs)`` shows each call.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

import numpy as np

from ..core.document import Document
from ..core.errors import CaraError
from ..core.points import BRIM, FACE
from ..core.progress import Progress
from ..core.project import Project

__all__ = ["CaraProcess", "CaraExport", "Pico", "DebugServices", "CaraError", "property_table", "run_script"]

log = logging.getLogger("carapost")


class CaraProcess:
    """Create a project from a take and run the Process menu's operations on it.

    Parameters
    ----------
    source : str or Path, optional
        A ``.cara`` project, a ``.pico`` file (its whole take is imported) or,
        with ``sources``, nothing.
    sources : list of str, optional
        One video file or image folder per channel, in channel order.

    Examples
    --------
    >>> p = CaraProcess("Example_0.pico")            # doctest: +SKIP
    >>> p.set_property("blob.find_white_blobs", True)  # doctest: +SKIP
    >>> p.detect_blobs()                             # doctest: +SKIP
    >>> p.save("Example_b.cara")                     # doctest: +SKIP
    """

    def __init__(self, source: str | Path | None = None, sources: list[str] | None = None):
        from ..io.take import project_from_input

        self.document = Document(project_from_input(source, sources))

    @classmethod
    def from_project(cls, project: Project) -> "CaraProcess":
        """Wrap a project already in memory."""
        self = cls.__new__(cls)
        self.document = Document(project)
        return self

    @property
    def project(self) -> Project:
        """The project being processed."""
        return self.document.project

    # ----------------------------------------------------------- properties
    def get_property(self, key: str) -> Any:
        """Value of property ``group.name`` (see ``carapost properties``)."""
        return self.project.properties[key]

    def set_property(self, key: str, value: Any) -> None:
        """Set property ``group.name`` (validated; undoable)."""
        from ..core.edits import SetProperties

        self.document.run(SetProperties({key: value}))

    def properties(self) -> dict[str, Any]:
        """Every property, ``group.name -> value``."""
        return self.project.properties.to_dict()

    # ------------------------------------------------------------- set-up
    def import_xcp(self, path: str | Path) -> None:
        """File > Import XCP."""
        from ..io.imports import import_xcp

        self.document.run(import_xcp(self.project, path, log))

    def import_labels(self, path: str | Path) -> None:
        """File > Import Labels From Text File (or From Cara File for a ``.cara``)."""
        from ..io.imports import import_labels_from_cara, import_labels_from_text

        fn = import_labels_from_cara if str(path).lower().endswith(".cara") else import_labels_from_text
        self.document.run(fn(self.project, path))

    def set_brim(self, brim: str | Path) -> None:
        """Initialize Default Calibration Brim (``"v2.0"``, ``"v1.1"``, ``"v1.0"``) or Import Calibration Brim [svg]."""
        from ..core.brim import DEFAULT_BRIMS, default_brim
        from ..core.edits import SetBrim

        if str(brim) in DEFAULT_BRIMS:
            self.document.run(SetBrim(default_brim(str(brim)), f"Initialize Default Calibration Brim [{brim}]"))
        else:
            from ..io.brim_svg import read_brim_svg

            self.document.run(SetBrim(read_brim_svg(brim), "Import Calibration Brim [svg]"))

    # ---------------------------------------------------------- processing
    def detect_blobs(self, sensors: list[int] | None = None, start: int | None = None, end: int | None = None,
                     progress: Progress | None = None, workers: int | None = None) -> bool:
        """Detect Blobs over a range (default: the active range) of some sensors (default: all).

        ``detect_blobs()`` or ``detect_blobs(sensors, start, end)`` as in PyCara.
        ``workers`` is the number of detection processes (default: every core;
        1 detects in this process, as a batch worker should).
        """
        from ..core.blob_ops import detect_blobs_range

        a, b = self.project.active_range
        start = a if start is None else start
        end = b if end is None else end
        self.document.run(detect_blobs_range(self.project, start, end, sensors=sensors, progress=progress,
                                             workers=workers))
        return True

    def apply_seeds(self, seeds: dict | str | Path) -> None:
        """Attach brim seeds and merge face seeds (``seeds.json``, CONTRACT section 3)."""
        import json

        from ..core.calib.seeds import apply_seeds

        if not isinstance(seeds, dict):
            seeds = json.loads(Path(seeds).read_text())
        self.document.run(apply_seeds(self.project, seeds))

    def initialize_from_seeds(self, seeds: dict | str | Path) -> int:
        """Initialise the take from a person's clicks, as ``carapost process`` does.

        Attaches the brim seeds, runs Solve Calibration Brim, merges the face
        seeds, then Bundle Current Frame and Initialize 3D, all on the seeds'
        frame.  Needs detections on that frame, cameras (an imported XCP) and a
        calibration brim (:meth:`set_brim`).  A failing step undoes the earlier
        ones, so the project is left as it was.

        Parameters
        ----------
        seeds : dict or path
            A ``seeds.json`` (CONTRACT section 3) or its dict.

        Returns
        -------
        int
            The frame initialised (the seeds' ``frame``): track from there.
        """
        import json

        from ..core.pipeline import process_to_init3d

        if not isinstance(seeds, dict):
            from ..core.errors import read_bytes

            try:
                seeds = json.loads(read_bytes(seeds))
            except json.JSONDecodeError as e:
                raise CaraError(f"not valid JSON: {e}", seeds) from None
        process_to_init3d(self.project, seeds, None, log=log.info, stack=self.document.stack)
        return self.document.set_frame(int(seeds.get("frame", 0)))

    def solve_calibration_brim(self, frame: int | None = None) -> None:
        """Process > Solve Calibration Brim [Manual] on ``frame`` (default: the current frame)."""
        from ..core.calib.brim_solve import solve_calibration_brim

        self.document.run(solve_calibration_brim(self.project, self._frame(frame)))

    def bundle_current_frame(self, frame: int | None = None) -> dict:
        """Process > Bundle Current Frame [Unconstrained]; returns the report (``rms_px``...)."""
        from ..core.calib.bundle import bundle_current_frame

        cmd, report = bundle_current_frame(self.project, self._frame(frame))
        self.document.run(cmd)
        return report

    def bundle_sequence(self, start: int | None = None, end: int | None = None,
                        progress: Progress | None = None) -> dict:
        """Process > Bundle Sequence [Unconstrained] over a range (default: the active range)."""
        from ..core.calib.bundle import bundle_sequence

        cmd, report = bundle_sequence(self.project, start, end, progress)
        self.document.run(cmd)
        return report

    def initialize_3d(self, frame: int | None = None) -> dict:
        """Process > Initialize 3D on ``frame``; returns the report."""
        from ..core.calib.init3d import initialize_3d

        cmd, report = initialize_3d(self.project, self._frame(frame))
        self.document.run(cmd)
        return report

    # ------------------------------------------------------------------ ROM
    def load_rom(self, path: str | Path) -> None:
        """Process > Load ROM: the ``.cara`` of a ROM take of the same actor (its path is saved with the project)."""
        from ..core.rom_ops import load_rom

        self.document.run(load_rom(self.project, path))

    def initialize_from_rom(self, frame: int | None = None, brim_only: bool = False) -> dict:
        """Process > Initialize from ROM (``brim_only``: [Brim Only]) on ``frame`` (default: the current frame).

        Uses the Initialize From ROM Parameters (``initialize_from_rom.*``).  Returns the
        report: ``brim_markers`` matched, ``points`` created, ``labelled``, ``rms_px``.
        Raises CaraError when no ROM is loaded.
        """
        from ..core.rom_ops import initialize_from_rom
        from ..io.frames import TakeFrames

        images = TakeFrames(self.project) if any(s.media.path and not s.media.missing
                                                 for s in self.project.sensors) else None
        try:
            cmd = initialize_from_rom(self.project, self._frame(frame), brim_only=brim_only, images=images)
        finally:
            if images is not None:
                images.close()
        self.document.run(cmd)
        log.info(cmd.summary)
        return cmd.report

    def add_rom_correspondence(self, rom_point: int, sensor: int, detection: int, frame: int | None = None) -> None:
        """ROM Tools > Add 2D To ROM Correspondence: ROM point ``rom_point`` (its id) is ``detection`` of ``sensor``."""
        from ..core.rom_ops import add_2d_to_rom_correspondence

        self.document.run(add_2d_to_rom_correspondence(self.project, rom_point,
                                                       [(sensor, self._frame(frame), detection)]))

    def clear_rom_correspondences(self) -> None:
        """ROM Tools > Clear 2D To ROM Correspondence."""
        from ..core.rom_ops import clear_2d_to_rom_correspondences

        self.document.run(clear_2d_to_rom_correspondences(self.project))

    def solve_rom_camera(self, sensor: int | None = None) -> None:
        """ROM Tools > Solve ROM Camera From Correspondences (4+ in one channel).

        The other ROM cameras follow it, or stay where they are when they already fit the take's brim.
        """
        from ..core.rom_ops import solve_rom_camera_from_correspondences

        cmd = solve_rom_camera_from_correspondences(self.project, sensor)
        self.document.run(cmd)
        log.info(cmd.summary)

    def solve_rom_face_alignment(self, frame: int | None = None) -> None:
        """ROM Tools > Solve ROM Face Alignment From Correspondences (3+ face point correspondences)."""
        from ..core.rom_ops import solve_rom_face_alignment_from_correspondences

        self.document.run(solve_rom_face_alignment_from_correspondences(self.project, self._frame(frame)))

    def track(self, frame: int | None = None, backwards: bool = False, single_frame: bool = False,
              point_ids: list[int] | None = None, progress: Progress | None = None) -> None:
        """Track Forwards/Backwards [Sequence] (or [Single Frame]) from ``frame``."""
        from ..core.tracking import track

        self._with_images(lambda images: self.document.run(
            track(self.project, self._frame(frame), -1 if backwards else 1, point_ids=point_ids,
                  single_frame=single_frame, images=images, progress=progress)))

    def _with_images(self, fn):
        """Run ``fn(images)`` with the take's frames (None when the project has no media)."""
        from ..io.frames import TakeFrames

        images = TakeFrames(self.project) if any(s.media.path and not s.media.missing
                                                 for s in self.project.sensors) else None
        try:
            return fn(images)
        finally:
            if images is not None:
                images.close()

    def target_track(self, point_ids: list[int], mode: str = "forward_to_end", frame: int | None = None,
                     channels: list[int] | None = None, progress: Progress | None = None) -> dict:
        """The Tracker pane's buttons: Target-track ``point_ids`` from their 2D samples on ``frame``.

        Parameters
        ----------
        point_ids : list of int
            The points to track (they need a keyframe or 2D sample on ``frame``).
        mode : str
            ``"forward_to_end"``, ``"forward_one"``, ``"back_one"`` or ``"back_to_start"``
            (to the end / start of the active range).
        channels : list of int, optional
            Restrict to these channels (the Selection pane's explicit selection).

        Returns
        -------
        dict
            The run's report (frames tracked, where and why each track stopped).
        """
        from ..core import target_ops

        def run(images):
            if images is None:
                raise CaraError("target tracking needs the take's images (no media in this project)")
            cmd = target_ops.track_targets(self.project, self._frame(frame), mode, images, point_ids,
                                           channels, progress=progress)
            self.document.run(cmd)
            return dict(getattr(cmd, "report", {}) or {})

        return self._with_images(run)

    def add_keyframes(self, point_ids: list[int], frame: int | None = None,
                      channels: list[int] | None = None) -> None:
        """Edit > Add Keyframe To Current Frame for ``point_ids`` on ``frame``."""
        from ..core import target_ops

        self.document.run(target_ops.add_keyframes(self.project, point_ids, self._frame(frame), channels))

    def gaps_to_keys(self, point_ids: list[int], channels: list[int] | None = None) -> None:
        """Edit > Gaps To Keys: keyframes on the samples either side of every gap of ``point_ids``."""
        from ..core import target_ops

        self.document.run(target_ops.gaps_to_keys(self.project, point_ids, channels))

    def clear_tracked_points(self, point_ids: list[int], start: int | None = None, end: int | None = None) -> None:
        """The Tracker pane's Clear Tracked Points over ``start..end`` (default: the active range)."""
        from ..core import target_ops

        a, b = self.project.active_range
        self.document.run(target_ops.clear_tracked(self.project, point_ids, a if start is None else start,
                                                   b if end is None else end))

    def interpolate_gaps(self, point_ids: list[int] | None = None) -> None:
        """Process > Interpolate Gaps over the active range (all points, or ``point_ids``)."""
        from ..core.gapfill_ops import interpolate_gaps

        self.document.run(interpolate_gaps(self.project, point_ids))

    # ------------------------------------------------------- stabilisation
    def stabilize(self, manual_point_ids: list | None = None, base_frame: int | None = None) -> dict:
        """Process > Stabilize Data [Manual] over the active range; returns the error figures (mm).

        ``manual_point_ids``: at least three gap-free points (ids or labels) that
        expressions do not move; default the selected points.  ``base_frame``:
        default the current frame.  The raw positions are kept; read the result
        with :meth:`CaraExport.point_3d_stabilized` or
        :func:`carapost.core.stabilize_ops.stabilized_positions`.
        """
        from ..core.stabilize_ops import resolve_points, stabilize_manual

        ids = resolve_points(self.project, manual_point_ids) if manual_point_ids else self.document.selection.points
        return self._logged(stabilize_manual(self.project, ids, self._frame(base_frame)))

    def stabilize_assisted(self, point_ids: list | None = None, base_frame: int | None = None,
                           progress: Progress | None = None) -> dict:
        """Process > Stabilize Data [Assisted] with the Stabilization Parameters; returns the error figures.

        ``point_ids`` (ids or labels; default the selected points, or every
        point when none is selected) is the starting set; the most stable points
        of each frame are found from there.
        """
        from ..core.stabilize_ops import resolve_points, stabilize_assisted

        ids = resolve_points(self.project, point_ids) if point_ids else self.document.selection.points
        return self._logged(stabilize_assisted(self.project, ids, self._frame(base_frame), progress=progress))

    def align_data(self, p0, p1, p2, frame: int | None = None) -> None:
        """Process > Align Data: ``p0`` the origin, ``p1`` on +X, ``p2`` in the XY plane (+Y side).

        Points are ids or labels, placed as they are on ``frame`` (default the
        current frame); applied on top of the stabilisation, raw data unchanged.
        """
        from ..core.stabilize_ops import align_data, resolve_points

        self._logged(align_data(self.project, resolve_points(self.project, [p0, p1, p2]), self._frame(frame)))

    def _logged(self, cmd) -> dict:
        self.document.run(cmd)
        log.info(cmd.summary)
        return dict(cmd.report)

    def undo(self) -> None:
        """Edit > Undo."""
        self.document.undo()

    def redo(self) -> None:
        """Edit > Redo."""
        self.document.redo()

    def save(self, path: str | Path) -> None:
        """File > Save As (atomic)."""
        from ..io.cara import save_project

        save_project(self.project, path)
        self.document.stack.mark_clean()

    def export_c3d(self, path: str | Path) -> None:
        """File > Export C3D."""
        from ..io.export_c3d import export_c3d

        export_c3d(self.project, path)

    def export_fbx(self, path: str | Path, frame_range: tuple[int, int] | None = None) -> None:
        """File > Export FBX: one animated Null per point (``frame_range``: first, last frame; default per the Export properties)."""
        from ..io.export_fbx import write_fbx

        write_fbx(self.project, path, frame_range)

    def export_xcp(self, path: str | Path, frame: int | None = None) -> None:
        """File > Export XCP: the cameras of ``frame`` (default: the start of the active range)."""
        from ..io.export_xcp import export_xcp

        export_xcp(self.project, path, self.project.active_range[0] if frame is None else int(frame))

    def _frame(self, frame: int | None) -> int:
        return self.document.current_frame if frame is None else int(frame)


class CaraExport:
    """Read a ``.cara`` project for custom exports.

    Parameters
    ----------
    path : str or Path
        The project file (opened memory-mapped: fast whatever the take's length).
    """

    def __init__(self, path: str | Path):
        from ..io.cara import load_project

        self.project = load_project(path)

    # ----------------------------------------------------------- structure
    @property
    def frame_count(self) -> int:
        return self.project.frame_count

    @property
    def frame_rate(self) -> float:
        return self.project.frame_rate

    @property
    def sensor_count(self) -> int:
        return self.project.sensor_count

    @property
    def take_name(self) -> str:
        """The take's name (``Example`` for ``Example_0.pico``)."""
        return self.project.name

    @property
    def timecode_start(self) -> str:
        """Timecode ``HH:MM:SS:FF`` of frame 0."""
        return self.project.timecode_start

    def properties(self) -> dict[str, Any]:
        """Every property of the project, ``group.name -> value`` (see :func:`property_table`)."""
        return self.project.properties.to_dict()

    def image_size(self, sensor: int) -> tuple[int, int]:
        """``(width, height)`` in pixels of a sensor's raw images (the frame of 2D tracks)."""
        info = self.project.sensors[sensor]
        return info.width, info.height

    def labels(self) -> list[str]:
        """The label list (Labelling pane order)."""
        return list(self.project.labels)

    def point_ids(self, kind: str | None = FACE) -> list[int]:
        """Ids of face points (``kind="brim"`` for brim points, ``None`` for all)."""
        return [p.id for p in self.project.points.values() if kind is None or p.kind == kind]

    def point_label(self, pid: int) -> str:
        """The point's label, ``""`` when unlabelled."""
        return self.project.point(pid).label

    # ---------------------------------------------------------------- data
    def point_3d(self, pid: int) -> np.ndarray:
        """``(F, 3)`` positions in mm (brim frame), NaN where the point has none."""
        p = self.project.point(pid)
        out = np.asarray(p.pos, float).copy()
        out[p.status == 0] = np.nan
        return out

    def point_3d_stabilized(self, pid: int) -> np.ndarray:
        """``(F, 3)`` stabilised (and aligned) positions in mm; NaN where absent or not stabilised.

        The raw positions (:meth:`point_3d`) when the project is not stabilised.
        """
        from ..core.stabilize_ops import stabilized_positions

        return stabilized_positions(self.project, slice(None), [pid])[:, 0]

    def stabilization_transforms(self) -> np.ndarray | None:
        """``(F, 3, 4)`` per-frame raw-to-stabilised transforms ``[R | t]`` (NaN: not stabilised), or None."""
        s = self.project.stabilization
        return None if s is None else np.array(s.transforms, float)

    def point_status(self, pid: int) -> np.ndarray:
        """``(F,)`` status: 0 none, 1 reconstructed, 2 single-sensor, 3 interpolated."""
        return np.asarray(self.project.point(pid).status).copy()

    def point_2d(self, pid: int, sensor: int) -> np.ndarray:
        """``(F, 2)`` raw-pixel 2D track of a point in a sensor, NaN where absent."""
        p = self.project.point(pid)
        uv = np.asarray(p.uv[:, sensor], float).copy()
        uv[p.src[:, sensor] == 0] = np.nan
        return uv

    def point_2d_source(self, pid: int, sensor: int) -> np.ndarray:
        """``(F,)`` how each 2D sample was found: 0 none, 1 detection, 2 patch, 3 target, 4 keyframe."""
        return np.asarray(self.project.point(pid).src[:, sensor]).copy()

    def brim_3d(self) -> dict[int, np.ndarray]:
        """Brim marker index -> ``(F, 3)`` tracked positions of brim points."""
        return {p.brim_index: self.point_3d(p.id) for p in self.project.points.values() if p.kind == BRIM}

    def brim_markers(self) -> np.ndarray:
        """The calibration brim's marker layout ``(M, 3)`` in mm (empty without a brim)."""
        return np.zeros((0, 3)) if self.project.brim is None else self.project.brim.markers.copy()

    def detections(self, sensor: int, frame: int) -> np.ndarray:
        """Detections of one sensor and frame (records x, y, major, minor, angle, score, color)."""
        return self.project.detections[sensor].frame(frame).copy()

    def camera(self, sensor: int, frame: int):
        """The :class:`carapost.core.camera.Camera` of a sensor on a frame."""
        if self.project.rig is None:
            raise CaraError("the project has no cameras")
        return self.project.rig.camera(sensor, frame)

    # ------------------------------------------------------------ timecode
    def frame_to_timecode(self, frame: int) -> str:
        """Zero-based frame index -> ``HH:MM:SS:FF`` from the take's timecode start (non-drop)."""
        return frame_to_timecode(frame, self.project.timecode_start, self.project.frame_rate)

    def timecode_to_frame(self, timecode: str) -> int:
        """``HH:MM:SS:FF`` -> zero-based frame index."""
        return timecode_to_frames(timecode, self.project.frame_rate) - \
            timecode_to_frames(self.project.timecode_start, self.project.frame_rate)

    def frame_to_burnt_in(self, frame: int, sensor: int = 0) -> int:
        """Zero-based frame index -> the frame number burnt into the sensor's ``.pico`` frames."""
        return int(self._burnt_in(sensor)[frame - self.project.sensors[sensor].image_offset])

    def burnt_in_to_frame(self, number: int, sensor: int = 0) -> int:
        """Burnt-in frame number -> zero-based frame index."""
        nums = self._burnt_in(sensor)
        hits = np.flatnonzero(nums == number)
        if not len(hits):
            raise CaraError(f"no frame numbered {number} in sensor {sensor}")
        return int(hits[0]) + self.project.sensors[sensor].image_offset

    def _burnt_in(self, sensor: int) -> np.ndarray:
        from ..io.pico import PicoReader

        media = self.project.sensors[sensor].media
        if media.kind != "pico" or media.missing:
            raise CaraError(f"sensor {sensor} has no .pico media with burnt-in frame numbers")
        with PicoReader(media.path) as r:
            return np.asarray(r.frame_numbers)


def run_script(main) -> None:
    """Run a script's ``main()`` as the ``carapost`` command runs its subcommands, then exit.

    The exit status is what ``main`` returns (``None`` is 0).  A
    :class:`CaraError` (a bad or missing input) becomes one line on stderr,
    ``<script>: error: <file>: <problem>``, and exit status 2, without a
    traceback; Ctrl+C exits with 130; a closed pipe (``| head``) with 0.  The
    guide's example scripts end with ``run_script(main)``.
    """
    import os
    import sys

    prog = Path(sys.argv[0]).stem or "script"
    try:
        code = int(main() or 0)
    except CaraError as e:
        print(f"{prog}: error: {e}", file=sys.stderr)
        code = 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        code = 130
    except BrokenPipeError:
        # The reader has gone; point stdout at devnull so the interpreter's final flush is quiet.
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        code = 0
    sys.exit(code)


def property_table() -> list[dict[str, Any]]:
    """Every property the Properties pane shows, in its order, with the guide's defaults.

    Returns
    -------
    list of dict
        One per property: ``key`` (``group.name``, what :meth:`CaraProcess.set_property`
        takes), ``group``, ``group_title``, ``title``, ``type`` (``bool``, ``int``,
        ``float``, ``str``), ``default``, ``minimum``, ``maximum``, ``unit``, ``help``.
    """
    from ..core.properties import GROUPS, PROPERTY_TABLE

    return [{"key": p.key, "group": p.group, "group_title": GROUPS[p.group], "title": p.title,
             "type": p.type.__name__, "default": p.default, "minimum": p.minimum, "maximum": p.maximum,
             "unit": p.unit, "help": p.help} for p in PROPERTY_TABLE]


def timecode_to_frames(timecode: str, rate: float) -> int:
    """``HH:MM:SS:FF`` -> frames since midnight at ``rate`` (rounded to whole frames per second)."""
    try:
        h, m, s, f = (int(x) for x in timecode.replace(";", ":").split(":"))
    except ValueError:
        raise CaraError(f"bad timecode {timecode!r} (expected HH:MM:SS:FF)") from None
    fps = int(round(rate))
    return ((h * 60 + m) * 60 + s) * fps + f


def frame_to_timecode(frame: int, start: str, rate: float) -> str:
    """Zero-based ``frame`` after timecode ``start`` -> ``HH:MM:SS:FF``."""
    fps = int(round(rate))
    n = timecode_to_frames(start, rate) + int(frame)
    f = n % fps
    s = n // fps
    return f"{s // 3600 % 24:02d}:{s // 60 % 60:02d}:{s % 60:02d}:{f:02d}"


class Pico:
    """Read a ``.pico`` file: metadata and frames.

    Parameters
    ----------
    path : str or Path
    """

    def __init__(self, path: str | Path):
        from ..io.pico import PicoReader

        self._reader = PicoReader(path)

    @property
    def metadata(self) -> dict[str, str]:
        """The capture's metadata dictionary (logger, capture name, timecode...)."""
        return dict(self._reader.metadata)

    @property
    def frame_count(self) -> int:
        return self._reader.frame_count

    @property
    def size(self) -> tuple[int, int]:
        """``(width, height)`` in pixels."""
        return self._reader.width, self._reader.height

    def frame(self, index: int) -> np.ndarray:
        """Frame ``index`` (zero-based) as a ``(height, width)`` uint8 grey image."""
        return self._reader.read(index)

    def frame_number(self, index: int) -> int:
        """The burnt-in frame number of frame ``index``."""
        return int(self._reader.frame_numbers[index])

    def close(self) -> None:
        self._reader.close()

    def __enter__(self) -> "Pico":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class DebugServices:
    """Show or hide log information (PyDebugServices)."""

    LEVELS = {"debug": logging.DEBUG, "info": logging.INFO, "warning": logging.WARNING, "error": logging.ERROR,
              "off": logging.CRITICAL + 10}

    @staticmethod
    def set_log_level(level: str) -> None:
        """``"debug"``, ``"info"``, ``"warning"``, ``"error"`` or ``"off"``."""
        try:
            lvl = DebugServices.LEVELS[level.lower()]
        except KeyError:
            raise CaraError(f"unknown log level {level!r} (choose {', '.join(DebugServices.LEVELS)})") from None
        logger = logging.getLogger("carapost")
        logger.setLevel(lvl)
        if not logger.handlers:
            logger.addHandler(logging.StreamHandler())

    @staticmethod
    def get_log_level() -> str:
        lvl = logging.getLogger("carapost").getEffectiveLevel()
        for name, v in DebugServices.LEVELS.items():
            if v == lvl:
                return name
        return logging.getLevelName(lvl).lower()
