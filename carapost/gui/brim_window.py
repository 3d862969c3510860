"""The Brim window (View > Show Calibration Brim SVG): the brim's markers, clickable.

It shows the imported SVG of a custom brim, or for a default brim a drawing
generated from its marker layout (:func:`carapost.io.brim_svg.brim_to_svg`),
with every marker numbered (its index: the brim definition's order, CONTRACT
section 4).  Select a marker's detection in one or more camera views on the
current frame, then click the marker: the detections are attached to it (Edit
history: "Attach To Brim Marker i").  Markers attached on the current frame are
drawn filled with the number of channels that see them; the marker of a
selected brim point is ringed in yellow.
"""
from __future__ import annotations

import logging

import numpy as np
from PySide6.QtCore import QByteArray, QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QFont, QPainter, QPen
from PySide6.QtSvg import QSvgRenderer
from PySide6.QtWidgets import QLabel, QSizePolicy, QVBoxLayout, QWidget

from ..core.brim_attach import attach_to_brim_marker, brim_attachments
from ..core.points import BRIM

log = logging.getLogger("carapost")

ATTACHED = QColor(70, 210, 90)        # the 3D view's brim colour
FREE = QColor(235, 120, 20)
SELECTED = QColor(255, 215, 0)
HOVER = QColor(40, 120, 255)
#: A click picks the nearest marker within this many widget pixels (or its drawn radius if larger).
CLICK_TOLERANCE = 10.0
_MARGIN = 24.0


class BrimCanvas(QWidget):
    """The brim drawing: markers in brim millimetres fitted into the widget, aspect kept.

    Signals
    -------
    markerClicked(int)
        A left click on (or near) a marker.
    """

    markerClicked = Signal(int)

    def __init__(self, parent=None):
        super().__init__(parent)
        self.setMouseTracking(True)
        self.setMinimumSize(320, 140)
        self.setSizePolicy(QSizePolicy.Policy.Expanding, QSizePolicy.Policy.Expanding)
        self.renderer: QSvgRenderer | None = None
        self.markers = np.zeros((0, 2))
        self.box = QRectF()
        self.radius_mm = 1.0
        #: marker index -> channels whose detection is attached on the current frame
        self.attached: dict[int, list[int]] = {}
        #: markers whose brim point is selected
        self.selected: set[int] = set()
        self.hover: int | None = None

    def set_brim(self, brim, svg: str) -> None:
        """Show ``brim`` (markers in mm) over ``svg``, whose viewBox user units are those millimetres."""
        self.renderer = QSvgRenderer(QByteArray(svg.encode("utf-8")), self)
        self.markers = np.asarray(brim.markers, float)[:, :2]
        vb = self.renderer.viewBoxF()
        lo, hi = self.markers.min(axis=0), self.markers.max(axis=0)
        # The drawing covers the viewBox and every marker, whatever the SVG's page.
        box = QRectF(QPointF(*lo), QPointF(*hi))
        self.box = box.united(vb) if vb.isValid() and not vb.isEmpty() else box.adjusted(-5, -5, 5, 5)
        d = np.linalg.norm(self.markers[:, None] - self.markers[None], axis=-1)
        np.fill_diagonal(d, np.inf)
        self.radius_mm = float(0.3 * np.min(d)) if len(self.markers) > 1 and np.isfinite(d).any() else 1.0
        self.hover = None
        self.update()

    def set_state(self, attached: dict[int, list[int]], selected: set[int]) -> None:
        self.attached, self.selected = attached, selected
        self.update()

    # ---------------------------------------------------------------- geometry
    def _scale(self) -> tuple[float, float, float]:
        """(pixels per mm, x offset, y offset) that fit the drawing box into the widget."""
        w, h = self.width() - 2 * _MARGIN, self.height() - 2 * _MARGIN
        if self.box.isEmpty() or w <= 0 or h <= 0:
            return 1.0, 0.0, 0.0
        k = min(w / self.box.width(), h / self.box.height())
        ox = _MARGIN + (w - k * self.box.width()) / 2 - k * self.box.left()
        oy = _MARGIN + (h - k * self.box.height()) / 2 - k * self.box.top()
        return k, ox, oy

    def marker_point(self, index: int) -> QPointF:
        """Where marker ``index`` is drawn, in widget coordinates."""
        k, ox, oy = self._scale()
        x, y = self.markers[index]
        return QPointF(ox + k * x, oy + k * y)

    def radius_px(self) -> float:
        return max(5.0, self.radius_mm * self._scale()[0])

    def marker_at(self, pos: QPointF) -> int | None:
        """The marker nearest widget position ``pos`` within the click tolerance."""
        if not len(self.markers):
            return None
        k, ox, oy = self._scale()
        d = np.hypot(ox + k * self.markers[:, 0] - pos.x(), oy + k * self.markers[:, 1] - pos.y())
        i = int(np.argmin(d))
        return i if d[i] <= max(CLICK_TOLERANCE, self.radius_px()) else None

    # ---------------------------------------------------------------- painting
    def paintEvent(self, _ev) -> None:
        qp = QPainter(self)
        qp.setRenderHint(QPainter.RenderHint.Antialiasing)
        qp.fillRect(self.rect(), QColor(255, 255, 255))
        if self.renderer is None:
            return
        k, ox, oy = self._scale()
        vb = self.renderer.viewBoxF()
        self.renderer.render(qp, QRectF(ox + k * vb.left(), oy + k * vb.top(), k * vb.width(), k * vb.height()))
        r = self.radius_px()
        font = QFont(self.font())
        font.setPointSizeF(max(7.0, min(11.0, r * 0.9)))
        qp.setFont(font)
        for i in range(len(self.markers)):
            c = self.marker_point(i)
            chans = self.attached.get(i, [])
            ring = HOVER if i == self.hover else (SELECTED if i in self.selected else (ATTACHED if chans else FREE))
            qp.setPen(QPen(ring, 3.0 if i in self.selected or i == self.hover else 2.0))
            qp.setBrush(ATTACHED if chans else Qt.BrushStyle.NoBrush)
            qp.drawEllipse(c, r, r)
            if chans:
                qp.setPen(QColor(0, 0, 0))
                qp.drawText(QRectF(c.x() - r, c.y() - r, 2 * r, 2 * r), Qt.AlignmentFlag.AlignCenter, str(len(chans)))
            label = QRectF(c.x() + r * 0.7, c.y() - r * 0.7 - 16, 28, 16)
            qp.setPen(QColor(20, 40, 140))
            qp.drawText(label, Qt.AlignmentFlag.AlignLeft | Qt.AlignmentFlag.AlignBottom, str(i))
        qp.end()

    # ------------------------------------------------------------------- mouse
    def mouseMoveEvent(self, ev) -> None:
        i = self.marker_at(ev.position())
        if i != self.hover:
            self.hover = i
            if i is None:
                self.setToolTip("")
            else:
                chans = self.attached.get(i, [])
                self.setToolTip(f"Brim marker {i}: " + (f"attached in channel(s) {', '.join(map(str, chans))}"
                                                         if chans else "not attached on this frame"))
            self.update()

    def leaveEvent(self, _ev) -> None:
        if self.hover is not None:
            self.hover = None
            self.update()

    def mouseReleaseEvent(self, ev) -> None:
        if ev.button() == Qt.MouseButton.LeftButton:
            i = self.marker_at(ev.position())
            if i is not None:
                self.markerClicked.emit(i)


