"""The Selected Point pane: a placeholder until its continuity bars arrive (issue 10)."""
from __future__ import annotations

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QLabel, QVBoxLayout, QWidget


class SelectedPointPane(QWidget):
    """Says what the pane will show and when."""

    def __init__(self, parent=None):
        super().__init__(parent)
        text = QLabel("Not available yet: the Selected Point pane (the continuity bars of the selected point "
                      "per channel) lands with issue 10.")
        text.setWordWrap(True)
        text.setAlignment(Qt.AlignmentFlag.AlignCenter)
        lay = QVBoxLayout(self)
        lay.addWidget(text)
