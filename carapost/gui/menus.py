"""QActions and the menu bar, built from the action registry (:mod:`carapost.core.actions`).

One QAction per registry entry, shared by the menu bar, the 2D context menu,
the pane buttons and the play controls.  Handlers are resolved on the window
(``"edit.merge"`` -> ``window.edit.merge``); enabled states follow the
registry's ``available`` flag and ``enabled_when`` condition, and edits are
disabled while a background job runs.
"""
from __future__ import annotations

import importlib.util
import logging
from dataclasses import replace

from PySide6.QtCore import Qt
from PySide6.QtGui import QAction, QKeySequence
from PySide6.QtWidgets import QMenu, QMenuBar

from ..core.actions import ACTIONS, CONTEXT_MENUS, MENUS, Action, menu_actions, mnemonic_titles

log = logging.getLogger("carapost")

#: Held down, these repeat (Next/Prev Frame act like play).
AUTO_REPEAT = {"view.next_frame", "view.prev_frame", "view.next_keyframe", "view.prev_keyframe"}


def _media_available() -> bool:
    return importlib.util.find_spec("carapost.io.take") is not None


class ActionSet:
    """Every QAction of the window.

    Parameters
    ----------
    window : MainWindow
        Owns the actions and resolves the handlers.
    """

    def __init__(self, window):
        self.window = window
        self.actions: dict[str, QAction] = {}
        self.spec: dict[str, Action] = {}
        self.recent_menu: QMenu | None = None
        self.panels_menu: QMenu | None = None
        for a in ACTIONS:
            a = self._adjust(a)
            qa = QAction(a.title, window)
            if a.shortcut:
                qa.setShortcut(QKeySequence(a.shortcut))
                qa.setShortcutContext(Qt.ShortcutContext.WindowShortcut)
            qa.setAutoRepeat(a.id in AUTO_REPEAT)
            qa.setCheckable(a.checkable)
            qa.setToolTip(a.tooltip)
            qa.setStatusTip(a.tooltip)
            qa.setObjectName(a.id)
            qa.triggered.connect(lambda _checked=False, a=a: self.trigger(a))
            if a.menu not in CONTEXT_MENUS:
                window.addAction(qa)   # shortcuts work with the menu bar hidden (full screen)
            self.actions[a.id] = qa
            self.spec[a.id] = a
        self.update()

    @staticmethod
    def _adjust(a: Action) -> Action:
        """Disable Import Pico Files when the media module is not in this build."""
        if a.id == "file.import_pico" and not _media_available():
            return replace(a, available=False, handler="",
                           tooltip="Not available yet: reading .pico files lands with issue 3.")
        return a

    # -------------------------------------------------------------- running
    def trigger(self, a: Action) -> None:
        """Run the handler of ``a`` (errors end up in the log and a message box, never a traceback)."""
        from ..core.errors import CaraError

        if not a.available or not a.handler:
            log.warning(a.tooltip)
            return
        owner, method = a.handler.split(".", 1)
        fn = getattr(getattr(self.window, owner), method)
        try:
            fn(a.arg) if a.arg else fn()
        except CaraError as e:
            self.window.session.error(f"{a.title}: {e}")

    # -------------------------------------------------------------- state
    def condition(self, name: str) -> bool:
        ses = self.window.session
        doc = ses.doc
        p = ses.project
        if name == "always":
            return True
        if name == "recent":
            return bool(self.window.files.recent_files())
        if doc is None:
            return False
        return {
            "project": True,
            "undo": doc.stack.can_undo(),
            "redo": doc.stack.can_redo(),
            "history": len(doc.stack) > 0,
            "brim": p.brim is not None and len(p.brim) > 0,
        }[name]

    def update(self) -> None:
        """Enable what can run now; Undo/Redo tooltips name the entry."""
        busy = self.window.session.busy
        for aid, qa in self.actions.items():
            a = self.spec[aid]
            qa.setEnabled(a.available and (a.while_busy or not busy) and self.condition(a.enabled_when))
        doc = self.window.session.doc
        if doc is not None:
            self.actions["edit.undo"].setToolTip(f"Undo {doc.stack.undo_name()}".strip())
            self.actions["edit.redo"].setToolTip(f"Redo {doc.stack.redo_name()}".strip())
        self.sync_checks()

    def sync_checks(self) -> None:
        """Checkable actions show the state they toggle (the model is the truth)."""
        w = self.window
        d = w.session.display
        p = w.session.project
        labels_all = bool(p is not None and p.properties["display.point_labels_all"])
        for aid, a in self.spec.items():
            if a.handler == "views.toggle_display":
                self._check(aid, getattr(d, a.arg))
            elif a.handler == "views.toggle_labels_all":
                self._check(aid, labels_all)
        self._check("view.full_screen", w.isFullScreen())
        self._check("view.lock_to_point", w.views.locked)
        self._check("view.play", w.navigate.playing)

    def _check(self, aid: str, on: bool) -> None:
        qa = self.actions[aid]
        if qa.isChecked() != on:
            qa.blockSignals(True)
            qa.setChecked(on)
            qa.blockSignals(False)
            qa.toggled.emit(on)   # widgets showing the state (Play button text) follow

    # -------------------------------------------------------------- menus
    def build_menubar(self, bar: QMenuBar, docks: list) -> None:
        """File, Edit, View, Process, Help with their submenus, mnemonics and tooltips."""
        for top in MENUS:
            menu = bar.addMenu(f"&{top}")
            menu.setToolTipsVisible(True)
            entries: list = []   # registry actions, and (title, kind, separator) for submenus
            if top == "View":
                entries.append(("Panels", "panels", False))
            seen: set[str] = set()
            for a in ACTIONS:     # registry order places each submenu where the guide lists it
                if a.menu == top:
                    if a.id == "file.clear_recent":
                        entries.append(("Recent Files", "recent", True))
                        a = replace(a, separator_before=False)
                    entries.append(a)
                elif a.menu.startswith(top + " > ") and a.menu not in seen:
                    seen.add(a.menu)
                    entries.append((a.menu.split(" > ")[-1], a.menu, a.separator_before))
            titles = [e.title if isinstance(e, Action) else e[0] for e in entries]
            fixed = {i: e.mnemonic for i, e in enumerate(entries) if isinstance(e, Action) and e.mnemonic}
            for e, text in zip(entries, mnemonic_titles(titles, fixed)):
                if isinstance(e, Action):
                    if e.separator_before:
                        menu.addSeparator()
                    qa = self.actions[e.id]
                    qa.setText(text)
                    menu.addAction(qa)
                    continue
                if e[2]:
                    menu.addSeparator()
                sub = menu.addMenu(text)
                sub.setToolTipsVisible(True)
                if e[1] == "panels":
                    self.panels_menu = sub
                    for dock in docks:
                        sub.addAction(dock.toggleViewAction())
                elif e[1] == "recent":
                    self.recent_menu = sub
                    sub.aboutToShow.connect(self.fill_recent)
                    self.fill_recent()
                else:
                    items = menu_actions(e[1])
                    for a, t in zip(items, mnemonic_titles([a.title for a in items])):
                        qa = self.actions[a.id]
                        qa.setText(t)
                        sub.addAction(qa)
        for a in ACTIONS:
            if a.menu in CONTEXT_MENUS:
                self.actions[a.id].setText(a.title)

    def fill_recent(self) -> None:
        """File > Recent Files: the last eight projects, newest first."""
        menu = self.recent_menu
        if menu is None:
            return
        menu.clear()
        files = self.window.files.recent_files()
        for i, path in enumerate(files):
            qa = menu.addAction(f"&{i + 1} {path}")
            qa.setToolTip(path)
            qa.triggered.connect(lambda _=False, p=path: self.window.files.open_path(p, ask=True))
        if not files:
            menu.addAction("(none)").setEnabled(False)
        menu.setEnabled(True)


def plain_text(text: str) -> str:
    """Menu text without mnemonic markers (``"Save &As"`` -> ``"Save As"``)."""
    return text.replace("&&", "\0").replace("&", "").replace("\0", "&")


def menubar_table(bar: QMenuBar) -> list[dict]:
    """``[{"menu", "action", "shortcut", "path"}]`` of every item of the live menu bar (submenus included).

    ``menu`` is the top-level menu; ``path`` the full menu path (``"Process > ROM Tools"``).
    Recent file entries are left out (they are file names, not actions).
    """
    rows: list[dict] = []

    def walk(menu: QMenu, path: str, top: str) -> None:
        for qa in menu.actions():
            if qa.isSeparator():
                continue
            title = plain_text(qa.text())
            sub = qa.menu()
            if sub is not None:
                rows.append({"menu": top, "action": title, "shortcut": "", "path": path})
                if title != "Recent Files":
                    walk(sub, f"{path} > {title}", top)
                continue
            rows.append({"menu": top, "action": title,
                         "shortcut": qa.shortcut().toString(QKeySequence.SequenceFormat.PortableText),
                         "path": path})

    for qa in bar.actions():
        if qa.menu() is not None:
            top = plain_text(qa.text())
            walk(qa.menu(), top, top)
    return rows
