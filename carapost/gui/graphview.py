"""The Graph view: 3D (mm) and 2D (pixel) coordinates of the selected points against frame.

For each selected point: x, y, z of its 3D position (red, green, blue solid
lines) and, when the point has 2D data in the chosen sensor, its image x and y
there (red and green dashed lines): five lines, or three when the point is not
seen by that sensor.  Context menu (the action registry's Graph items, built by
:mod:`carapost.gui.viewgrid`): Fit To Data, Track Data (2D lines on/off),
Recon Data (3D lines on/off), Sensor.  Mouse: click goes to a frame,
(Shift+)middle-drag pans, (Shift+)right-drag zooms, Alt+Shift+drag zooms to a
rectangle, the wheel zooms.
"""
from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPoint, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QPainterPath, QPen
from PySide6.QtWidgets import QGraphicsPathItem
from .continuity import cache_axes

AXIS_COLORS = ((230, 50, 50), (50, 210, 50), (70, 120, 255))   #: x, y, z


class GraphViewBox(pg.ViewBox):
    def __init__(self, owner: "GraphView"):
        super().__init__(enableMenu=False)
        self.owner = owner

    def mouseClickEvent(self, ev) -> None:
        o = self.owner
        if ev.button() == Qt.MouseButton.RightButton:
            ev.accept()
            o.contextRequested.emit(o, ev.screenPos().toPoint())
        elif ev.button() == Qt.MouseButton.LeftButton and o.session.doc is not None:
            ev.accept()
            o.session.doc.set_frame(int(np.rint(self.mapToView(ev.pos()).x())))

    def mouseDragEvent(self, ev, axis=None) -> None:
        M = Qt.KeyboardModifier
        if ev.button() == Qt.MouseButton.LeftButton:
            ev.accept()
            if ev.modifiers() & M.AltModifier and ev.modifiers() & M.ShiftModifier:
                if ev.isFinish():
                    self.rbScaleBox.hide()
                    r = QRectF(self.mapToView(ev.buttonDownPos()), self.mapToView(ev.pos())).normalized()
                    if r.width() > 0 and r.height() > 0:
                        self.setRange(rect=r, padding=0)
                else:
                    self.updateScaleBox(ev.buttonDownPos(), ev.pos())
            elif self.owner.session.doc is not None:
                self.owner.session.doc.set_frame(int(np.rint(self.mapToView(ev.pos()).x())))
            return
        super().mouseDragEvent(ev, axis)           # middle pans, right zooms (with or without Shift)


