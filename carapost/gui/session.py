"""The GUI's adapter of the open :class:`~carapost.core.document.Document`.

The project, its history, the selection and the current frame live in the
Document; :class:`Session` turns its listener calls into Qt signals, holds the
few things that are GUI state only (active view, hover, display options,
click mode, the label chosen in the Labelling pane) and runs commands with
error reporting and a log line.
"""
from __future__ import annotations

import logging
from dataclasses import dataclass, fields

from PySide6.QtCore import QObject, Signal

from ..core.commands import Command
from ..core.document import Document, Selection
from ..core.errors import CaraError
from . import live_preview
from .framedata import FrameData, gather
from .imageloader import ImageLoader, open_sources

log = logging.getLogger("carapost")


@dataclass
class DisplayOptions:
    """The views' display switches (the 2D and 3D context menus); shared by every view of a kind."""

    image: bool = True
    border: bool = True
    detections: bool = True
    points: bool = True
    projections: bool = True
    connected: bool = True
    unconnected: bool = True
    errors: bool = True
    blob_preview: bool = False
    pixel_report: bool = False
    sticks: bool = True
    # the 3D view's (its context menu)
    face_points: bool = True
    brim_points: bool = True
    reconstruction_colors: bool = True
    cameras: bool = True
    rays: bool = True
    rom_3d: bool = True
    sticks_3d: bool = True

    @classmethod
    def names(cls) -> list[str]:
        return [f.name for f in fields(cls)]


