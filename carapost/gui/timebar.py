"""The timebar, the play controls under the views, and the progress bar of background jobs.

The timebar shows the view range; the active range is the highlighted band.
Click or drag to scrub, Ctrl+drag to set the active range, middle-drag or the
wheel to shuttle.
"""
from __future__ import annotations

import numpy as np
from PySide6.QtCore import QRectF, Qt, Signal
from PySide6.QtGui import QColor, QPainter, QPen
from PySide6.QtWidgets import (QHBoxLayout, QLabel, QProgressBar, QPushButton, QSizePolicy, QSpinBox, QToolButton,
                               QVBoxLayout, QWidget)

from ..core.editing import keyframe_frames


class Timebar(QWidget):
    """Frames of the view range with the current frame, the active range and keyframes."""

    frameRequested = Signal(int)
    activeRangeRequested = Signal(int, int)

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        self.setMinimumHeight(34)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Fixed)
        self.setMouseTracking(False)
        self._ctrl_range: tuple[int, int] | None = None
        self._ctrl_anchor = 0
        self._shuttle: tuple[float, int] | None = None
        self._keys_cache: tuple | None = None
        for sig in (session.documentChanged, session.projectChanged, session.selectionChanged):
            sig.connect(self.update)
        session.frameChanged.connect(lambda _f: self.update())

    # ------------------------------------------------------------ geometry
    def _range(self) -> tuple[int, int]:
        p = self.session.project
        return p.view_range if p is not None else (0, 0)

    def x_of(self, frame: float) -> float:
        return frame_x(self._range(), self.width(), frame)

    def frame_at(self, x: float) -> int:
        """Frame under widget x (clamped to the view range)."""
        return frame_under(self._range(), self.width(), x)

    # ------------------------------------------------------------ painting
    def paintEvent(self, _ev) -> None:
        qp = QPainter(self)
        p = self.session.project
        if p is None:
            qp.fillRect(self.rect(), QColor(45, 45, 45))
            return
        paint_frames(qp, self.width(), self.height(), p.view_range, self.session.frame,
                     self._ctrl_range or p.active_range, self._keyframes())

    def _keyframes(self) -> list[int]:
        ses = self.session
        key = (id(ses.doc), tuple(ses.selection.points), ses.doc.stack.index if ses.doc else 0)
        if self._keys_cache is None or self._keys_cache[0] != key:
            self._keys_cache = (key, keyframe_frames(ses.project, ses.selection.points))
        return self._keys_cache[1]

    # ------------------------------------------------------------ mouse
    def mousePressEvent(self, ev) -> None:
        if self.session.project is None:
            return
        f = self.frame_at(ev.position().x())
        if ev.button() == Qt.MouseButton.LeftButton and ev.modifiers() & Qt.KeyboardModifier.ControlModifier:
            self._ctrl_range = (f, f)
            self._ctrl_anchor = f
            self.update()
        elif ev.button() == Qt.MouseButton.LeftButton:
            self.frameRequested.emit(f)
        elif ev.button() == Qt.MouseButton.MiddleButton:
            self._shuttle = (ev.position().x(), self.session.frame)

    def mouseMoveEvent(self, ev) -> None:
        if self.session.project is None:
            return
        x = ev.position().x()
        if self._ctrl_range is not None:
            f = self.frame_at(x)
            self._ctrl_range = (min(f, self._ctrl_anchor), max(f, self._ctrl_anchor))
            self.update()
        elif self._shuttle is not None:
            x0, f0 = self._shuttle
            a, b = self._range()
            per_px = max(1.0, (b - a + 1) / max(self.width(), 1))
            self.frameRequested.emit(int(round(f0 + (x - x0) * per_px)))
        elif ev.buttons() & Qt.MouseButton.LeftButton:
            self.frameRequested.emit(self.frame_at(x))

    def mouseReleaseEvent(self, ev) -> None:
        if self._ctrl_range is not None:
            r, self._ctrl_range = self._ctrl_range, None
            self.activeRangeRequested.emit(*r)
            self.update()
        self._shuttle = None

    def wheelEvent(self, ev) -> None:
        if self.session.project is None:
            return
        self.frameRequested.emit(self.session.frame - wheel_steps(ev))
        ev.accept()