class GraphView(pg.PlotWidget):
    """Coordinates of the selected points in one sensor.

    Parameters
    ----------
    session : Session
    sensor : int
        The sensor whose 2D data is drawn (the context menu's Sensor submenu changes it).
    """

    contextRequested = Signal(object, QPoint)

    def __init__(self, session, sensor: int = 0, parent=None):
        self.vb = GraphViewBox(self)
        super().__init__(parent, background=(30, 30, 30), viewBox=self.vb)
        self.session = session
        self.sensor = int(sensor)
        self.track_data = True      #: 2D lines
        self.recon_data = True      #: 3D lines
        self.plotItem.hideButtons()
        self.plotItem.setMenuEnabled(False)
        # One path for the whole grid: the axes' own grid (a line each, replayed from their pictures)
        # cost ~20 ms a change of range, most of a selected-point switch on a long take.
        self.grid = QGraphicsPathItem()
        pen = QPen(QColor(255, 255, 255, 38))
        pen.setCosmetic(True)
        self.grid.setPen(pen)
        self.grid.setZValue(-10)
        self.vb.addItem(self.grid, ignoreBounds=True)
        self.vb.sigRangeChanged.connect(self._update_grid)
        self.vb.sigResized.connect(self._update_grid)
        self.plotItem.setLabel("bottom", "frame")
        self.plotItem.setLabel("left", "mm / px")
        cache_axes(self.plotItem)
        self.plotItem.setClipToView(True)
        self.plotItem.setDownsampling(auto=True, mode="peak")
        self.marker = pg.InfiniteLine(angle=90, movable=False, pen=pg.mkPen((255, 255, 0)))
        self.marker.setZValue(10)
        self.vb.addItem(self.marker, ignoreBounds=True)
        self.curves: list[pg.PlotDataItem] = []     # pool; the first len(self.lines) are shown
        #: what is drawn: (point id, "x"|"y"|"z"|"u"|"v") per shown curve
        self.lines: list[tuple[int, str]] = []
        self._dirty = True
        self._fit_pending = True
        s = session
        s.documentChanged.connect(self.on_document)
        s.projectChanged.connect(self.invalidate)
        s.selectionChanged.connect(self.on_selection)
        s.frameChanged.connect(self.on_frame)
        self.on_document()

    def _update_grid(self, *_) -> None:
        """Grid lines at the axes' major ticks of the visible range."""
        (x0, x1), (y0, y1) = self.vb.viewRange()
        path = QPainterPath()
        for axis, (lo, hi), vertical in ((self.plotItem.getAxis("bottom"), (x0, x1), True),
                                         (self.plotItem.getAxis("left"), (y0, y1), False)):
            size = axis.geometry().width() if vertical else axis.geometry().height()
            levels = axis.tickValues(lo, hi, max(float(size), 1.0))
            for v in (levels[0][1] if levels else []):
                if vertical:
                    path.moveTo(v, y0)
                    path.lineTo(v, y1)
                else:
                    path.moveTo(x0, v)
                    path.lineTo(x1, v)
        self.grid.setPath(path)

    # ------------------------------------------------------------------ state
    def set_sensor(self, sensor: int) -> None:
        self.sensor = int(sensor)
        self.invalidate()

    def set_track_data(self, on: bool) -> None:
        self.track_data = bool(on)
        self.invalidate()

    def set_recon_data(self, on: bool) -> None:
        self.recon_data = bool(on)
        self.invalidate()

    def on_document(self) -> None:
        p = self.session.project
        if p is not None and self.sensor >= p.sensor_count:
            self.sensor = 0
        self.marker.setValue(self.session.frame)
        self._fit_pending = True
        self.invalidate()

    def on_frame(self, frame: int) -> None:
        self.marker.setValue(frame)

    def on_selection(self) -> None:
        self._fit_pending = True
        self.invalidate()

    def invalidate(self) -> None:
        self._dirty = True
        if self.isVisible():
            self.ensure_drawn()

    def showEvent(self, ev) -> None:
        super().showEvent(ev)
        self.ensure_drawn()

    # ---------------------------------------------------------------- drawing
    def ensure_drawn(self) -> None:
        if self._dirty:
            self.redraw()

    def _curve(self, i: int) -> pg.PlotDataItem:
        while len(self.curves) <= i:
            # Long takes: draw at most a few points per pixel column (peaks kept) and only the visible span.
            c = pg.PlotDataItem(connect="finite", skipFiniteCheck=True, autoDownsample=True, downsampleMethod="peak",
                                clipToView=True)
            self.plotItem.addItem(c)
            self.curves.append(c)
        return self.curves[i]

    def redraw(self) -> None:
        """Draw the lines of the selected points."""
        self._dirty = False
        p = self.session.project
        lines: list[tuple[int, str, np.ndarray, tuple, Qt.PenStyle]] = []
        if p is not None:
            frames = None
            for pid in self.session.selection.points:
                pt = p.points.get(pid)
                if pt is None:
                    continue
                if self.recon_data:
                    for k, name in enumerate("xyz"):
                        lines.append((pid, name, pt.pos[:, k], AXIS_COLORS[k], Qt.PenStyle.SolidLine))
                if self.track_data and 0 <= self.sensor < p.sensor_count:
                    uv = pt.uv[:, self.sensor]
                    if np.isfinite(uv[:, 0]).any():
                        for k, name in enumerate("uv"):
                            lines.append((pid, name, uv[:, k], AXIS_COLORS[k], Qt.PenStyle.DashLine))
            if lines:
                frames = np.arange(p.frame_count, dtype=np.float64)
        for i, (pid, name, y, color, style) in enumerate(lines):
            c = self._curve(i)
            c.setData(frames, y, connect="finite", pen=pg.mkPen(color, width=1, style=style))
            c.setVisible(True)
        for c in self.curves[len(lines):]:
            if c.isVisible():
                c.setData([], [])
                c.setVisible(False)
        self.lines = [(pid, name) for pid, name, *_ in lines]
        if self._fit_pending and lines:
            self._fit_pending = False
            self.fit_to_data()

    def fit_to_data(self) -> None:
        """Zoom to the data of the selected points (nothing selected: no change)."""
        self.ensure_drawn()
        shown = [c for c in self.curves[:len(self.lines)]]
        if not shown:
            return
        lo, hi, f0, f1 = np.inf, -np.inf, np.inf, -np.inf
        for c in shown:
            x, y = c.xData, c.yData
            if y is None:
                continue
            ok = np.flatnonzero(np.isfinite(y))
            if len(ok):
                v = y[ok]
                lo, hi = min(lo, float(v.min())), max(hi, float(v.max()))
                f0, f1 = min(f0, float(x[ok[0]])), max(f1, float(x[ok[-1]]))
        if not np.isfinite(lo):
            return
        pad = max((hi - lo) * 0.05, 1.0)
        self.vb.setRange(xRange=(f0, max(f1, f0 + 1)), yRange=(lo - pad, hi + pad), padding=0.02)
