"""Every question the window asks the user, in one replaceable object.

Handlers never open dialogs themselves: they call the window's
:class:`Prompts`.  Tests (and scripts driving the window) replace it with a
scripted one, so a modal dialog never blocks an offscreen run.
"""
from __future__ import annotations

from PySide6.QtGui import QColor
from PySide6.QtWidgets import QColorDialog, QFileDialog, QInputDialog, QMessageBox, QWidget

CARA_FILTER = "CaraPost projects (*.cara)"


class Prompts:
    """Modal dialogs parented to ``parent``."""

    def __init__(self, parent: QWidget | None = None):
        self.parent = parent

    def open_file(self, title: str, file_filter: str, folder: str = "") -> str | None:
        path, _ = QFileDialog.getOpenFileName(self.parent, title, folder, file_filter)
        return path or None

    def open_files(self, title: str, file_filter: str, folder: str = "") -> list[str]:
        paths, _ = QFileDialog.getOpenFileNames(self.parent, title, folder, file_filter)
        return list(paths)

    def save_file(self, title: str, file_filter: str, suggested: str = "") -> str | None:
        path, _ = QFileDialog.getSaveFileName(self.parent, title, suggested, file_filter)
        if path and file_filter == CARA_FILTER and not path.lower().endswith(".cara"):
            path += ".cara"
        return path or None

    def get_text(self, title: str, label: str, text: str = "", items: list[str] | None = None) -> str | None:
        """A line of text; with ``items`` an editable list to pick from."""
        dlg = QInputDialog(self.parent)
        dlg.setWindowTitle(title)
        dlg.setLabelText(label)
        if items:
            dlg.setComboBoxItems(items)
            dlg.setComboBoxEditable(True)
        dlg.setTextValue(text)
        return dlg.textValue() if dlg.exec() else None

    def get_int(self, title: str, label: str, value: int, minimum: int, maximum: int) -> int | None:
        v, ok = QInputDialog.getInt(self.parent, title, label, value, minimum, maximum)
        return int(v) if ok else None

    def get_item(self, title: str, label: str, items: list[str]) -> str | None:
        v, ok = QInputDialog.getItem(self.parent, title, label, items, 0, False)
        return v if ok else None

    def get_color(self, title: str, color: tuple[int, int, int]) -> tuple[int, int, int] | None:
        c = QColorDialog.getColor(QColor(*color), self.parent, title)
        return (c.red(), c.green(), c.blue()) if c.isValid() else None

    def confirm(self, title: str, text: str) -> bool:
        return QMessageBox.question(self.parent, title, text) == QMessageBox.StandardButton.Yes

    def save_discard_cancel(self, title: str, text: str) -> str:
        """``"save"``, ``"discard"`` or ``"cancel"``."""
        B = QMessageBox.StandardButton
        r = QMessageBox.question(self.parent, title, text, B.Save | B.Discard | B.Cancel, B.Save)
        return {B.Save: "save", B.Discard: "discard"}.get(r, "cancel")

    def relocate(self, project) -> dict[int, str] | None:
        """Edit > Relocate Files: new media path per sensor (only the changed ones)."""
        from .relocate import RelocateDialog

        dlg = RelocateDialog(project, self.parent)
        return dlg.changes() if dlg.exec() else None

    def error(self, title: str, text: str) -> None:
        QMessageBox.critical(self.parent, title, text)

    def info(self, title: str, text: str) -> None:
        QMessageBox.information(self.parent, title, text)
