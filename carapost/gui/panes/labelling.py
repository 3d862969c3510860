"""The Labelling pane: the label list with its colours, drag to reorder, double-click to rename.

Colours are the guide's: red for a label no point carries, grey for an
assigned label, yellow for an assigned label whose point has no 3D position
on the current frame.  The label selected here is the one Merge and Select
Next Label (L) gives the merged point.
"""
from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtGui import QColor
from PySide6.QtWidgets import (QAbstractItemView, QHBoxLayout, QLineEdit, QListWidget, QListWidgetItem, QPushButton,
                               QVBoxLayout, QWidget)

from ...core.editing import RenameLabel, label_states, reorder_labels
from ...core.edits import SetLabels

STATE_COLORS = {"unassigned": QColor(255, 90, 90), "assigned": QColor(160, 160, 160), "absent": QColor(255, 216, 74)}
STATE_TIPS = {"unassigned": "not assigned to a point", "assigned": "assigned",
              "absent": "assigned, but its point has no 3D data on this frame"}
STATE_ROLE = Qt.ItemDataRole.UserRole + 1


class LabellingPane(QWidget):
    """The project's label list.

    Parameters
    ----------
    session : Session
    window : MainWindow
        For its prompts (rename) and its Clear All / Delete Selected actions.
    """

    def __init__(self, session, window, parent=None):
        super().__init__(parent)
        self.session = session
        self.window = window
        self.list = QListWidget()
        self.list.setSelectionMode(QAbstractItemView.SelectionMode.ExtendedSelection)
        self.list.setDragDropMode(QAbstractItemView.DragDropMode.InternalMove)
        self.list.setDefaultDropAction(Qt.DropAction.MoveAction)
        self.list.setStyleSheet("QListWidget { background: #262626; }")
        self.list.model().rowsMoved.connect(self._rows_moved)
        self.list.itemDoubleClicked.connect(self.rename_item)
        self.list.currentItemChanged.connect(self._current_changed)
        self.add = QLineEdit(placeholderText="New label, Enter to add")
        self.add.returnPressed.connect(self._add_label)
        buttons = QHBoxLayout()
        for aid in ("edit.clear_all_labels", "edit.delete_selected_labels"):
            act = window.actionset.actions[aid]
            b = QPushButton(act.text().replace("&", ""))
            b.setToolTip(act.toolTip())
            b.clicked.connect(act.trigger)
            buttons.addWidget(b)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addWidget(self.list)
        lay.addWidget(self.add)
        lay.addLayout(buttons)
        self._labels: list[str] = []
        session.documentChanged.connect(self.refresh)
        session.projectChanged.connect(self.refresh)
        session.frameChanged.connect(lambda _f: self.recolor())
        session.labelChanged.connect(self._select_current)
        self.refresh()

    # ------------------------------------------------------------- display
    def refresh(self) -> None:
        p = self.session.project
        labels = list(p.labels) if p is not None else []
        if labels != self._labels:
            self._labels = labels
            self.list.blockSignals(True)
            self.list.clear()
            for lb in labels:
                item = QListWidgetItem(lb)
                item.setFlags(item.flags() | Qt.ItemFlag.ItemIsDragEnabled)
                self.list.addItem(item)
            self.list.blockSignals(False)
            if self.session.current_label not in labels:
                self.session.set_current_label(None)
            self._select_current()
        self.recolor()
        self.setEnabled(p is not None)

    def recolor(self) -> None:
        p = self.session.project
        if p is None:
            return
        states = label_states(p, self.session.frame)
        for i in range(self.list.count()):
            item = self.list.item(i)
            state = states.get(item.text(), "unassigned")
            if item.data(STATE_ROLE) != state:    # restyling every item each frame would repaint the list
                item.setData(STATE_ROLE, state)
                item.setForeground(STATE_COLORS[state])
                item.setToolTip(STATE_TIPS[state])

    def state_of(self, label: str) -> str:
        """The colour state of ``label`` on the current frame (tests)."""
        return label_states(self.session.project, self.session.frame)[label]

    def selected_labels(self) -> list[str]:
        return [i.text() for i in self.list.selectedItems()]

    def _select_current(self) -> None:
        lb = self.session.current_label
        self.list.blockSignals(True)
        for i in range(self.list.count()):
            item = self.list.item(i)
            if item.text() == lb:
                self.list.setCurrentItem(item)
                self.list.scrollToItem(item)
                break
        else:
            self.list.setCurrentRow(-1)
        self.list.blockSignals(False)

    # --------------------------------------------------------------- edits
    def _current_changed(self, item, _prev) -> None:
        self.session.set_current_label(item.text() if item is not None else None)

    def _rows_moved(self, *_args) -> None:
        order = [self.list.item(i).text() for i in range(self.list.count())]
        p = self.session.project
        if p is not None and order != p.labels:
            self._labels = order          # the list already shows it
            self.session.attempt(reorder_labels, p, order)

    def rename_item(self, item: QListWidgetItem) -> None:
        """Double-click: rename the label (and its point)."""
        old = item.text()
        new = self.window.prompts.get_text("Rename Label", "Label:", old)
        if new is not None and new.strip() and new.strip() != old:
            self.session.attempt(lambda: RenameLabel(old, new))

    def _add_label(self) -> None:
        p = self.session.project
        names = self.add.text().split()
        if p is None or not names:
            return
        new = [n for n in names if n not in p.labels]
        if new:
            self.session.attempt(lambda: SetLabels(p.labels + new, name="Add Labels"))
        self.add.clear()