#: Room (px) left and right of the frames.
MARGIN = 6.0


def frame_x(frames: tuple[int, int], width: float, frame: float) -> float:
    """Widget x of the middle of ``frame`` on a strip ``width`` px wide showing ``frames = (first, last)``."""
    a, b = frames
    return MARGIN + (frame - a + 0.5) / max(1, b - a + 1) * (width - 2 * MARGIN)


def frame_under(frames: tuple[int, int], width: float, x: float) -> int:
    """The frame under widget ``x`` (clamped to ``frames``), on a strip as :func:`frame_x` draws it."""
    a, b = frames
    f = a + int(np.floor((x - MARGIN) / max(width - 2 * MARGIN, 1) * (b - a + 1)))
    return max(a, min(b, f))


def paint_frames(qp: QPainter, width: int, height: int, frames: tuple[int, int], current: int,
                 band: tuple[int, int] | None = None, keys=()) -> None:
    """A timebar: the frames ``(first, last)`` with labelled ticks, the ``band`` of frames highlighted (the
    active range), ``keys`` as white marks and the ``current`` frame as a red line."""
    qp.fillRect(0, 0, width, height, QColor(45, 45, 45))
    a, b = frames
    x_of = lambda f: frame_x(frames, width, f)   # noqa: E731
    if band is not None:
        x0, x1 = x_of(max(band[0], a) - 0.5), x_of(min(band[1], b) + 0.5)
        if x1 > x0:
            qp.fillRect(QRectF(x0, 2, x1 - x0, height - 4), QColor(70, 95, 140))
    # ticks: about one labelled tick per 80 px
    step = _nice_step((b - a + 1) * 80 / max(width, 1))
    qp.setPen(QColor(170, 170, 170))
    for f in range(int(np.ceil(a / step) * step), b + 1, step):
        x = x_of(f)
        qp.drawLine(int(x), height - 10, int(x), height - 2)
        qp.drawText(int(x) + 2, height - 12, str(f))
    qp.setPen(QPen(QColor(255, 255, 255), 1))
    for f in keys:
        if a <= f <= b:
            x = int(x_of(f))
            qp.drawLine(x, 2, x, 10)
    qp.setPen(QPen(QColor(255, 80, 80), 2))
    x = x_of(current)
    qp.drawLine(int(x), 0, int(x), height)


def wheel_steps(ev) -> int:
    """Frames a wheel event moves a timebar by: one a notch forwards or back, ten with Shift."""
    steps = int(np.sign(ev.angleDelta().y() or ev.angleDelta().x()))
    return 10 * steps if ev.modifiers() & Qt.KeyboardModifier.ShiftModifier else steps


def _nice_step(raw: float) -> int:
    """1, 2, 5, 10, 20, 50... at least ``raw``."""
    raw = max(raw, 1.0)
    mag = 10 ** int(np.floor(np.log10(raw)))
    for m in (1, 2, 5, 10):
        if m * mag >= raw:
            return int(m * mag)
    return int(10 * mag)


class ProgressPanel(QWidget):
    """Progress of the running background job with its Cancel button (hidden when idle)."""

    cancelRequested = Signal()

    def __init__(self, parent=None):
        super().__init__(parent)
        self.title = QLabel()
        self.bar = QProgressBar()
        self.bar.setTextVisible(True)
        self.cancel = QPushButton("Cancel")
        self.cancel.clicked.connect(self.cancelRequested)
        lay = QHBoxLayout(self)
        lay.setContentsMargins(4, 0, 4, 0)
        lay.addWidget(self.title)
        lay.addWidget(self.bar, 1)
        lay.addWidget(self.cancel)
        self.hide()

    def start(self, title: str, cancellable: bool = True) -> None:
        self.title.setText(title)
        self.bar.setRange(0, 0)          # busy indicator until the first step
        self.cancel.setVisible(cancellable)
        self.cancel.setEnabled(True)
        self.show()

    def set_progress(self, done: int, total: int, message: str) -> None:
        if total > 0:
            self.bar.setRange(0, total)
            self.bar.setValue(min(done, total))
        if message:
            self.bar.setFormat(f"{message}  %p%")
        if message == "cancelling…":
            self.cancel.setEnabled(False)

    def stop(self) -> None:
        self.hide()
        self.bar.setFormat("%p%")


