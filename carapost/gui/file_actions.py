"""File menu handlers (and Edit > Relocate Files): open, save, import, recent files, exit.

Opening replaces the window's Document; saving runs in the background (a
ten-minute take is hundreds of megabytes) with edits blocked meanwhile; every
path that would lose unsaved changes asks first.
"""
from __future__ import annotations

import logging
from pathlib import Path

from PySide6.QtCore import QCoreApplication, QEventLoop

from ..core.commands import CompoundCommand
from ..core.document import Document
from ..core.errors import CaraError
from . import settings as st
from .prompts import CARA_FILTER

log = logging.getLogger("carapost")

PICO_FILTER = "Pico files (*.pico);;All files (*)"
XCP_FILTER = "Calibration files (*.xcp);;All files (*)"
TEXT_FILTER = "Label text files (*.txt);;All files (*)"
SVG_FILTER = "Calibration brim (*.svg);;All files (*)"
C3D_FILTER = "C3D files (*.c3d)"
FBX_FILTER = "FBX files (*.fbx)"
XCP_SAVE_FILTER = "Calibration files (*.xcp)"


def load_any(path: str | Path):
    """A project from a ``.cara`` file, or a new one from a ``.pico`` take (all its channels)."""
    p = Path(path)
    if p.suffix.lower() == ".pico":
        try:
            from ..io.take import project_from_pico
        except ImportError:   # the media modules are not in this build
            raise CaraError("reading .pico files is not available in this build", p) from None
        return project_from_pico(p)
    from ..io.cara import load_project

    return load_project(p)