class BrimWindow(QWidget):
    """A floating window on the session's brim: the canvas, what to do, and what is attached."""

    def __init__(self, session, parent=None):
        super().__init__(parent, Qt.WindowType.Tool)
        self.session = session
        self.setObjectName("brim_window")
        self.canvas = BrimCanvas(self)
        self.status = QLabel()
        self.status.setWordWrap(True)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(4, 4, 4, 4)
        lay.addWidget(self.canvas, 1)
        lay.addWidget(self.status)
        self.canvas.markerClicked.connect(self.attach)
        self._brim = None
        for sig in (session.documentChanged, session.projectChanged, session.selectionChanged):
            sig.connect(self.refresh)
        session.frameChanged.connect(lambda _f: self.refresh())
        self.resize(760, 320)
        self.refresh()

    def refresh(self) -> None:
        """Follow the project's brim, the current frame's attachments and the selection."""
        from ..io.brim_svg import brim_to_svg

        p = self.session.project
        brim = p.brim if p is not None else None
        if brim is None or not len(brim):
            self._brim = None
            self.canvas.renderer = None
            self.canvas.markers = np.zeros((0, 2))
            self.canvas.update()
            self.setWindowTitle("Calibration Brim")
            self.status.setText("No calibration brim: Process > Initialize Default Calibration Brim, "
                                "or File > Import Calibration Brim [svg].")
            return
        if brim is not self._brim:
            self._brim = brim
            self.canvas.set_brim(brim, brim.svg or brim_to_svg(brim))
            self.setWindowTitle(f"Calibration Brim {brim.name}")
        f = self.session.frame
        attached = brim_attachments(p, f)
        sel = self.session.selection
        selected = {p.points[i].brim_index for i in sel.points if i in p.points and p.points[i].kind == BRIM}
        self.canvas.set_state(attached, selected)
        dets = [d for d in sel.detections if d[1] == f]
        chans = sorted({d[0] for d in dets})
        todo = (f"{len(dets)} detection(s) selected in channel(s) {', '.join(map(str, chans))}: click a marker "
                "to attach them." if dets else
                "Select a marker's detection in each camera view that sees it (Ctrl+click adds), then click "
                "the marker here.")
        self.status.setText(f"Frame {f}: {len(attached)} of {len(brim)} markers attached. {todo}")

    def attach(self, index: int) -> bool:
        """Attach the selected detections of the current frame to brim marker ``index`` (one history entry)."""
        ses = self.session
        if ses.project is None:
            return False
        if ses.busy:
            ses.error(f"Attach To Brim Marker {index}: wait until the running operation finishes")
            return False
        return ses.attempt(attach_to_brim_marker, ses.project, ses.frame, index, ses.selection.detections)
