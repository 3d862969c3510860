"""The Continuity chart and the continuity bars of the Selected Point pane.

Both draw rows of colour over frames (see :mod:`carapost.core.continuity` for
the colours): the chart one bar per point (double-click a point to expand it
into one row per channel), the pane the selected point's bar and its channel
rows.  The whole chart is **one** :class:`pyqtgraph.ImageItem`: an RGBA image of
``rows x columns`` where row ``r`` spans y ``[r, r+1]`` (first row at the top)
and column ``c`` frames ``first + c*bin ... first + (c+1)*bin - 1``.  When the
take fits in the column budget (about twice the widget's width) the image is
the whole take at one column per frame (``bin`` 1, ``first`` 0); longer takes
are drawn for the visible frames only, binned by a power of two, and redrawn
when the view pans or zooms.  :meth:`ContinuityBars.color_at` reads a colour
back from the drawn image.  While a track runs with Update Timeline Every Frame,
the frames it has done are coloured from its live overlay
(:mod:`carapost.gui.live_preview`) before the project holds them.

Mouse: click selects the point of a row and goes to the clicked frame
(Ctrl+click toggles it in the selection), drag scrubs frames, double-click
expands / collapses a point, Alt+Shift+drag zooms to the dragged rectangle,
(Shift+)middle-drag pans, (Shift+)right-drag zooms, the wheel zooms frames,
right-click opens the Continuity context menu (Collapse All, Expand All, Fit To Data: the
action registry's items, see :mod:`carapost.gui.viewgrid`).
"""
from __future__ import annotations

import time
import weakref

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPoint, QPointF, QRectF, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QPainterPath, QPen
from PySide6.QtWidgets import QGraphicsPathItem

from ..core.continuity import C_GAP, ContinuityModel, rgba
from . import live_preview

BACKGROUND = (30, 30, 30)
ROW_PX = 15            #: initial height of a row in screen pixels (the chart shows as many as fit)
_models: "weakref.WeakKeyDictionary" = weakref.WeakKeyDictionary()


def shared_model(session) -> ContinuityModel:
    """The session's continuity cache (one for the chart(s) and the pane; emptied on every edit)."""
    m = _models.get(session)
    if m is None:
        m = _models[session] = ContinuityModel(session.project)

        def changed(m=m, s=weakref.ref(session)):
            m.set_project(s().project)
            m.invalidate()

        session.projectChanged.connect(changed)
        session.documentChanged.connect(changed)
    return m


class BarsViewBox(pg.ViewBox):
    """ViewBox of the bars: mouse handling per the module docstring."""

    def __init__(self, owner: "ContinuityBars"):
        super().__init__(invertY=True, enableMenu=False, defaultPadding=0.0)
        self.owner = owner

    def mouseClickEvent(self, ev) -> None:
        self.owner.handle_click(ev)

    def mouseDragEvent(self, ev, axis=None) -> None:
        M = Qt.KeyboardModifier
        mods = ev.modifiers()
        if ev.button() == Qt.MouseButton.LeftButton:
            ev.accept()
            if mods & M.AltModifier and mods & M.ShiftModifier:      # zoom to the dragged rectangle
                if ev.isFinish():
                    self.rbScaleBox.hide()
                    rect = QRectF(self.mapToView(ev.buttonDownPos()), self.mapToView(ev.pos())).normalized()
                    if rect.width() > 0 and rect.height() > 0:
                        self.owner.zoom_to(rect)
                else:
                    self.updateScaleBox(ev.buttonDownPos(), ev.pos())
            else:
                self.owner.scrub(self.mapToView(ev.pos()).x())
            return
        super().mouseDragEvent(ev, axis)                        # middle: pan, right: zoom

    def wheelEvent(self, ev, axis=None) -> None:
        super().wheelEvent(ev, axis=0)                          # the wheel zooms frames


def cache_axes(plot_item) -> None:
    """Keep each axis of a plot as a pixmap until it changes.

    Replaying an axis' text costs ~4 ms a paint; without the cache every repaint of the
    bars or graph (a new selected point, a frame step) paid it for axes that did not change.
    """
    from PySide6.QtWidgets import QGraphicsItem

    for name in ("left", "bottom", "right", "top"):
        ax = plot_item.getAxis(name)
        if ax is not None:
            ax.setCacheMode(QGraphicsItem.CacheMode.DeviceCoordinateCache)


