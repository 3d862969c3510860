"""The Properties pane: every section of the property table, editable, undoable."""
from __future__ import annotations

from typing import Any

from PySide6.QtWidgets import QHeaderView, QPushButton, QTreeWidget, QTreeWidgetItem, QVBoxLayout, QWidget

from ...core.actions import ACTIONS, CONTEXT_2D
from ...core.edits import SetProperties
from ...core.properties import GROUPS, PROPERTY_TABLE, property_def
from .editors import make_editor

#: Property groups shown in other panes (the Tracker pane holds the tracker settings).
ELSEWHERE = {"tracker"}
#: The guide's read-only Shortcut section sits after Export.
SHORTCUT_SECTION_AFTER = "export"


class PropertiesPane(QWidget):
    """Groups of the property table as a tree; edits go through SetProperties.

    Parameters
    ----------
    session : Session
    restore_action : QAction, optional
        Edit > Restore Properties To Defaults (shown as a button).
    """

    def __init__(self, session, restore_action=None, parent=None):
        super().__init__(parent)
        self.session = session
        self.tree = QTreeWidget()
        self.tree.setColumnCount(2)
        self.tree.setHeaderLabels(["Property", "Value"])
        self.tree.header().setSectionResizeMode(0, QHeaderView.ResizeMode.ResizeToContents)
        self.editors: dict[str, QWidget] = {}
        self.groups: dict[str, QTreeWidgetItem] = {}
        for group, title in GROUPS.items():
            if group in ELSEWHERE:
                continue
            item = QTreeWidgetItem(self.tree, [title])
            self.groups[group] = item
            for pdef in (p for p in PROPERTY_TABLE if p.group == group):
                child = QTreeWidgetItem(item, [pdef.title])
                child.setToolTip(0, pdef.help)
                ed = make_editor(pdef, self.commit)
                self.tree.setItemWidget(child, 1, ed)
                self.editors[pdef.key] = ed
            if group == SHORTCUT_SECTION_AFTER:
                self._shortcut_section()
        for item in self.groups.values():
            item.setExpanded(True)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        if restore_action is not None:
            b = QPushButton(restore_action.text().replace("&", ""))
            b.clicked.connect(restore_action.trigger)
            b.setToolTip(restore_action.toolTip())
            lay.addWidget(b)
        lay.addWidget(self.tree)
        session.documentChanged.connect(self.refresh)
        session.projectChanged.connect(self.refresh)
        self.refresh()

    def _shortcut_section(self) -> None:
        """The guide's Shortcut section: commonly used shortcuts, read-only (from the action registry)."""
        item = QTreeWidgetItem(self.tree, ["Shortcut"])
        self.groups["shortcut"] = item
        for a in ACTIONS:
            if a.shortcut and a.available and a.menu != CONTEXT_2D:
                QTreeWidgetItem(item, [a.title, a.shortcut])

    def editor(self, key: str) -> QWidget:
        """The editor of property ``group.name``."""
        return self.editors[key]

    def commit(self, key: str, value: Any) -> None:
        p = self.session.project
        if p is None:
            self.refresh()
            return
        if p.properties[key] == value:
            return
        if not self.session.attempt(lambda: SetProperties({key: value})):
            self.refresh()           # invalid value: show the project's again

    def refresh(self) -> None:
        p = self.session.project
        self.tree.setEnabled(p is not None)
        for key, ed in self.editors.items():
            ed.set_value(p.properties[key] if p is not None else property_def(key).default)
