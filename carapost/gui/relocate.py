"""Edit > Relocate Files: choose each channel's media again (moved or replaced .pico files)."""
from __future__ import annotations

from pathlib import Path

from PySide6.QtWidgets import (QDialog, QDialogButtonBox, QFileDialog, QGridLayout, QLabel, QLineEdit, QPushButton,
                               QVBoxLayout)

MEDIA_FILTER = "Channel media (*.pico *.mp4 *.avi *.mov *.mkv);;All files (*)"


class RelocateDialog(QDialog):
    """One row per channel: its media path, whether it was found, and Browse…"""

    def __init__(self, project, parent=None):
        super().__init__(parent)
        self.setWindowTitle("Relocate Files")
        self.project = project
        grid = QGridLayout()
        self.edits: list[QLineEdit] = []
        for i, s in enumerate(project.sensors):
            grid.addWidget(QLabel(s.name), i, 0)
            edit = QLineEdit(s.media.path)
            edit.setMinimumWidth(420)
            self.edits.append(edit)
            grid.addWidget(edit, i, 1)
            state = QLabel("missing" if s.media.missing or not s.media.path else "found")
            state.setStyleSheet("color: #ff5a5a" if s.media.missing else "")
            grid.addWidget(state, i, 2)
            b = QPushButton("Browse…")
            b.clicked.connect(lambda _=False, i=i: self._browse(i))
            grid.addWidget(b, i, 3)
        buttons = QDialogButtonBox(QDialogButtonBox.StandardButton.Ok | QDialogButtonBox.StandardButton.Cancel)
        buttons.accepted.connect(self.accept)
        buttons.rejected.connect(self.reject)
        lay = QVBoxLayout(self)
        lay.addWidget(QLabel("Where is each channel's media? (a .pico file, a video file or a folder of images)"))
        lay.addLayout(grid)
        lay.addWidget(buttons)

    def _browse(self, i: int) -> None:
        start = str(Path(self.edits[i].text()).parent) if self.edits[i].text() else ""
        path, _ = QFileDialog.getOpenFileName(self, f"Media of {self.project.sensors[i].name}", start, MEDIA_FILTER)
        if path:
            self.edits[i].setText(path)

    def set_path(self, sensor: int, path: str) -> None:
        self.edits[sensor].setText(path)

    def changes(self) -> dict[int, str]:
        """Channels whose path was changed: sensor -> new path."""
        return {i: e.text().strip() for i, e in enumerate(self.edits)
                if e.text().strip() and e.text().strip() != self.project.sensors[i].media.path}
