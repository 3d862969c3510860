"""Autosave and crash recovery.

While a project has unsaved changes, it is saved every few minutes (atomic
save, in the background) to ``<data dir>/recovery/session-<pid>.cara`` with a
``.json`` note of where it came from.  A clean exit removes both.  At start-up
the notes of sessions whose process is gone are offered back: the work of a
killed session is one click away.
"""
from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path

from PySide6.QtCore import QObject, QTimer

from ..core.document import Document
from ..core.errors import CaraError
from .settings import data_dir

log = logging.getLogger("carapost")

DEFAULT_INTERVAL_S = 120


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:       # exists, owned by someone else
        return True
    except OSError:
        return False
    return True


class Recovery(QObject):
    """Autosaves the window's project and offers crashed sessions' work back.

    Parameters
    ----------
    window : MainWindow
    interval_s : float, optional
        Seconds between autosaves (default: the ``autosave/interval_s`` setting, 120).
    """

    def __init__(self, window, interval_s: float | None = None):
        super().__init__(window)
        self.window = window
        self.folder = data_dir() / "recovery"
        self.path = self.folder / f"session-{os.getpid()}.cara"
        self.note = self.path.with_suffix(".json")
        self._saved_state = None          # (document, history index, history length) last autosaved
        self._adopted: list[Path] = []    # recovered files still memory-mapped: removed at exit
        if interval_s is None:
            interval_s = float(window.settings.value("autosave/interval_s", DEFAULT_INTERVAL_S))
        self.timer = QTimer(self)
        self.timer.setInterval(int(interval_s * 1000))
        self.timer.timeout.connect(self.tick)
        if interval_s > 0:
            self.timer.start()

    # ------------------------------------------------------------- autosave
    def _state(self):
        doc = self.window.session.doc
        return None if doc is None else (id(doc), doc.stack.index, len(doc.stack))

    def tick(self) -> None:
        """Autosave when there are changes since the last one and nothing else runs."""
        ses = self.window.session
        if ses.doc is None or ses.busy or not ses.is_modified() or self._state() == self._saved_state:
            return
        self.autosave()

    def autosave(self) -> bool:
        """Save the project to the recovery file in the background; False when it could not start."""
        from ..io.cara import save_project

        ses = self.window.session
        project = ses.project
        if project is None:
            return False
        state = self._state()
        self.folder.mkdir(parents=True, exist_ok=True)
        target, note = self.path, self.note
        meta = {"pid": os.getpid(), "original": project.path, "name": project.name,
                "saved_at": time.strftime("%Y-%m-%d %H:%M:%S")}

        def work(_progress):
            original = project.path
            try:
                save_project(project, target)
            finally:
                project.path = original       # the project still belongs where it was
            tmp = note.with_suffix(".json.tmp")
            tmp.write_text(json.dumps(meta))
            os.replace(tmp, note)

        def done(_result):
            self._saved_state = state
            log.info(f"Autosaved to {target}")

        return self.window.runner.run(work, "Autosave", on_done=done, cancellable=False, quiet=True)

    def discard_own(self) -> None:
        """Remove this session's recovery files (after a save, or at a clean exit)."""
        for p in (self.note, self.path):
            p.unlink(missing_ok=True)
        self._saved_state = None

    def clean_exit(self) -> None:
        """The window closes normally: nothing is left to recover."""
        self.timer.stop()
        self.discard_own()
        for p in self._adopted:
            p.unlink(missing_ok=True)
        self._adopted.clear()

    # ------------------------------------------------------------- recovery
    def orphans(self) -> list[tuple[Path, dict]]:
        """Recovery files of sessions whose process is gone, newest first."""
        out = []
        if not self.folder.is_dir():
            return out
        for note in self.folder.glob("session-*.json"):
            try:
                meta = json.loads(note.read_text())
                pid = int(meta.get("pid", -1))
            except (OSError, ValueError):
                continue
            cara = note.with_suffix(".cara")
            if pid == os.getpid() or _alive(pid) or not cara.exists():
                continue
            out.append((cara, meta))
        # a killed session's data file without its note cannot be offered: remove it
        for cara in self.folder.glob("session-*.cara"):
            pid = cara.stem.split("-")[-1]
            if not cara.with_suffix(".json").exists() and pid.isdigit() and not _alive(int(pid)) \
                    and int(pid) != os.getpid():
                cara.unlink(missing_ok=True)
        return sorted(out, key=lambda t: t[1].get("saved_at", ""), reverse=True)

    def offer(self) -> bool:
        """Ask whether to recover each crashed session's work; True when one was opened."""
        from ..io.cara import load_project

        for cara, meta in self.orphans():
            what = meta.get("original") or meta.get("name") or "an unsaved project"
            if self.window.session.doc is not None and self.window.session.is_modified():
                break    # do not replace work in progress; offered again next start
            if not self.window.prompts.confirm(
                    "Recover unsaved work",
                    f"carapost was closed without saving {what} (autosaved {meta.get('saved_at', '?')}).\n"
                    "Recover it? (No discards it.)"):
                cara.unlink(missing_ok=True)
                cara.with_suffix(".json").unlink(missing_ok=True)
                log.info(f"Discarded the recovery file of {what}")
                continue
            try:
                project = load_project(cara)
            except CaraError as e:
                self.window.session.error(f"cannot recover {what}: {e}")
                continue
            project.path = meta.get("original", "")
            cara.with_suffix(".json").unlink(missing_ok=True)   # offered once; the data stays mapped
            self._adopted.append(cara)
            self.window.files.show_document(Document(project))
            self.window.session.recovered = True
            self.window.update_title()
            log.warning(f"Recovered the unsaved work of {what} (autosaved {meta.get('saved_at', '?')}); "
                        "save it to keep it")
            return True
        return False
