"""Process > ROM Tools > Display ROM Timebar: the ROM take's frames as a timebar in a window of its own.

The guide: "Displays a timebar for the ROM in its own window".  The strip is drawn as the main timebar is
(:func:`.timebar.paint_frames`: labelled ticks, the current frame in red), and its current frame is the
Initialize From ROM Parameters' ROM Frame Index.  Click or drag on it (or use the wheel, Shift for ten
frames a notch, or type in the box beside it): the red line follows, and the frame where the mouse is
released becomes the ROM Frame Index, one History entry ("Set ROM Frame Index").
"""
from __future__ import annotations

from pathlib import Path

from PySide6.QtCore import Qt, Signal
from PySide6.QtGui import QPainter
from PySide6.QtWidgets import QDialog, QHBoxLayout, QLabel, QSizePolicy, QSpinBox, QWidget

from ..core.rom_ops import ROM_FRAME_INDEX, rf_index
from .timebar import frame_under, frame_x, paint_frames, wheel_steps


class RomFrameStrip(QWidget):
    """The ROM take's frames ``0 .. last``; ``frameChosen`` when a click, drag or wheel step ends on a frame."""

    frameChosen = Signal(int)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setMinimumSize(400, 34)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
        self.last = 0
        self.frame = 0

    def set_frames(self, last: int, frame: int) -> None:
        """Show frames ``0 .. last`` with ``frame`` current."""
        self.last, self.frame = max(0, int(last)), int(frame)
        self.update()

    def x_of(self, frame: float) -> float:
        return frame_x((0, self.last), self.width(), frame)

    def paintEvent(self, _ev) -> None:
        paint_frames(QPainter(self), self.width(), self.height(), (0, self.last), self.frame)

    def _follow(self, x: float) -> None:
        self.frame = frame_under((0, self.last), self.width(), x)
        self.update()

    def mousePressEvent(self, ev) -> None:
        if ev.button() == Qt.MouseButton.LeftButton:
            self._follow(ev.position().x())

    def mouseMoveEvent(self, ev) -> None:
        if ev.buttons() & Qt.MouseButton.LeftButton:
            self._follow(ev.position().x())

    def mouseReleaseEvent(self, ev) -> None:
        if ev.button() == Qt.MouseButton.LeftButton:
            self._follow(ev.position().x())
            self.frameChosen.emit(self.frame)

    def wheelEvent(self, ev) -> None:
        self.frame = max(0, min(self.last, self.frame - wheel_steps(ev)))
        self.update()
        self.frameChosen.emit(self.frame)
        ev.accept()


class RomTimebar(QDialog):
    """The window: the ROM file's name, its frames (:class:`RomFrameStrip`) and a box for the frame number."""

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        self.setWindowTitle("ROM Timebar")
        self.setWindowFlag(Qt.WindowType.Tool, True)
        lay = QHBoxLayout(self)
        self.name = QLabel()
        self.strip = RomFrameStrip()
        self.spin = QSpinBox()
        for w in (self.name, self.strip, self.spin):
            lay.addWidget(w)
        self.strip.frameChosen.connect(self.set_frame)
        self.spin.editingFinished.connect(lambda: self.set_frame(self.spin.value()))
        session.projectChanged.connect(self._sync)

    def set_rom(self, state) -> None:
        """Show the frames of the loaded ROM ``state`` (:func:`carapost.core.rom_ops.loaded_rom`)."""
        self.name.setText(Path(state.path).name)
        self.spin.setRange(0, state.rom.frame_count - 1)
        self.strip.set_frames(state.rom.frame_count - 1, self.strip.frame)
        self._sync()

    def _sync(self) -> None:
        p = self.session.project
        if p is None:
            return
        v = rf_index(p)
        self.strip.set_frames(self.strip.last, v)
        self.spin.blockSignals(True)
        self.spin.setValue(v)
        self.spin.blockSignals(False)

    def set_frame(self, frame: int) -> None:
        """Set the ROM Frame Index (one undoable edit), as releasing the mouse on that frame does."""
        from ..core.edits import SetProperties

        p = self.session.project
        v = max(0, min(self.strip.last, int(frame)))
        if p is not None and rf_index(p) != v:
            self.session.run(SetProperties({ROM_FRAME_INDEX: v}, name="Set ROM Frame Index"))
        self._sync()
