"""Edit menu handlers: each builds a command with :mod:`carapost.core.editing` and runs it.

The handlers only gather what the user selected (points, detections, the
current frame, the active or selected channels, the label chosen in the
Labelling pane) and ask for names or colours; the work is in the core.
"""
from __future__ import annotations

import logging

from ..core import editing
from ..core.edits import ShiftImageOffset, restore_properties_to_defaults

log = logging.getLogger("carapost")


class EditActions:
    """Handlers of the Edit menu."""

    def __init__(self, window):
        self.w = window

    @property
    def s(self):
        return self.w.session

    def _one_point(self, what: str) -> int | None:
        pts = self.s.selection.points
        if len(pts) != 1:
            self.s.error(f"{what} needs exactly one point selected ({len(pts)} are)")
            return None
        return pts[0]

    # ------------------------------------------------------------- history
    def undo(self) -> None:
        cmd = self.s.doc.undo()
        if cmd is not None:
            log.info(f"Undo {cmd.name}")

    def redo(self) -> None:
        cmd = self.s.doc.redo()
        if cmd is not None:
            log.info(f"Redo {cmd.name}")

    def clear_history(self) -> None:
        mb = self.s.doc.stack.memory_bytes() / 1e6
        self.s.doc.stack.clear()
        log.info(f"Cleared the history ({mb:.1f} MB freed)")

    # ------------------------------------------------------------- points
    def create_points_from_detections(self) -> None:
        self.s.attempt(editing.create_points_from_detections, self.s.project, self.s.selection.detections)

    def delete_selected(self) -> None:
        sel = self.s.selection
        self.s.attempt(editing.delete_selected, self.s.project, sel.points, sel.detections, sel.sticks)

    def split_point(self) -> None:
        pid = self._one_point("Split Selected Point")
        if pid is not None:
            self.s.attempt(editing.split_point, self.s.project, pid, self.s.frame)

    def merge(self) -> None:
        sel = self.s.selection
        self.s.attempt(editing.merge, self.s.project, self.s.frame, sel.points, sel.detections)

    def merge_and_select_next_label(self) -> None:
        """Merge, label the point with the label selected in the Labelling pane, select the next label."""
        ses, p = self.s, self.s.project
        label = ses.current_label
        sel = ses.selection
        if ses.attempt(editing.merge, p, ses.frame, sel.points, sel.detections, label=label,
                       name="Merge and Select Next Label"):
            nxt = editing.next_label(p, label, ses.frame, 1, p.properties["labelling.navigate_missing_labels_only"])
            ses.set_current_label(nxt)

    def clear_selected(self, which: str) -> None:
        f = self.s.frame
        a, b = (f, f) if which == "frame" else self.s.project.active_range
        name = "Clear Selected [Current Frame]" if which == "frame" else "Clear Selected [Active Range]"
        self.s.attempt(editing.clear_selected, self.s.project, self.s.selection.points, a, b, name)

    def detach_detections(self, which: str) -> None:
        p, f = self.s.project, self.s.frame
        a, b = (f, f) if which == "frame" else p.active_range
        name = "Detach Detections [Current Frame]" if which == "frame" else "Detach Detections [Active Range]"
        sensors = p.selected_channels(self.s.active_sensor)
        self.s.attempt(editing.detach_detections, p, self.s.selection.points, sensors, a, b, name)

    def clear_active_range(self) -> None:
        self.s.attempt(editing.clear_active_range, self.s.project)

    def remove_interpolated(self) -> None:
        """Remove Interpolated 3D Points of the selected points (all when none) in the active range."""
        from ..core.errors import CaraError
        from ..core.gapfill_ops import remove_interpolated

        p = self.s.project
        a, b = p.active_range
        ids = list(self.s.selection.points) or None

        def build():
            cmd = remove_interpolated(p, ids, a, b)
            n = sum(len(v["status"]) for _pid, _s, v in cmd.updates)
            if not n:
                raise CaraError(f"Remove Interpolated 3D Points: no interpolated samples in frames {a}-{b}"
                                + (" of the selected points" if ids else ""))
            pts = len({pid for pid, _s, _v in cmd.updates})
            cmd.summary = f"Remove Interpolated 3D Points: {n} samples of {pts} point(s), frames {a}-{b}"
            return cmd

        self.s.attempt(build)

    def remove_unused_detections(self) -> None:
        from ..core.blob_ops import remove_unused_detections

        self.s.attempt(remove_unused_detections, self.s.project)

    # ------------------------------------------------------------- channels
    def increment_image_offset(self) -> None:
        sensors = self.s.project.selected_channels(self.s.active_sensor)
        cmd = ShiftImageOffset(sensors, 1)
        cmd.summary = f"Increment Image Sequence Offset: channel(s) {', '.join(map(str, sensors))}"
        self.s.run(cmd)

    def sensor_click(self, sensor: int, _ctrl: bool = False) -> None:
        """Shift+click in a camera view: toggle its channel in the Selection pane's selection."""
        chans = set(self.s.project.channel_selection)
        chans ^= {sensor}
        self.s.attempt(lambda: editing.SetChannelSelection(chans))

    # ------------------------------------------------------------- target tracks
    def set_click_mode(self, mode: str = "") -> None:
        """Add Target Track (Shift+A), Edit Target Track (Shift+E), Stop Point Edit mode (Shift+S)."""
        if mode == "edit" and self._one_point("Edit Target Track") is None:
            return
        self.s.set_click_mode(mode)
        log.info({"add": "Add Target Track: click in a camera view to place the keyframe",
                  "edit": "Edit Target Track: click in a camera view to place the selected point's keyframe",
                  "": "Point edit mode stopped"}[mode])

    def target_click(self, sensor: int, x: float, y: float) -> None:
        ses = self.s
        if ses.click_mode == "add":
            ses.attempt(editing.add_target_track, ses.project, sensor, ses.frame, (x, y))
        elif ses.click_mode == "edit":
            pid = self._one_point("Edit Target Track")
            if pid is not None:
                ses.attempt(editing.edit_target_track, ses.project, pid, sensor, ses.frame, (x, y))

    # ------------------------------------------------------------- labels
    def rename_point(self) -> None:
        pid = self._one_point("Rename Point")
        if pid is None:
            return
        p = self.s.project
        label = self.w.prompts.get_text("Rename Point", f"Label of point {pid}:", p.point(pid).label, items=p.labels)
        if label is not None:
            self.s.attempt(editing.rename_point, p, pid, label)

    def clear_all_labels(self) -> None:
        self.s.attempt(editing.clear_all_labels, self.s.project)

    def delete_selected_labels(self) -> None:
        self.s.attempt(editing.delete_labels, self.s.project, self.w.labelling.selected_labels())

    def unlabel(self) -> None:
        self.s.attempt(editing.unlabel, self.s.project, self.s.selection.points)

    # ------------------------------------------------------------- sticks
    def create_stick(self) -> None:
        self.s.attempt(editing.create_stick, self.s.project, self.s.selection.points)

    def create_stick_mesh(self) -> None:
        self.s.attempt(editing.create_stick_mesh, self.s.project, self.s.frame)

    def edit_stick_color(self) -> None:
        p = self.s.project
        if not p.sticks:
            self.s.error("Edit Stick Color: the take has no sticks")
            return
        which = self.s.selection.sticks
        start = p.sticks[which[0] if which else 0].color
        color = self.w.prompts.get_color("Edit Stick Color", start)
        if color is not None:
            self.s.attempt(editing.set_stick_color, p, which, color)

    # ------------------------------------------------------------- properties
    def restore_defaults(self) -> None:
        cmd = restore_properties_to_defaults()
        cmd.summary = "Restore Properties To Defaults"
        self.s.run(cmd)

    def read_blob_parameters(self) -> None:
        from ..core.blob_ops import read_blob_parameters_from_pico

        self.s.attempt(read_blob_parameters_from_pico, self.s.project)