class Session(QObject):
    """The open document (or none) and the GUI state around it.

    Parameters
    ----------
    loader : ImageLoader, optional
        Image source of the views.
    """

    documentChanged = Signal()
    projectChanged = Signal()
    frameChanged = Signal(int)
    selectionChanged = Signal()
    displayChanged = Signal()
    hoverChanged = Signal()
    modeChanged = Signal(str)
    labelChanged = Signal()
    busyChanged = Signal(bool)
    errorRaised = Signal(str)

    def __init__(self, loader: ImageLoader | None = None, parent=None):
        super().__init__(parent)
        self.doc: Document | None = None
        self.loader = loader or ImageLoader(parent=self)
        self.display = DisplayOptions()
        self.active_sensor = 0
        self.click_mode = ""          #: "", "add" or "edit" (Add/Edit Target Track)
        self.hover = None             #: ("point", id) or ("detection", (s, f, i)) under the mouse
        self.current_label: str | None = None
        self.busy = False
        #: Work recovered from a crashed session that is not saved yet.
        self.recovered = False
        self._frame_data: FrameData | None = None
        self._media_paths: list[str] = []

    # ------------------------------------------------------------------ document
    @property
    def project(self):
        return self.doc.project if self.doc is not None else None

    @property
    def frame(self) -> int:
        return self.doc.current_frame if self.doc is not None else 0

    def set_document(self, doc: Document | None) -> None:
        """Show ``doc`` (None: no project)."""
        if self.doc is not None:
            self.doc.remove_listener(self._on_doc)
        self.doc = doc
        self._frame_data = None
        self.hover = None
        self.current_label = None
        self.click_mode = ""
        self.recovered = False
        self.active_sensor = 0
        if doc is not None:
            doc.add_listener(self._on_doc)
            self._reopen_media()
        else:
            self.loader.set_sources([], [])
            self._media_paths = []
        self.documentChanged.emit()

    def is_modified(self) -> bool:
        """Unsaved changes (including recovered work)."""
        return self.doc is not None and (self.doc.modified or self.recovered)

    def _reopen_media(self) -> None:
        p = self.project
        self._media_paths = [s.media.path for s in p.sensors]
        self.loader.set_sources(open_sources(p), [s.image_offset for s in p.sensors])

    def _on_doc(self, what: str) -> None:
        if what == "project":
            self._frame_data = None
            p = self.project
            if [s.media.path for s in p.sensors] != self._media_paths:
                self._reopen_media()
            else:
                self.loader.set_offsets([s.image_offset for s in p.sensors])
            self._drop_stale_detections()
            self.projectChanged.emit()
        elif what == "frame":
            self._frame_data = None
            self._drop_stale_detections()
            self.frameChanged.emit(self.doc.current_frame)
        elif what == "selection":
            self.selectionChanged.emit()

    def _drop_stale_detections(self) -> None:
        """Selected detections belong to their frame and index: drop those that went away."""
        sel = self.doc.selection
        p = self.project
        keep = [d for d in sel.detections
                if d[1] == self.doc.current_frame and d[2] < p.detections[d[0]].count(d[1])]
        if keep != sel.detections:
            self.doc.set_selection(Selection(list(sel.points), keep, list(sel.sensors), list(sel.sticks)))

    # --------------------------------------------------------------------- data
    def frame_data(self) -> FrameData | None:
        """Every point's samples on the current frame (computed once per frame and edit)."""
        if self.doc is None:
            return None
        if self._frame_data is None or self._frame_data.frame != self.doc.current_frame:
            self._frame_data = gather(self.project, self.doc.current_frame)
        live = live_preview.existing(self)       # a running track's frames (Update 2D View Every Frame)
        return self._frame_data if live is None else live.frame_data(self._frame_data)

    # ----------------------------------------------------------------- commands
    def run(self, command: Command | None) -> bool:
        """Push ``command`` on the history, log what it did and select what it asks; False on error."""
        if command is None or self.doc is None:
            return False
        try:
            self.doc.run(command)
        except CaraError as e:
            self.error(f"{command.name}: {e}")
            return False
        log.info(getattr(command, "summary", "") or command.name)
        after = getattr(command, "select_after", None)
        if after is not None:
            self.doc.set_selection(Selection([i for i in after if i in self.project.points]))
        return True

    def attempt(self, build, *args, **kwargs) -> bool:
        """Build a command with ``build(*args)`` and run it; a CaraError from either is reported."""
        if self.doc is None:
            return False
        try:
            cmd = build(*args, **kwargs)
        except CaraError as e:
            self.error(str(e))
            return False
        return self.run(cmd)

    def error(self, message: str) -> None:
        """Report a failed operation: red in the Log pane and a message box (never a traceback)."""
        log.error(message)
        self.errorRaised.emit(message)

    # ---------------------------------------------------------------- selection
    @property
    def selection(self) -> Selection:
        return self.doc.selection if self.doc is not None else Selection()

    def select(self, points=(), detections=(), add: bool = False, toggle: bool = False) -> None:
        """Select points and detections (``add``: keep the rest; ``toggle``: Ctrl+click)."""
        if self.doc is None:
            return
        old = self.doc.selection
        keep = add or toggle
        pts = list(old.points) if keep else []
        dets = list(old.detections) if keep else []
        for pid in points:
            if toggle and pid in pts:
                pts.remove(pid)
            elif pid not in pts:
                pts.append(pid)
        for d in detections:
            d = tuple(int(v) for v in d)
            if toggle and d in dets:
                dets.remove(d)
            elif d not in dets:
                dets.append(d)
        self.doc.set_selection(Selection(pts, dets, list(old.sensors), list(old.sticks) if keep else []))

    def select_sticks(self, sticks, add: bool = False) -> None:
        """Select sticks (by index); ``add`` keeps the rest of the selection (Ctrl+click)."""
        old = self.selection
        if add:
            self.doc.set_selection(Selection(list(old.points), list(old.detections), list(old.sensors),
                                             list(dict.fromkeys(list(old.sticks) + list(sticks)))))
        else:
            self.doc.set_selection(Selection([], [], list(old.sensors), list(sticks)))

    def set_hover(self, hover) -> None:
        if hover != self.hover:
            self.hover = hover
            self.hoverChanged.emit()

    def set_active_sensor(self, sensor: int) -> None:
        self.active_sensor = int(sensor)

    def set_click_mode(self, mode: str) -> None:
        if mode != self.click_mode:
            self.click_mode = mode
            self.modeChanged.emit(mode)

    def set_current_label(self, label: str | None) -> None:
        if label != self.current_label:
            self.current_label = label
            self.labelChanged.emit()

    def set_display(self, name: str, on: bool) -> None:
        if getattr(self.display, name) != bool(on):
            setattr(self.display, name, bool(on))
            self.displayChanged.emit()

    def set_busy(self, busy: bool) -> None:
        if busy != self.busy:
            self.busy = busy
            self.busyChanged.emit(busy)
