"""Process menu's ROM items and the ROM Tools, and the camera views' ROM display.

Load ROM asks for a ``.cara``; Initialize from ROM [Brim Only] runs
:func:`carapost.core.rom_ops.initialize_from_rom` off the GUI thread (the
progress bar follows it, the result is one undo step).  With the 2D context
menu's ROM switch on, every camera view draws the loaded ROM frame's points
where the ROM cameras (as the ROM Tools aligned them) see them, pale blue; a
plain click on one selects it as the ROM point of Add 2D To ROM
Correspondence (Ctrl+L), whose other half is the selected detection.
Display ROM Timebar opens the ROM take's timebar in a window of its own (:mod:`.rom_timebar`).
"""
from __future__ import annotations

import logging

import numpy as np
from PySide6.QtCore import QEvent, QObject, Qt

from ..core.errors import CaraError
from .overlays import circles, combine, crosses, segments_item
from .prompts import CARA_FILTER
from .rom_timebar import RomTimebar

log = logging.getLogger("carapost")

#: Pale blue of the ROM points (the guide's "light blue ROM marker positions").
ROM_COLOR = (170, 205, 255)
SELECTED_COLOR = (255, 255, 255)
#: Half-size of a drawn ROM point and how near (screen px) a click must be to select one.
ROM_R_PX = 5.0
PICK_PX = 8.0


