"""The History pane: the undo stack, undone entries in red; click an entry to go back to that state."""
from __future__ import annotations

from PySide6.QtGui import QColor, QFont
from PySide6.QtWidgets import QHBoxLayout, QLabel, QListWidget, QListWidgetItem, QPushButton, QVBoxLayout, QWidget

DONE, UNDONE = QColor(235, 235, 235), QColor(255, 90, 90)
ORIGIN = "(opened)"


class HistoryPane(QWidget):
    """Entries of the undo stack; row 0 is the state the project was opened in.

    Parameters
    ----------
    session : Session
    clear_action : QAction
        Edit > Clear History.
    """

    def __init__(self, session, clear_action=None, parent=None):
        super().__init__(parent)
        self.session = session
        self.list = QListWidget()
        self.list.setStyleSheet("QListWidget { background: #262626; }")
        self.list.itemClicked.connect(self._clicked)
        self.memory = QLabel()
        row = QHBoxLayout()
        row.addWidget(self.memory, 1)
        if clear_action is not None:
            b = QPushButton("Clear History")
            b.setToolTip(clear_action.toolTip())
            b.clicked.connect(clear_action.trigger)
            row.addWidget(b)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addWidget(self.list)
        lay.addLayout(row)
        self._names: list[str] | None = None
        session.documentChanged.connect(self.refresh)
        session.projectChanged.connect(self.refresh)
        self.refresh()

    def refresh(self) -> None:
        doc = self.session.doc
        names = doc.stack.names() if doc is not None else []
        if names != self._names:
            self._names = names
            self.list.clear()
            self.list.addItem(QListWidgetItem(ORIGIN))
            for n in names:
                self.list.addItem(QListWidgetItem(n))
        index = doc.stack.index if doc is not None else 0
        bold = QFont()
        bold.setBold(True)
        for r in range(self.list.count()):
            item = self.list.item(r)
            item.setForeground(DONE if r <= index else UNDONE)
            item.setFont(bold if r == index else QFont())
        if doc is not None:
            self.list.scrollToItem(self.list.item(index))
            mb = doc.stack.memory_bytes() / 1e6
            self.memory.setText(f"{len(names)} entries, {doc.stack.index} done; history memory {mb:.1f} MB")
        else:
            self.memory.setText("")

    def entries(self) -> list[tuple[str, bool]]:
        """``(name, undone)`` of every stack entry (tests)."""
        doc = self.session.doc
        return [(self.list.item(r).text(), self.list.item(r).foreground().color() == UNDONE)
                for r in range(1, self.list.count())] if doc is not None else []

    def _clicked(self, item: QListWidgetItem) -> None:
        doc = self.session.doc
        if doc is None or self.session.busy:
            return
        target = self.list.row(item)
        doc.stack.set_index(target)
