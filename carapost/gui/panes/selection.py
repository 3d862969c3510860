"""The Selection pane: the channels that editing and processing functions apply to explicitly.

With no channel ticked, functions such as Detach Detections use the active
camera view's channel (the last one clicked).  Shift+click in a camera view
toggles its channel here too.
"""
from __future__ import annotations

from PySide6.QtWidgets import QCheckBox, QLabel, QPushButton, QVBoxLayout, QWidget

from ...core.editing import SetChannelSelection


class SelectionPane(QWidget):
    """One check box per channel (sets ``project.channel_selection`` through a command)."""

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        self.boxes: list[QCheckBox] = []
        self.box_layout = QVBoxLayout()
        self.summary = QLabel()
        self.summary.setWordWrap(True)
        clear = QPushButton("Clear Channel Selection")
        clear.clicked.connect(lambda: self.set_channels([]))
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(QLabel("Channels used by Detach Detections, Rotate, Increment Image Sequence Offset:"))
        lay.addLayout(self.box_layout)
        lay.addWidget(clear)
        lay.addWidget(self.summary)
        lay.addStretch(1)
        session.documentChanged.connect(self.refresh)
        session.projectChanged.connect(self.refresh)
        session.selectionChanged.connect(self._summary)
        self.refresh()

    def refresh(self) -> None:
        p = self.session.project
        n = p.sensor_count if p is not None else 0
        while len(self.boxes) > n:
            self.boxes.pop().deleteLater()
        while len(self.boxes) < n:
            i = len(self.boxes)
            b = QCheckBox()
            b.toggled.connect(lambda on, i=i: self._toggled(i, on))
            self.box_layout.addWidget(b)
            self.boxes.append(b)
        for i, b in enumerate(self.boxes):
            b.blockSignals(True)
            b.setText(p.sensors[i].name)
            b.setChecked(i in p.channel_selection)
            b.blockSignals(False)
        self.setEnabled(p is not None)
        self._summary()

    def _toggled(self, i: int, on: bool) -> None:
        p = self.session.project
        chans = set(p.channel_selection)
        chans = chans | {i} if on else chans - {i}
        self.set_channels(sorted(chans))

    def set_channels(self, channels: list[int]) -> None:
        p = self.session.project
        if p is not None and sorted(channels) != sorted(p.channel_selection):
            self.session.attempt(lambda: SetChannelSelection(channels))

    def _summary(self) -> None:
        sel = self.session.selection
        p = self.session.project
        if p is None:
            self.summary.setText("")
            return
        chans = p.selected_channels(self.session.active_sensor)
        self.summary.setText(f"Selected: {len(sel.points)} point(s), {len(sel.detections)} detection(s), "
                             f"{len(sel.sticks)} stick(s). Channels in use: {', '.join(map(str, chans))}")