class RomActions(QObject):
    """Handlers of Process > Load ROM, Initialize from ROM [Brim Only], ROM Tools and the 2D ROM switch."""

    def __init__(self, window):
        super().__init__(window)
        self.w = window
        self.show_rom = False
        self.selected_rom_point: int | None = None
        self._layers: dict[int, tuple] = {}     # id(view) -> (view, ROM layer, selected layer)
        self._timebar: RomTimebar | None = None
        self._data = None          # the ROM projections drawn; None: to compute again
        s = window.session
        for sig in (s.documentChanged, s.projectChanged):
            sig.connect(lambda *_: self.refresh(recompute=True))
        s.documentChanged.connect(self._forget_selection)

    @property
    def s(self):
        return self.w.session

    # ------------------------------------------------------------------ Process menu
    def load_rom(self) -> None:
        """Process > Load ROM: pick a ``.cara`` (its path is saved with the project)."""
        from ..core.rom_ops import load_rom

        p = self.s.project
        path = self.w.prompts.open_file("Load ROM", CARA_FILTER)
        if not path:
            return
        self.w.runner.run(lambda _progress: load_rom(p, path), "Load ROM", cancellable=False)

    def initialize(self, which: str) -> None:
        """Initialize from ROM (``which="full"``) or its [Brim Only] variant (``"brim"``) on the current frame."""
        from ..core.rom_ops import initialize_from_rom, loaded_rom

        p, f = self.s.project, self.s.frame
        brim_only = which == "brim"
        title = "Initialize from ROM" + (" [Brim Only]" if brim_only else "")
        loaded_rom(p)     # no ROM: the error now, in the log and a message box (the guide's "does nothing")

        def job(progress):
            images = self.w.process._images(p)
            try:
                return initialize_from_rom(p, f, brim_only=brim_only, images=images, progress=progress)
            finally:
                if images is not None:
                    images.close()

        self.w.process._run(title, job, cancellable=False)

    # ------------------------------------------------------------------ ROM Tools
    def add_correspondence(self) -> None:
        """Add 2D To ROM Correspondence (Ctrl+L): the selected ROM point is the selected detection."""
        from ..core.rom_ops import add_2d_to_rom_correspondence

        if self.selected_rom_point is None:
            raise CaraError("select a ROM point first: turn on ROM in a camera view's context menu and click a "
                            "pale blue ROM point, then Ctrl+click its detection")
        self.s.attempt(add_2d_to_rom_correspondence, self.s.project, self.selected_rom_point,
                       self.s.selection.detections)

    def clear_correspondences(self) -> None:
        """Clear 2D To ROM Correspondence."""
        from ..core.rom_ops import clear_2d_to_rom_correspondences

        self.s.attempt(clear_2d_to_rom_correspondences, self.s.project)

    def solve_camera(self) -> None:
        """Solve ROM Camera From Correspondences."""
        from ..core.rom_ops import solve_rom_camera_from_correspondences

        self.s.attempt(solve_rom_camera_from_correspondences, self.s.project)

    def solve_face(self) -> None:
        """Solve ROM Face Alignment From Correspondences."""
        from ..core.rom_ops import solve_rom_face_alignment_from_correspondences

        self.s.attempt(solve_rom_face_alignment_from_correspondences, self.s.project, self.s.frame)

    def show_timebar(self) -> None:
        """Display ROM Timebar: the ROM take's frames in a window; the frame chosen is the ROM Frame Index."""
        from ..core.rom_ops import loaded_rom

        state = loaded_rom(self.s.project)
        if self._timebar is None:
            self._timebar = RomTimebar(self.s, self.w)
        self._timebar.set_rom(state)
        self._timebar.show()
        self._timebar.raise_()

    # ------------------------------------------------------------------ 2D display
    def toggle_display(self) -> None:
        """The 2D context menu's ROM switch."""
        self.show_rom = self.w.action("view2d.rom").isChecked()
        self.refresh(recompute=True)

    def select_rom_point(self, pid: int | None) -> None:
        """Make ``pid`` (a ROM point id) the ROM half of the next correspondence."""
        self.selected_rom_point = pid
        if pid is not None:
            log.info(f"ROM point {self._name(pid)} selected: Ctrl+click its detection, then Ctrl+L")
        self.refresh()

    def _name(self, pid: int) -> str:
        from ..core.rom_ops import loaded_rom

        state = loaded_rom(self.s.project, required=False)
        p = state.rom.points.get(pid) if state is not None else None
        return p.name if p is not None else str(pid)

    def _forget_selection(self) -> None:
        self.selected_rom_point = None

    def projections(self) -> dict | None:
        """The ROM frame's points in every channel (None: nothing to draw)."""
        from ..core.rom_ops import rom_projections

        p = self.s.project
        if p is None or not self.show_rom:
            return None
        if self._data is None:
            self._data = rom_projections(p)
        return self._data

    def refresh(self, recompute: bool = False) -> None:
        """Redraw the ROM layer of every camera view (``recompute``: the project or the ROM changed)."""
        if recompute:
            self._data = None
        grid = getattr(self.w, "grid", None)
        if grid is None:
            return
        data = self.projections()
        for view in grid.views:
            rom_layer, sel_layer = self._layer(view)
            rom_layer.clear()
            sel_layer.clear()
            if data is None or view.sensor >= data["uv"].shape[1]:
                continue
            uv = data["uv"][:, view.sensor]
            ok = np.all(np.isfinite(uv), axis=1)
            r = ROM_R_PX * view.pixel_size()
            x, y = uv[ok, 0], uv[ok, 1]
            rom_layer.set_shapes(combine(circles(x, y, r), crosses(x, y, 0.6 * r)))
            sel = ok & (data["ids"] == self.selected_rom_point)
            if sel.any():
                sel_layer.set_shapes(circles(uv[sel, 0], uv[sel, 1], 2 * r))

    def _layer(self, view):
        key = id(view)
        if key not in self._layers:
            rom_layer = segments_item(view.content, ROM_COLOR, 1, z=17)
            sel_layer = segments_item(view.content, SELECTED_COLOR, 2, z=17)
            view.viewport().installEventFilter(self)
            view.vb.sigRangeChanged.connect(lambda *_: self.refresh())
            self._layers[key] = (view, rom_layer, sel_layer)
        return self._layers[key][1:]

    def eventFilter(self, obj, ev) -> bool:  # noqa: N802 - Qt name
        """A plain left click on a drawn ROM point selects it (other clicks go to the view)."""
        if (ev.type() != QEvent.Type.MouseButtonPress or ev.button() != Qt.MouseButton.LeftButton
                or ev.modifiers() != Qt.KeyboardModifier.NoModifier or not self.show_rom):
            return False
        view = next((v for v, *_ in self._layers.values() if v.viewport() is obj), None)
        data = self.projections()
        if view is None or data is None or view.sensor >= data["uv"].shape[1]:
            return False
        q = view.content.mapFromScene(view.mapToScene(ev.position().toPoint()))
        d = np.linalg.norm(data["uv"][:, view.sensor] - (q.x(), q.y()), axis=1)
        d = np.where(np.isfinite(d), d, np.inf)
        if not len(d) or d.min() > PICK_PX * view.pixel_size():
            return False
        self.select_rom_point(int(data["ids"][int(np.argmin(d))]))
        return True
