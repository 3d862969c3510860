"""The basic edit commands of the take model.

Each stores only what it changes.  Algorithms compute results as arrays; a
command from here applies them, so every operation is undoable the same way.
"""
from __future__ import annotations

import copy
from typing import Any

import numpy as np

from .brim import Brim
from .commands import Command
from .errors import CaraError
from .points import POINT_FIELDS, Point
from .properties import PROPERTY_TABLE, property_def
from .rig import CameraRig
from .project import Project, Stick


# ------------------------------------------------------------------ properties
class SetProperties(Command):
    """Set one or more properties (validated before anything changes)."""

    def __init__(self, values: dict[str, Any], name: str | None = None):
        self.new = {k: property_def(k).coerce(v) for k, v in values.items()}
        self.old: dict[str, Any] = {}
        if name is None:
            name = ("Set " + property_def(next(iter(self.new))).title) if len(self.new) == 1 else "Set Properties"
        self.name = name

    def do(self, project: Project) -> None:
        self.old = {k: project.properties[k] for k in self.new}
        for k, v in self.new.items():
            project.properties.set(k, v)

    def undo(self, project: Project) -> None:
        for k, v in self.old.items():
            project.properties.set(k, v)


def restore_properties_to_defaults() -> SetProperties:
    """Edit > Restore Properties To Defaults, as one undoable command."""
    return SetProperties({p.key: p.default for p in PROPERTY_TABLE}, name="Restore Properties To Defaults")


# ---------------------------------------------------------------------- points
class AddPoints(Command):
    """Add points (built with ``Project.new_point`` and filled by the caller)."""

    def __init__(self, points: list[Point], name: str = "Add Points"):
        self.points = list(points)
        self.name = name
        self._old_next = 0

    def do(self, project: Project) -> None:
        self._old_next = project.next_point_id
        for p in self.points:
            project.add_point(p)

    def undo(self, project: Project) -> None:
        for p in self.points:
            del project.points[p.id]
        project.next_point_id = self._old_next


class DeletePoints(Command):
    """Delete points for the whole take (and the sticks that use them)."""

    name = "Delete Points"

    def __init__(self, ids: list[int], name: str = "Delete Selected"):
        self.ids = list(dict.fromkeys(ids))
        self.name = name
        self._order: list[int] = []
        self._removed: dict[int, Point] = {}
        self._sticks: list[Stick] = []

    def do(self, project: Project) -> None:
        for pid in self.ids:
            project.point(pid)  # fail before changing anything
        self._order = list(project.points)
        self._removed = {pid: project.points.pop(pid) for pid in self.ids}
        self._sticks = list(project.sticks)
        gone = set(self.ids)
        project.sticks = [s for s in project.sticks if s.a not in gone and s.b not in gone]

    def undo(self, project: Project) -> None:
        current = project.points
        project.points = {pid: (self._removed[pid] if pid in self._removed else current[pid])
                          for pid in self._order if pid in self._removed or pid in current}
        project.sticks = self._sticks


class SetPointData(Command):
    """Write computed per-frame values into points.

    Parameters
    ----------
    updates : list of (point id, start frame, {field: array})
        Each array covers frames ``start .. start + len - 1`` of that field
        (``pos``, ``status``, ``residual``, ``src``, ``det``, ``uv``, ``score``).
    """

    def __init__(self, updates: list[tuple[int, int, dict[str, np.ndarray]]], name: str = "Edit Points"):
        for _pid, _start, values in updates:
            for k in values:
                if k not in POINT_FIELDS:
                    raise CaraError(f"unknown point field {k!r}")
        self.updates = updates
        self.name = name
        self._old: list[tuple[int, int, dict[str, np.ndarray]]] = []

    def do(self, project: Project) -> None:
        self._old = []
        for pid, start, values in self.updates:
            p = project.point(pid)
            saved = {k: p.arrays[k][start:start + len(v)].copy() for k, v in values.items()}
            self._old.append((pid, start, saved))
            for k, v in values.items():
                p.arrays[k][start:start + len(v)] = v

    def undo(self, project: Project) -> None:
        for pid, start, saved in reversed(self._old):
            project.points[pid].restore_slice(start, saved)


class ClearPointRange(Command):
    """Remove 3D (and 2D) data of points on an inclusive frame range.

    With ``sensors`` given, only those sensors' 2D data is detached (Detach
    Detections); otherwise everything goes (Clear Selected, Clear Active Range).
    """

    def __init__(self, ids: list[int], start: int, end: int, sensors: list[int] | None = None,
                 name: str = "Clear Selected"):
        self.ids = list(ids)
        self.start, self.stop = int(start), int(end) + 1
        self.sensors = None if sensors is None else list(sensors)
        self.name = name
        self._old: list[tuple[int, dict[str, np.ndarray]]] = []

    def do(self, project: Project) -> None:
        project.check_range(self.start, self.stop - 1)
        self._old = []
        fields = None if self.sensors is None else ("src", "det", "uv", "score")
        for pid in self.ids:
            p = project.point(pid)
            saved = p.slice_copy(self.start, self.stop)
            if fields:
                saved = {k: saved[k] for k in fields}
            self._old.append((pid, saved))
            p.clear_range(self.start, self.stop, self.sensors)

    def undo(self, project: Project) -> None:
        for pid, saved in reversed(self._old):
            project.points[pid].restore_slice(self.start, saved)