class TimePanel(QWidget):
    """Play controls, frame number, timebar and ranges; the progress panel sits under them.

    Parameters
    ----------
    session : Session
    actions : dict
        The window's QActions (the buttons trigger Play, Next Frame...).
    """

    def __init__(self, session, actions: dict, parent=None):
        super().__init__(parent)
        self.session = session
        self.timebar = Timebar(session)
        self.spin = QSpinBox()
        self.spin.setKeyboardTracking(False)
        self.spin.setToolTip("Current frame (type a number and press Enter)")
        self.spin.setRange(0, 0)
        self.spin.setMinimumWidth(80)
        self.total = QLabel("/ 0")
        self.ranges = QLabel()
        self.progress = ProgressPanel()
        row = QHBoxLayout()
        row.setContentsMargins(2, 0, 2, 0)
        self.buttons = {}
        for aid, text in (("view.go_start", "|<"), ("view.prev_frame", "<"), ("view.play", "Play"),
                          ("view.next_frame", ">"), ("view.go_end", ">|")):
            act = actions[aid]
            b = QToolButton(text=text, toolTip=f"{act.text().replace('&', '')} ({act.shortcut().toString()})")
            b.clicked.connect(act.trigger)
            # held down, the step buttons repeat like the arrow keys
            b.setAutoRepeat(aid in ("view.prev_frame", "view.next_frame"))
            b.setFocusPolicy(Qt.FocusPolicy.NoFocus)
            act.changed.connect(lambda b=b, act=act: b.setEnabled(act.isEnabled()))
            b.setEnabled(act.isEnabled())
            self.buttons[aid] = b
            row.addWidget(b)
        actions["view.play"].toggled.connect(lambda on: self.buttons["view.play"].setText("Stop" if on else "Play"))
        row.addWidget(QLabel("Frame"))
        row.addWidget(self.spin)
        row.addWidget(self.total)
        row.addWidget(self.timebar, 1)
        row.addWidget(self.ranges)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(0, 2, 0, 2)
        lay.setSpacing(2)
        lay.addLayout(row)
        lay.addWidget(self.progress)
        self.spin.valueChanged.connect(self._spin_changed)
        session.documentChanged.connect(self.refresh)
        session.projectChanged.connect(self.refresh)
        session.frameChanged.connect(self._frame_changed)
        self.refresh()

    def _spin_changed(self, v: int) -> None:
        if self.session.doc is not None and v != self.session.frame:
            self.session.doc.set_frame(v)

    def _frame_changed(self, f: int) -> None:
        self.spin.blockSignals(True)
        self.spin.setValue(f)
        self.spin.blockSignals(False)

    def refresh(self) -> None:
        p = self.session.project
        self.spin.blockSignals(True)
        if p is None:
            self.spin.setRange(0, 0)
            self.total.setText("/ -")
            self.ranges.setText("")
        else:
            self.spin.setRange(0, p.frame_count - 1)
            self.spin.setValue(self.session.frame)
            self.total.setText(f"/ {p.frame_count - 1}")
            a, b = p.active_range
            va, vb = p.view_range
            self.ranges.setText(f"Active {a}-{b}" + ("" if (va, vb) == (0, p.frame_count - 1) else f"  View {va}-{vb}"))
        self.spin.blockSignals(False)
        self.timebar.update()
