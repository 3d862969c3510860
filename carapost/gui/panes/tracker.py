"""The Tracker pane: the Target Tracker's controls, the selected keyframe's box, and the settings.

The buttons run the registry's ``tracker.*`` actions (handlers in
:mod:`carapost.gui.target_actions`), so they are enabled exactly when the
actions are; a running Track back to start / forward to end shows ``||``
(Pause) on its button.  The Keyframe box edits the pattern and comparison
region half sizes of the selected point's keyframe on the current frame in the
active view (the guide's blue box and green cross).  The settings are the
``tracker.*`` properties, edited undoably.
"""
from __future__ import annotations

from PySide6.QtWidgets import (QAbstractButton, QDoubleSpinBox, QFormLayout, QGridLayout, QGroupBox, QHBoxLayout,
                               QPushButton, QToolButton, QVBoxLayout, QWidget)

from ...core.edits import SetProperties
from ...core.properties import PROPERTY_TABLE
from ..target_actions import PAUSE
from .editors import make_editor

#: (registry id, button text), the guide's order.
TRACK_BUTTONS = (("tracker.back_to_start", "<"), ("tracker.back_one", "|<"), ("tracker.forward_one", ">|"),
                 ("tracker.forward_to_end", ">"))
OTHER_BUTTONS = (("tracker.clear", "Clear Tracked Points"), ("tracker.add_keyframe", "Add Keyframe To Current Frame"))
NUDGE_BUTTONS = (("tracker.nudge_left", "←"), ("tracker.nudge_right", "→"), ("tracker.nudge_up", "↑"),
                 ("tracker.nudge_down", "↓"))
#: What a running track button shows (its action's text is then :data:`~carapost.gui.target_actions.PAUSE`).
PAUSE_TEXT = "||"
#: Rows of the keyframe box: half sizes (w, h) in pixels of the pattern and of the comparison region.
BOX_ROWS = ("Pattern half size", "Region half size")


class TrackerPane(QWidget):
    """Target tracking buttons, the keyframe box and the tracker settings.

    Parameters
    ----------
    session : Session
    actions : dict, optional
        The window's QActions by registry id; without them the buttons stay disabled.
    """

    def __init__(self, session, actions=None, parent=None):
        super().__init__(parent)
        self.session = session
        self.actions = actions or {}
        self.buttons: dict[str, QAbstractButton] = {}
        self._texts: dict[str, str] = {}
        grid = QGridLayout()
        for i, (aid, text) in enumerate(TRACK_BUTTONS):
            grid.addWidget(self._button(aid, text, QPushButton), 0, i)
        for j, (aid, text) in enumerate(OTHER_BUTTONS):
            grid.addWidget(self._button(aid, text, QPushButton), 1, 2 * j, 1, 2)

        self.keybox = QGroupBox("Keyframe")
        kform = QFormLayout(self.keybox)
        nudge = QHBoxLayout()
        for aid, text in NUDGE_BUTTONS:
            nudge.addWidget(self._button(aid, text, QToolButton))
        nudge.addStretch(1)
        kform.addRow("Nudge", nudge)
        self.box_editors: list[QDoubleSpinBox] = []
        for title in BOX_ROWS:
            row = QHBoxLayout()
            for axis in ("w", "h"):
                ed = QDoubleSpinBox()
                ed.setRange(1.0, 200.0)
                ed.setDecimals(0)
                ed.setPrefix(f"{axis} ")
                ed.setKeyboardTracking(False)
                ed.valueChanged.connect(self._box_edited)
                row.addWidget(ed)
                self.box_editors.append(ed)
            kform.addRow(title, row)

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
        lay.addWidget(self.keybox)
        lay.addWidget(self.settings_button)
        lay.addWidget(self.settings)
        lay.addStretch(1)
        session.documentChanged.connect(self.refresh)
        session.projectChanged.connect(self.refresh)
        session.frameChanged.connect(lambda _f: self.refresh_keybox())
        session.selectionChanged.connect(self.refresh_keybox)
        self.refresh()

    # ------------------------------------------------------------- buttons
    def _button(self, aid: str, text: str, kind) -> QAbstractButton:
        b = kind()
        b.setText(text)
        b.setObjectName(aid)
        self.buttons[aid] = b
        self._texts[aid] = text
        qa = self.actions.get(aid)
        if qa is None:
            b.setEnabled(False)
            return b
        b.clicked.connect(qa.trigger)
        qa.changed.connect(lambda aid=aid: self._sync_button(aid))
        self._sync_button(aid)
        return b

    def _sync_button(self, aid: str) -> None:
        qa, b = self.actions[aid], self.buttons[aid]
        paused = qa.text() == PAUSE
        b.setText(PAUSE_TEXT if paused else self._texts[aid])
        tip = qa.toolTip()
        if qa.shortcut().toString():
            tip += f" ({qa.shortcut().toString()})"
        b.setToolTip(tip)
        b.setEnabled(qa.isEnabled())

    # ------------------------------------------------------------- keyframe box
    def current_keyframe(self):
        """``(point id, frame, channels, box)`` of the keyframe the box edits, or None."""
        ses = self.session
        p = ses.project
        if p is None or len(ses.selection.points) != 1 or ses.selection.points[0] not in p.points:
            return None
        pid, f = ses.selection.points[0], ses.frame
        keys = p.points[pid].keyframes
        chans = [c for c in p.selected_channels(ses.active_sensor) if (f, c) in keys]
        if not chans:
            chans = [c for c in range(p.sensor_count) if (f, c) in keys][:1]
        return (pid, f, chans, keys[(f, chans[0])]) if chans else None

    def refresh_keybox(self) -> None:
        cur = self.current_keyframe()
        self.keybox.setTitle("Keyframe" if cur is None else
                             f"Keyframe: point {cur[0]}, channel(s) {', '.join(map(str, cur[2]))}")
        for i, ed in enumerate(self.box_editors):
            ed.blockSignals(True)
            ed.setEnabled(cur is not None)
            if cur is not None:
                ed.setValue(float(cur[3][i]))
            ed.blockSignals(False)

    def _box_edited(self, _value=None) -> None:
        from ...core.target_ops import set_keyframe_box

        cur = self.current_keyframe()
        if cur is None:
            return
        box = tuple(ed.value() for ed in self.box_editors)
        if box != tuple(cur[3]):
            p = self.session.project
            if not self.session.attempt(set_keyframe_box, p, cur[0], cur[1], cur[2], box):
                self.refresh_keybox()

    # ------------------------------------------------------------- settings
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
        self.refresh_keybox()