class RenamePoint(Command):
    """Give a point a label (``""`` unlabels); a new label joins the label list."""

    def __init__(self, pid: int, label: str, name: str = "Rename Point"):
        label = label.strip()
        self.pid = pid
        self.label = label
        self.name = name
        self._old_label = ""
        self._old_labels: list[str] = []
        self._other: int | None = None

    def do(self, project: Project) -> None:
        p = project.point(self.pid)
        self._old_label = p.label
        self._old_labels = list(project.labels)
        # One label names one point: the previous holder loses it, as in the Labelling pane.
        other = project.point_by_label(self.label) if self.label else None
        self._other = other.id if other is not None and other.id != self.pid else None
        if self._other is not None:
            project.points[self._other].label = ""
        p.label = self.label
        if self.label and self.label not in project.labels:
            project.labels.append(self.label)

    def undo(self, project: Project) -> None:
        project.points[self.pid].label = self._old_label
        if self._other is not None:
            project.points[self._other].label = self.label
        project.labels = self._old_labels


class Unlabel(Command):
    """Remove the labels of points (Unlabel Selected Points)."""

    def __init__(self, ids: list[int], name: str = "Unlabel Selected Points"):
        self.ids = list(ids)
        self.name = name
        self._old: dict[int, str] = {}

    def do(self, project: Project) -> None:
        self._old = {pid: project.point(pid).label for pid in self.ids}
        for pid in self.ids:
            project.points[pid].label = ""

    def undo(self, project: Project) -> None:
        for pid, lab in self._old.items():
            project.points[pid].label = lab


class SetLabels(Command):
    """Replace the label list; points whose label leaves the list are unlabelled."""

    def __init__(self, labels: list[str], name: str = "Edit Labels"):
        self.labels = list(labels)
        self.name = name
        self._old_labels: list[str] = []
        self._unlabelled: dict[int, str] = {}

    def do(self, project: Project) -> None:
        self._old_labels = list(project.labels)
        keep = set(self.labels)
        self._unlabelled = {p.id: p.label for p in project.points.values() if p.label and p.label not in keep}
        for pid in self._unlabelled:
            project.points[pid].label = ""
        project.labels = list(self.labels)

    def undo(self, project: Project) -> None:
        project.labels = self._old_labels
        for pid, lab in self._unlabelled.items():
            project.points[pid].label = lab


# ------------------------------------------------------------------ detections
class SetFrameDetections(Command):
    """Replace the detections of some (sensor, frame) cells."""

    def __init__(self, cells: dict[tuple[int, int], np.ndarray], name: str = "Set Detections"):
        self.cells = cells
        self.name = name
        self._old: dict[tuple[int, int], tuple[np.ndarray, bool]] = {}

    def do(self, project: Project) -> None:
        self._old = {}
        for (s, f), rec in self.cells.items():
            table = project.detections[s]
            self._old[(s, f)] = (table.frame(f).copy(), bool(table.detected[f]))
            table.set_frame(f, rec)

    def undo(self, project: Project) -> None:
        for (s, f), (rec, detected) in self._old.items():
            project.detections[s].set_frame(f, rec, detected)


# ------------------------------------------------------------- take structure
class SetRange(Command):
    """Set the active range (``"active"``) or the view range (``"view"``), inclusive."""

    def __init__(self, which: str, start: int, end: int, name: str | None = None):
        if which not in ("active", "view"):
            raise CaraError(f"unknown range {which!r}")
        self.which = which
        self.start, self.end = int(start), int(end)
        self.name = name or f"Set {which.capitalize()} Range"
        self._old: tuple[int, int] = (0, 0)

    def do(self, project: Project) -> None:
        project.check_range(self.start, self.end)
        attr = f"{self.which}_range"
        self._old = getattr(project, attr)
        setattr(project, attr, (self.start, self.end))

    def undo(self, project: Project) -> None:
        setattr(project, f"{self.which}_range", self._old)


