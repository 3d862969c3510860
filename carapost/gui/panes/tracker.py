"""The Tracker pane: the Target Tracker's controls and settings.

The tracking buttons arrive with the Target Tracker (issue 8) and are shown
disabled until then; the settings are the ``tracker.*`` properties and are
edited (undoably) here.
"""
from __future__ import annotations

from PySide6.QtWidgets import QFormLayout, QGridLayout, QGroupBox, QPushButton, QVBoxLayout, QWidget

from ...core.edits import SetProperties
from ...core.properties import PROPERTY_TABLE
from .editors import make_editor

BUTTONS = (("<", "Track back to start"), ("|<", "Track back one frame"), (">|", "Track forward one frame"),
           (">", "Track forward to end"))
LATER = "Not available yet: the Target Tracker lands with issue 8."


class TrackerPane(QWidget):
    """Target tracking buttons (disabled until issue 8) and the tracker settings."""

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        grid = QGridLayout()
        self.buttons: dict[str, QPushButton] = {}
        for i, (text, tip) in enumerate(BUTTONS):
            b = QPushButton(text)
            b.setToolTip(f"{tip}. {LATER}")
            b.setEnabled(False)
            grid.addWidget(b, 0, i)
            self.buttons[tip] = b
        for j, text in enumerate(("Clear Tracked Points", "Add Keyframe To Current Frame")):
            b = QPushButton(text)
            b.setToolTip(LATER)
            b.setEnabled(False)
            grid.addWidget(b, 1, 2 * j, 1, 2)
            self.buttons[text] = b
        self.settings_button = QPushButton("Settings", checkable=True, checked=True)
        self.settings = QGroupBox("Settings")
        form = QFormLayout(self.settings)
        self.editors = {}
        for pdef in (p for p in PROPERTY_TABLE if p.group == "tracker"):
            ed = make_editor(pdef, self.commit)
            form.addRow(pdef.title + ("=" if pdef.name == "n_frames" else ""), ed)
            self.editors[pdef.key] = ed
        self.settings_button.toggled.connect(self.settings.setVisible)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addLayout(grid)
        lay.addWidget(self.settings_button)
        lay.addWidget(self.settings)
        lay.addStretch(1)
        session.documentChanged.connect(self.refresh)
        session.projectChanged.connect(self.refresh)
        self.refresh()

    def commit(self, key, value) -> None:
        p = self.session.project
        if p is not None and p.properties[key] != value:
            if not self.session.attempt(lambda: SetProperties({key: value})):
                self.refresh()

    def refresh(self) -> None:
        p = self.session.project
        self.settings.setEnabled(p is not None)
        if p is not None:
            for key, ed in self.editors.items():
                ed.set_value(p.properties[key])