class FileActions:
    """Handlers of the File menu."""

    def __init__(self, window):
        self.w = window

    @property
    def session(self):
        return self.w.session

    # ------------------------------------------------------------ recent files
    def recent_files(self) -> list[str]:
        return st.recent_files(self.w.settings)

    def clear_recent(self) -> None:
        st.clear_recent(self.w.settings)
        self.w.actionset.update()
        log.info("Cleared the recent files")

    # ------------------------------------------------------------ documents
    def maybe_save(self) -> bool:
        """Before losing unsaved changes: save, discard or cancel.  True to go on."""
        ses = self.session
        if not ses.is_modified():
            return True
        name = Path(ses.project.path).name if ses.project.path else (ses.project.name or "The project")
        answer = self.w.prompts.save_discard_cancel("Unsaved changes", f"{name} has unsaved changes. Save them?")
        if answer == "save":
            return self.save(wait=True)
        return answer == "discard"

    def show_document(self, doc: Document | None) -> None:
        """Make ``doc`` the window's document (None: no project)."""
        self.w.navigate.stop()
        self.session.set_document(doc)
        self.w.recovery.discard_own()
        self.w.update_title()
        self.w.actionset.update()

    def open(self) -> None:
        """File > Open (Ctrl+O)."""
        if not self.maybe_save():
            return
        recent = self.recent_files()
        path = self.w.prompts.open_file("Open", CARA_FILTER, str(Path(recent[0]).parent) if recent else "")
        if path:
            self.open_path(path)

    def open_path(self, path: str, ask: bool = False) -> bool:
        """Open a ``.cara`` project (or a ``.pico`` take); False on error (reported)."""
        if ask and not self.maybe_save():
            return False
        try:
            project = load_any(path)
        except CaraError as e:
            self.session.error(f"Open: {e}")
            return False
        self.show_document(Document(project))
        if Path(path).suffix.lower() == ".cara":
            st.add_recent(self.w.settings, path)
            self.w.actionset.fill_recent()
        log.info(f"Opened {path}: {project.frame_count} frames, {project.sensor_count} sensors, "
                 f"{len(project.points)} points")
        return True

    def clear(self) -> None:
        """File > Clear: close the project."""
        if self.maybe_save():
            self.show_document(None)
            log.info("Cleared the project")

    def save(self, wait: bool = False) -> bool:
        """File > Save (Ctrl+S); asks for a name when the project has none."""
        p = self.session.project
        if p is None:
            return False
        if not p.path or Path(p.path).suffix.lower() != ".cara":
            return self.save_as(wait)
        return self._save_to(p.path, wait)

    def save_as(self, wait: bool = False) -> bool:
        """File > Save As."""
        p = self.session.project
        if p is None:
            return False
        suggested = p.path if p.path.endswith(".cara") else (p.name or "untitled") + ".cara"
        path = self.w.prompts.save_file("Save As", CARA_FILTER, suggested)
        return self._save_to(path, wait) if path else False

    def _save_to(self, path: str, wait: bool) -> bool:
        from ..io.cara import save_project

        runner = self.w.runner
        if runner.running:               # an autosave: let it finish first
            self.wait_for_background()
        doc, project = self.session.doc, self.session.project
        result = {"ok": False}

        def work(_progress):
            save_project(project, path)

        def done(_r):
            result["ok"] = True
            doc.stack.mark_clean()
            self.session.recovered = False
            st.add_recent(self.w.settings, path)
            self.w.actionset.fill_recent()
            self.w.recovery.discard_own()
            self.w.update_title()
            log.info(f"Saved {path}")

        if not runner.run(work, f"Save {Path(path).name}", on_done=done, cancellable=False, quiet=True):
            return False
        if wait:
            self.wait_for_background()
            return result["ok"]
        return True

    def wait_for_background(self) -> None:
        """Block (processing events) until the background job finished."""
        while self.w.runner.running:
            self.w.runner.wait(50)
            QCoreApplication.processEvents(QEventLoop.ProcessEventsFlag.AllEvents, 50)

    def exit(self) -> None:
        """File > Exit."""
        self.w.close()

    # ------------------------------------------------------------ imports
    def import_pico(self) -> None:
        """File > Import Pico Files: a new project from a take's channel files."""
        from ..io.media import group_takes
        from ..io.take import project_from_sources

        if not self.maybe_save():
            return
        paths = self.w.prompts.open_files("Import Pico Files", PICO_FILTER)
        if not paths:
            return
        takes = group_takes(paths)
        name = next(iter(takes))
        if len(takes) > 1:
            name = self.w.prompts.get_item("Import Pico Files", "The files hold several takes. Import:", list(takes))
            if name is None:
                return
        try:
            project = project_from_sources(takes[name], name=Path(name).name)
        except CaraError as e:
            self.session.error(f"Import Pico Files: {e}")
            return
        self.show_document(Document(project))
        log.info(f"Imported take {name}: {project.sensor_count} channels, {project.frame_count} frames")

    def import_xcp(self) -> None:
        """File > Import XCP."""
        from ..io.imports import import_xcp

        path = self.w.prompts.open_file("Import XCP", XCP_FILTER)
        if path:
            self.session.attempt(import_xcp, self.session.project, path, log)

    def import_labels_cara(self) -> None:
        """File > Import Labels From Cara File."""
        from ..io.imports import import_labels_from_cara

        path = self.w.prompts.open_file("Import Labels From Cara File", CARA_FILTER)
        if path:
            self.session.attempt(import_labels_from_cara, self.session.project, path)

    def import_labels_text(self) -> None:
        """File > Import Labels From Text File (names already present get `` - Copy``)."""
        from ..io.imports import import_labels_from_text

        path = self.w.prompts.open_file("Import Labels From Text File", TEXT_FILTER)
        if path:
            self.session.attempt(import_labels_from_text, self.session.project, path)

    def import_brim_svg(self) -> None:
        """File > Import Calibration Brim [svg]."""
        from ..core.edits import SetBrim
        from ..io.brim_svg import read_brim_svg

        path = self.w.prompts.open_file("Import Calibration Brim [svg]", SVG_FILTER)
        if path:
            self.session.attempt(lambda: SetBrim(read_brim_svg(path), name="Import Calibration Brim [svg]"))

    def _export_path(self, title: str, file_filter: str, suffix: str) -> str | None:
        p = self.session.project
        base = Path(p.path).with_suffix(suffix) if p.path else Path((p.name or "take") + suffix)
        path = self.w.prompts.save_file(title, file_filter, str(base))
        if path and not path.lower().endswith(suffix):
            path += suffix
        return path

    def _export_in_background(self, title: str, file_filter: str, suffix: str, writer) -> None:
        """Ask for the file, then run ``writer(project, path)`` off the GUI thread (a long take writes for a while)."""
        project = self.session.project
        path = self._export_path(title, file_filter, suffix)
        if path:
            self.w.runner.run(lambda _progress: writer(project, path), f"{title} {Path(path).name}",
                              cancellable=False)

    def export_c3d(self) -> None:
        """File > Export C3D."""
        from ..io.export_c3d import export_c3d

        self._export_in_background("Export C3D", C3D_FILTER, ".c3d", export_c3d)

    def export_fbx(self) -> None:
        """File > Export FBX."""
        from ..io.export_fbx import write_fbx

        self._export_in_background("Export FBX", FBX_FILTER, ".fbx", write_fbx)

    def export_xcp(self) -> None:
        """File > Export XCP [Current Frame]."""
        from ..io.export_xcp import export_xcp

        path = self._export_path("Export XCP [Current Frame]", XCP_SAVE_FILTER, ".xcp")
        if path:
            try:
                export_xcp(self.session.project, path, self.session.frame)
            except CaraError as e:
                self.session.error(f"Export XCP: {e}")
                return
            log.info(f"Exported the cameras of frame {self.session.frame} to {path}")

    def relocate(self) -> None:
        """Edit > Relocate Files: new media per channel, as one undoable command."""
        from ..core.edits import SetMedia
        from ..core.project import MediaRef
        from ..io.media import open_source

        p = self.session.project
        changes = self.w.prompts.relocate(p)
        if not changes:
            return
        cmds = []
        for sensor, path in sorted(changes.items()):
            try:
                with open_source(path) as src:
                    ref = MediaRef(str(Path(path).absolute()), kind=src.kind)
                    frames = src.frame_count
            except CaraError as e:
                self.session.error(f"Relocate Files: channel {sensor}: {e}")
                return
            cmds.append(SetMedia(sensor, ref, frames))
        cmd = CompoundCommand("Relocate Files", cmds)
        cmd.summary = f"Relocate Files: channel(s) {', '.join(str(s) for s in sorted(changes))}"
        self.session.run(cmd)