class RotateSensors(Command):
    """Rotate sensors' displayed video by 90-degree steps (positive: clockwise)."""

    def __init__(self, sensors: list[int], steps: int):
        self.sensors = list(sensors)
        self.steps = int(steps)
        self.name = "Rotate Selected Sensors " + ("Clockwise" if steps > 0 else "Anticlockwise")

    def do(self, project: Project) -> None:
        for s in self.sensors:
            project.sensors[s].rotation = (project.sensors[s].rotation + self.steps) % 4

    def undo(self, project: Project) -> None:
        for s in self.sensors:
            project.sensors[s].rotation = (project.sensors[s].rotation - self.steps) % 4


class ShiftImageOffset(Command):
    """Increment Image Sequence Offset: move sensors' video ``delta`` frames forward."""

    def __init__(self, sensors: list[int], delta: int = 1):
        self.sensors = list(sensors)
        self.delta = int(delta)
        self.name = "Increment Image Sequence Offset"

    def do(self, project: Project) -> None:
        for s in self.sensors:
            project.sensors[s].image_offset += self.delta

    def undo(self, project: Project) -> None:
        for s in self.sensors:
            project.sensors[s].image_offset -= self.delta


class SetRig(Command):
    """Replace the cameras (Import XCP)."""

    def __init__(self, rig: CameraRig | None, name: str = "Import XCP"):
        self.rig = rig
        self.name = name
        self._old: CameraRig | None = None

    def do(self, project: Project) -> None:
        if self.rig is not None and self.rig.sensors != project.sensor_count:
            raise CaraError(f"the calibration has {self.rig.sensors} cameras, the take {project.sensor_count} sensors")
        self._old = project.rig
        project.rig = self.rig

    def undo(self, project: Project) -> None:
        project.rig = self._old


class SetCameraPoses(Command):
    """Write solved camera poses on an inclusive frame range (brim solve, bundle)."""

    def __init__(self, start: int, quat: np.ndarray, position: np.ndarray, solved: np.ndarray,
                 name: str = "Solve Cameras"):
        self.start = int(start)
        self.values = (np.asarray(quat, float), np.asarray(position, float), np.asarray(solved, bool))
        self.name = name
        self._old = None

    def do(self, project: Project) -> None:
        if project.rig is None:
            raise CaraError("no camera calibration is loaded (File > Import XCP)")
        n = self.values[0].shape[1]
        self._old = project.rig.slice_copy(self.start, self.start + n)
        project.rig.restore_slice(self.start, self.values)

    def undo(self, project: Project) -> None:
        project.rig.restore_slice(self.start, self._old)


class SetBrim(Command):
    """Set the calibration brim (Initialize Default Calibration Brim, Import Calibration Brim)."""

    def __init__(self, brim: Brim | None, name: str = "Set Calibration Brim"):
        self.brim = brim
        self.name = name
        self._old: Brim | None = None

    def do(self, project: Project) -> None:
        self._old = project.brim
        project.brim = self.brim

    def undo(self, project: Project) -> None:
        project.brim = self._old


class SetSticks(Command):
    """Replace the stick list (create, delete, recolour)."""

    def __init__(self, sticks: list[Stick], name: str = "Edit Sticks"):
        self.sticks = [copy.copy(s) for s in sticks]
        self.name = name
        self._old: list[Stick] = []

    def do(self, project: Project) -> None:
        for s in self.sticks:
            project.point(s.a)
            project.point(s.b)
        self._old = project.sticks
        project.sticks = [copy.copy(s) for s in self.sticks]

    def undo(self, project: Project) -> None:
        project.sticks = self._old


class SetAttribute(Command):
    """Set a plain project attribute (``rom_path``, ``name``, ``frame_rate``...)."""

    _ALLOWED = ("rom_path", "name", "frame_rate", "timecode_start", "pico_blob_parameters")

    def __init__(self, attr: str, value: Any, name: str | None = None):
        if attr not in self._ALLOWED:
            raise CaraError(f"{attr} cannot be set this way")
        self.attr, self.value = attr, value
        self.name = name or f"Set {attr}"
        self._old: Any = None

    def do(self, project: Project) -> None:
        self._old = getattr(project, self.attr)
        setattr(project, self.attr, copy.deepcopy(self.value))

    def undo(self, project: Project) -> None:
        setattr(project, self.attr, self._old)


class SetMedia(Command):
    """Point a sensor at other media (File > Relocate Files)."""

    def __init__(self, sensor: int, media, frame_count: int | None = None, name: str = "Relocate Files"):
        self.sensor = int(sensor)
        self.media = copy.copy(media)
        self.frame_count = frame_count
        self.name = name
        self._old = None

    def do(self, project: Project) -> None:
        s = project.sensors[self.sensor]
        self._old = (copy.copy(s.media), s.frame_count)
        s.media = copy.copy(self.media)
        if self.frame_count is not None:
            s.frame_count = int(self.frame_count)

    def undo(self, project: Project) -> None:
        s = project.sensors[self.sensor]
        s.media, s.frame_count = self._old