class _LabelAxis(pg.AxisItem):
    """Left axis that shows one text per row (given as ticks) and no tick marks."""

    def __init__(self):
        super().__init__("left")
        self.setStyle(tickLength=0, autoExpandTextSpace=False, hideOverlappingLabels=True)
        self.setWidth(90)

    def set_labels(self, labels: list[tuple[float, str]]) -> None:
        self.setTicks([labels, []])


class ContinuityBars(pg.PlotWidget):
    """Rows of continuity colour over frames (base of the chart and the pane's bars).

    Parameters
    ----------
    session : Session
    """

    contextRequested = Signal(object, QPoint)    #: widget, global position

    def __init__(self, session, parent=None):
        self.vb = BarsViewBox(self)
        self.axis = _LabelAxis()
        super().__init__(parent, background=BACKGROUND, viewBox=self.vb, axisItems={"left": self.axis})
        self.session = session
        self.model = shared_model(session)
        self.plotItem.hideButtons()
        self.plotItem.setMenuEnabled(False)
        self.plotItem.showGrid(False, False)
        self.plotItem.getAxis("bottom").setStyle(tickLength=-4)
        cache_axes(self.plotItem)
        self.image = pg.ImageItem(axisOrder="row-major")
        self.image.setZValue(-5)
        self.vb.addItem(self.image)
        self.separators = QGraphicsPathItem()
        pen = QPen(QColor(*BACKGROUND))
        pen.setCosmetic(True)
        pen.setWidth(2)
        self.separators.setPen(pen)
        self.vb.addItem(self.separators, ignoreBounds=True)
        self.highlight = QGraphicsPathItem()
        pen = QPen(QColor(255, 255, 255))
        pen.setCosmetic(True)
        self.highlight.setPen(pen)
        self.highlight.setZValue(5)
        self.vb.addItem(self.highlight, ignoreBounds=True)
        self.marker = pg.InfiniteLine(angle=90, movable=False, pen=pg.mkPen((255, 255, 0), width=1))
        self.marker.setZValue(10)
        self.vb.addItem(self.marker, ignoreBounds=True)
        #: the drawn rows: (point id, channel) with channel -1 for the point bar
        self.rows: list[tuple[int, int]] = []
        self.first = 0           #: first frame of the image's column 0
        self.bin = 1             #: frames per image column
        self._drawn_range: tuple[int, int] | None = None
        self._dirty = True
        self._rows_dirty = True
        self._render_timer = QTimer(self)
        self._render_timer.setSingleShot(True)
        self._render_timer.setInterval(0)
        self._render_timer.timeout.connect(self._on_range)
        self.vb.sigXRangeChanged.connect(lambda *_: self._render_timer.start())
        s = session
        s.documentChanged.connect(self.on_document)
        s.projectChanged.connect(self.on_project)
        s.frameChanged.connect(self.on_frame)
        s.selectionChanged.connect(self.on_selection)
        live_preview.of(s).changed.connect(self.on_live)
        self.on_document()

    # ------------------------------------------------------------------ rows
    def build_rows(self) -> list[tuple[int, int]]:
        """The rows to show (subclasses)."""
        return []

    def row_label(self, pid: int, channel: int) -> str:
        p = self.session.project
        if channel >= 0:
            return f"Sensor {channel}"
        pt = p.points.get(pid) if p is not None else None
        return pt.name if pt is not None else ""

    def row_of(self, pid: int, channel: int = -1) -> int | None:
        """Image row of point ``pid``'s bar (``channel`` -1) or channel row; None when not shown."""
        self.ensure_drawn()
        try:
            return self.rows.index((pid, channel))
        except ValueError:
            return None

    def hit(self, x: float, y: float) -> tuple[int | None, int | None, int]:
        """``(point id, channel, frame)`` at view coordinates (None when off the rows)."""
        r = int(np.floor(y))
        f = int(np.rint(x))
        p = self.session.project
        if p is not None:
            f = p.clamp_frame(f)
        if 0 <= r < len(self.rows):
            pid, ch = self.rows[r]
            return pid, ch, f
        return None, None, f

    # --------------------------------------------------------------- drawing
    def columns(self) -> int:
        """Column budget of the image: about two per screen pixel of the plot."""
        return max(1024, 2 * int(self.vb.width() or self.width()))

    def ensure_drawn(self) -> None:
        """Bring the image up to date now (it is drawn lazily while the widget is hidden)."""
        if self._rows_dirty:
            self._rows_dirty = False
            self._dirty = True
            self.rows = self.build_rows()
            self._update_rows()
        if self._dirty:
            self.render()

    def _update_rows(self) -> None:
        """New rows: labels, separators, limits."""
        rows = self.rows
        self.axis.set_labels([(r + 0.5, self.row_label(pid, ch)) for r, (pid, ch) in enumerate(rows)])
        p = self.session.project
        F = p.frame_count if p is not None else 1
        path = QPainterPath()
        for r in range(1, len(rows)):
            if rows[r][1] < 0:                 # a new point starts
                path.moveTo(-0.5, r)
                path.lineTo(F - 0.5, r)
        self.separators.setPath(path)
        pad = max(F * 0.02, 1.0)
        self.vb.setLimits(xMin=-0.5 - pad, xMax=F - 0.5 + pad, yMin=0, yMax=max(len(rows), 1),
                          minXRange=2.0, minYRange=1.0)
        self._update_highlight()

    def render(self) -> None:
        """Redraw the image for the visible frames."""
        self._dirty = False
        p = self.session.project
        if p is None or not self.rows:
            self.image.setImage(np.zeros((1, 1, 4), np.uint8), autoLevels=False)
            self.image.setRect(QRectF(0, 0, 1, 1))
            self.image.setVisible(False)
            self._drawn_range = None
            return
        F = p.frame_count
        cols = self.columns()
        if F <= cols:
            start, stop = 0, F
        else:
            (x0, x1), _ = self.vb.viewRange()
            start = max(0, int(np.floor(x0 + 0.5)))
            stop = min(F, int(np.ceil(x1 + 0.5)) + 1)
            if stop <= start:
                start, stop = 0, F
        codes, self.bin, self.first = self.model.codes(self.rows, start, stop, cols)
        live = live_preview.existing(self.session)
        if live is not None and live.active:
            live.patch_codes(codes, self.rows, self.bin, self.first, self.model)
        img = rgba(codes)
        self._drawn_range = (start, stop)
        self.image.setImage(img, autoLevels=False, levels=None)
        self.image.setRect(QRectF(self.first - 0.5, 0, img.shape[1] * self.bin, len(self.rows)))
        self.image.setVisible(True)

    def _on_range(self) -> None:
        p = self.session.project
        if p is None or self._drawn_range is None or p.frame_count <= self.columns():
            return
        (x0, x1), _ = self.vb.viewRange()
        a, b = self._drawn_range
        n = max(x1 - x0, 1.0)
        need_bin = 1
        while -(-int(n) // need_bin) > self.columns():
            need_bin *= 2
        if x0 + 0.5 < a - 1 or x1 + 0.5 > b + 1 or need_bin != self.bin:
            if self.isVisible():
                self.render()
            else:
                self._dirty = True

    def color_at(self, pid: int, frame: int, channel: int = -1) -> tuple[int, int, int, int] | None:
        """RGBA drawn for point ``pid`` (its bar or ``channel``) at ``frame``; None when not drawn."""
        self.ensure_drawn()
        r = self.row_of(pid, channel)
        img = self.image.image
        if r is None or img is None or not self.image.isVisible():
            return None
        c = (int(frame) - self.first) // self.bin
        if not 0 <= c < img.shape[1]:
            return None
        return tuple(int(v) for v in img[r, c])

    def _update_highlight(self) -> None:
        path = QPainterPath()
        sel = set(self.session.selection.points)
        p = self.session.project
        if p is not None and sel and self.highlight_selection():
            F = p.frame_count
            for r, (pid, ch) in enumerate(self.rows):
                if ch < 0 and pid in sel:
                    path.addRect(QRectF(-0.5, r, F, 1))
        self.highlight.setPath(path)

    def highlight_selection(self) -> bool:
        return True

    # --------------------------------------------------------------- signals
    def invalidate(self, rows: bool = True) -> None:
        self._rows_dirty = self._rows_dirty or rows
        self._dirty = True
        if self.isVisible():
            self.ensure_drawn()

    def on_document(self) -> None:
        self.invalidate()
        self.home()
        self.on_frame(self.session.frame)

    def on_project(self) -> None:
        self.invalidate()

    def on_selection(self) -> None:
        self._update_highlight()

    def on_live(self) -> None:
        """A running track published frames (or its overlay went): redraw the colours."""
        self.invalidate(rows=False)

    def on_frame(self, frame: int) -> None:
        self.marker.setValue(frame)

    def showEvent(self, ev) -> None:
        super().showEvent(ev)
        self.ensure_drawn()

    def paintEvent(self, ev) -> None:
        live = live_preview.existing(self.session)
        if live is None or not live.active:
            super().paintEvent(ev)
            return
        t0 = time.perf_counter()
        super().paintEvent(ev)
        live.note_paint(time.perf_counter() - t0)      # the live overlay keeps its redraws to a budget

    def resizeEvent(self, ev) -> None:
        super().resizeEvent(ev)
        timer = getattr(self, "_render_timer", None)       # pyqtgraph resizes during __init__
        if timer is not None:
            timer.start()

    # ------------------------------------------------------------------- view
    def home(self) -> None:
        """Whole take; as many rows as fit at :data:`ROW_PX` pixels each."""
        self.ensure_drawn()
        p = self.session.project
        F = p.frame_count if p is not None else 1
        h = max(self.vb.height() or self.height(), ROW_PX)
        n = min(max(len(self.rows), 1), max(int(h // ROW_PX), 1))
        self.vb.setRange(xRange=(-0.5, F - 0.5), yRange=(0, n), padding=0)

    def zoom_to(self, rect: QRectF) -> None:
        self.vb.setRange(rect=rect, padding=0)

    def scrub(self, x: float) -> None:
        if self.session.doc is not None:
            self.session.doc.set_frame(int(np.rint(x)))

    # ------------------------------------------------------------------ mouse
    def handle_click(self, ev) -> None:
        if self.session.project is None:
            return
        if ev.button() == Qt.MouseButton.RightButton:
            ev.accept()
            self.contextRequested.emit(self, ev.screenPos().toPoint())
            return
        if ev.button() != Qt.MouseButton.LeftButton:
            return
        ev.accept()
        q = self.vb.mapToView(ev.pos())
        pid, ch, frame = self.hit(q.x(), q.y())
        if not ev.double():          # double-clicks: mouseDoubleClickEvent
            self.clicked(pid, ch, frame, ev.modifiers())

    def mouseDoubleClickEvent(self, ev) -> None:
        super().mouseDoubleClickEvent(ev)
        sc = self.scene()             # pyqtgraph queues a 'double' click that would swallow the next click
        sc.clickEvents[:] = [e for e in sc.clickEvents if not e.double()]
        if self.session.project is None or ev.button() != Qt.MouseButton.LeftButton:
            return
        q = self.vb.mapSceneToView(self.mapToScene(ev.position().toPoint()))
        if self.vb.sceneBoundingRect().contains(self.mapToScene(ev.position().toPoint())):
            self.double_clicked(*self.hit(q.x(), q.y()))

    def clicked(self, pid, ch, frame, mods) -> None:
        """Go to the clicked frame."""
        self.session.doc.set_frame(frame)

    def double_clicked(self, pid, ch, frame) -> None:
        pass

    def click_at(self, frame: float, row: float, mods=Qt.KeyboardModifier.NoModifier, double: bool = False,
                 button=Qt.MouseButton.LeftButton):
        """Click (as the mouse does) at ``frame`` on image row ``row`` (scripts and tests)."""
        from PySide6.QtTest import QTest

        self.ensure_drawn()
        pos = self.vb.mapViewToScene(QPointF(frame, row + 0.5))
        vp = self.mapFromScene(pos)
        if double:
            QTest.mouseDClick(self.viewport(), button, mods, vp)
        else:
            QTest.mouseClick(self.viewport(), button, mods, vp)


class ContinuityChart(ContinuityBars):
    """The Continuity chart: one bar per point, expandable into channel rows."""

    def __init__(self, session, parent=None):
        self.expanded: set[int] = set()
        super().__init__(session, parent)

    def build_rows(self) -> list[tuple[int, int]]:
        p = self.session.project
        if p is None:
            return []
        S = p.sensor_count
        rows = []
        for pid in p.points:
            rows.append((pid, -1))
            if pid in self.expanded:
                rows.extend((pid, ch) for ch in range(S))
        return rows

    def row_label(self, pid: int, channel: int) -> str:
        return f"   Sensor {channel}" if channel >= 0 else super().row_label(pid, channel)

    def on_document(self) -> None:
        self.expanded.clear()
        super().on_document()

    # ------------------------------------------------------------- expansion
    def set_expanded(self, pid: int, on: bool) -> None:
        (self.expanded.add if on else self.expanded.discard)(pid)
        self.invalidate()

    def toggle_expanded(self, pid: int) -> None:
        self.set_expanded(pid, pid not in self.expanded)

    def expand_all(self) -> None:
        p = self.session.project
        self.expanded = set(p.points) if p is not None else set()
        self.invalidate()

    def collapse_all(self) -> None:
        self.expanded.clear()
        self.invalidate()

    def fit_to_data(self) -> None:
        """Show the selected points' rows and frames with data (all points and the whole take when none)."""
        self.ensure_drawn()
        p = self.session.project
        if p is None or not self.rows:
            return
        sel = [pid for pid in self.session.selection.points if pid in p.points]
        F = p.frame_count
        if not sel:
            self.vb.setRange(xRange=(-0.5, F - 0.5), yRange=(0, len(self.rows)), padding=0)
            return
        rs = [r for r, (pid, _ch) in enumerate(self.rows) if pid in sel]
        has = np.zeros(F, bool)
        for pid in sel:
            has |= self.model.bar(pid) != C_GAP
        frames = np.flatnonzero(has)
        x0, x1 = (frames[0], frames[-1]) if len(frames) else (0, F - 1)
        self.vb.setRange(xRange=(x0 - 0.5, x1 + 0.5), yRange=(min(rs), max(rs) + 1), padding=0)

    # ------------------------------------------------------------------ mouse
    def clicked(self, pid, ch, frame, mods) -> None:
        if pid is not None:
            self.session.select(points=[pid], toggle=bool(mods & Qt.KeyboardModifier.ControlModifier))
        self.session.doc.set_frame(frame)

    def double_clicked(self, pid, ch, frame) -> None:
        if pid is not None:
            self.toggle_expanded(pid)


class SelectedPointBars(ContinuityBars):
    """The selected point's bar and one row per sensor (nothing unless exactly one point is selected)."""

    def __init__(self, session, parent=None):
        super().__init__(session, parent)
        self.axis.setWidth(80)

    def build_rows(self) -> list[tuple[int, int]]:
        p = self.session.project
        sel = self.session.selection.points
        if p is None or len(sel) != 1 or sel[0] not in p.points:
            return []
        pid = sel[0]
        return [(pid, -1)] + [(pid, ch) for ch in range(p.sensor_count)]

    def highlight_selection(self) -> bool:
        return False

    def on_selection(self) -> None:
        n = len(self.rows)
        self.invalidate()
        if len(self.rows) != n:
            self.fit_rows()

    def on_document(self) -> None:
        super().on_document()
        self.fit_rows()

    def fit_rows(self) -> None:
        """Keep the frames shown; fit the rows to the height."""
        if self.rows:
            (x0, x1), _ = self.vb.viewRange()
            self.vb.setRange(xRange=(x0, x1), yRange=(0, len(self.rows)), padding=0)

    def resizeEvent(self, ev) -> None:
        super().resizeEvent(ev)
        if getattr(self, "rows", None):
            self.fit_rows()

    def clicked(self, pid, ch, frame, mods) -> None:
        self.session.doc.set_frame(frame)
