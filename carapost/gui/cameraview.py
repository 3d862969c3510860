"""A camera view: one sensor's image with its detections, points and projections.

Coordinates: items live in *raw image pixels* (pixel column c, row r is centred
on (c, r)) inside a ``content`` group whose transform is the sensor's display
rotation; the pyqtgraph ViewBox shows that group with y down and a locked
aspect.  Mouse bindings are the guide's: click / Ctrl+click / drag rectangle /
Shift+Alt lasso select, Shift+click selects the sensor, Shift+right-drag
zooms, (Shift+)middle-drag pans, the wheel zooms, right-click opens the 2D
context menu.
"""
from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPoint, QPointF, QRectF, Qt, QTimer, Signal
from PySide6.QtGui import QColor, QPainterPath, QPalette, QPen, QTransform
from PySide6.QtWidgets import QFrame, QGraphicsItem, QGraphicsRectItem, QGraphicsSimpleTextItem

from ..core.points import SRC_DETECTION, SRC_KEYFRAME, SRC_NONE, SRC_TARGET
from . import blobpreview, keyframe_handles, picking
from .overlays import (GreyImageItem, HudItem, LabelsItem, boxes, checker_brush, circles, combine, crosses,
                       ellipses, finite, path_item, segments, segments_item, xs)

COLORS = {
    "detection": (255, 45, 45), "point": (60, 150, 255), "connected": (255, 230, 0), "unconnected": (255, 140, 0),
    "error": (255, 230, 0), "selected": (255, 255, 255), "hover": (0, 255, 255), "selected_detection": (90, 255, 90),
    "preview": (255, 0, 255), "keycircle": (255, 230, 0), "measure": (0, 255, 140), "border": (150, 150, 150),
    "keyregion": (60, 230, 60), "keyhandle": (255, 255, 255),
}
#: Screen-pixel sizes of markers that keep their size at any zoom: a projection's circle sits
#: inside the point's ring, which sits outside its detection's ellipse, so all three show.
PROJ_R = 4.0       #: connected / unconnected projection circle
RING_PAD = 4.0     #: point ring beyond its detection's ellipse
POINT_R = 7.0      #: point ring without a detection (patch, target)
SELECT_R = 11.0    #: selection highlight
HOVER_R = 14.0     #: pre-selection highlight
PICK_TOLERANCE = picking.PICK_TOLERANCE


class SensorViewBox(pg.ViewBox):
    """ViewBox whose mouse handling is the guide's (see the module docstring)."""

    def __init__(self, view: "CameraView"):
        super().__init__(lockAspect=True, invertY=True, enableMenu=False, defaultPadding=0.02)
        self.view = view

    def mouseClickEvent(self, ev) -> None:
        self.view.handle_click(ev)

    def mouseDragEvent(self, ev, axis=None) -> None:
        if not self.view.handle_drag(ev):
            super().mouseDragEvent(ev, axis)

    def hoverEvent(self, ev) -> None:
        self.view.handle_hover(ev)


class CameraView(pg.GraphicsView):
    """One sensor of the take.

    Parameters
    ----------
    session : Session
    sensor : int
        The channel shown (the context menu's Sensor submenu changes it).
    """

    sensorClicked = Signal(int, bool)            #: sensor, Ctrl held (Shift+click)
    contextRequested = Signal(object, QPoint)    #: view, global position
    targetClicked = Signal(int, float, float)    #: sensor, raw x, y (Add/Edit Target Track mode)
    activated = Signal(int)                      #: sensor of a view clicked

    def __init__(self, session, sensor: int = 0, parent=None):
        super().__init__(parent, background=(40, 40, 40))
        self.session = session
        self.sensor = int(sensor)
        self.vb = SensorViewBox(self)
        self.setCentralItem(self.vb)
        self.setFocusPolicy(Qt.FocusPolicy.ClickFocus)
        self.content = pg.ItemGroup()
        self.vb.addItem(self.content)
        self.content.setFlag(QGraphicsItem.GraphicsItemFlag.ItemHasNoContents, True)

        self.checker = QGraphicsRectItem(self.content)
        self.checker.setBrush(checker_brush())
        self.checker.setPen(QPen(Qt.PenStyle.NoPen))
        self.checker.setZValue(-2)
        self.image = GreyImageItem(self.content)
        self.image.setZValue(-1)
        self.border = path_item(self.content, COLORS["border"], 1.0, z=0)
        # Bulk markers use 1-pixel cosmetic pens: Qt strokes those as plain lines, while wider
        # pens go through the path stroker (4 ms for 160 ellipses instead of 0.5 ms).
        self.items = {
            "detections": segments_item(self.content, COLORS["detection"], 1, z=10),
            "preview": segments_item(self.content, COLORS["preview"], 1, z=11, dashed=True),
            "errors": segments_item(self.content, COLORS["error"], 1, z=13),
            "rings": segments_item(self.content, COLORS["point"], 1, z=14),
            "targets": segments_item(self.content, COLORS["point"], 1, z=14, dashed=True),
            "keycircles": segments_item(self.content, COLORS["keycircle"], 1, z=15, dashed=True),
            "connected": segments_item(self.content, COLORS["connected"], 1, z=16),
            "unconnected": segments_item(self.content, COLORS["unconnected"], 1, z=16),
            "selected_detections": segments_item(self.content, COLORS["selected_detection"], 2, z=20),
            "selected": segments_item(self.content, COLORS["selected"], 2, z=21),
            "selected_sticks": segments_item(self.content, COLORS["selected"], 2, z=21),
            "hover": segments_item(self.content, COLORS["hover"], 2, z=22),
            # The selected keyframe: its pattern box, comparison region and handles (keyframe_handles).
            "keybox": segments_item(self.content, COLORS["point"], 1, z=23),
            "keyregion": segments_item(self.content, COLORS["keyregion"], 1, z=23),
            "keyhandles": segments_item(self.content, COLORS["keyhandle"], 1, z=24),
            "measure": segments_item(self.content, COLORS["measure"], 2, z=40),
        }
        self.stick_items: dict[tuple, object] = {}
        self.labels = LabelsItem(self.content)
        self.labels.setZValue(30)
        self.measure_text = QGraphicsSimpleTextItem(self.content)
        self.measure_text.setBrush(QColor(*COLORS["measure"]))
        self.measure_text.setFlag(QGraphicsItem.GraphicsItemFlag.ItemIgnoresTransformations, True)
        self.measure_text.setZValue(41)
        # Rubber band and lasso live in view coordinates (not rotated).
        self.band = path_item(None, (255, 255, 255), 1.0, z=50, dashed=True)
        self.vb.addItem(self.band, ignoreBounds=True)

        # The scene paints every pixel: an opaque viewport spares Qt repainting the window behind it.
        self.viewport().setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent, True)
        self.setFrameShape(QFrame.Shape.Box)
        self.setFrameShadow(QFrame.Shadow.Plain)      # drawn in the palette colour set below
        self.setLineWidth(2)
        self.info = HudItem()          # scene coordinates are viewport pixels: top-left corner
        self.scene().addItem(self.info)
        self.info.setPos(4, 4)

        self.measuring = False
        self._measure_line = None
        self._region: picking.RegionDrag | None = None
        #: A keyframe handle being dragged: (target, handle kind, the box so far).
        self._key_drag: tuple | None = None
        self._pixel_text = ""
        self._preview_failed = False
        self._border = ""
        self._sensor_size = (0, 0)
        self._bounds = QRectF()          # where any overlay may be (the image and a margin)
        self._rotation = -1
        self._flash = QTimer(self)
        self._flash.setInterval(300)
        self._flash.timeout.connect(lambda: self.items["hover"].setVisible(not self.items["hover"].isVisible()))
        self._rerender = QTimer(self)
        self._rerender.setSingleShot(True)
        self._rerender.setInterval(0)
        self._rerender.timeout.connect(self.refresh_overlays)
        self.vb.sigRangeChanged.connect(lambda *_: self._rerender.start())
        self.refresh()

    # ================================================================ geometry
    def set_sensor(self, sensor: int) -> None:
        """Show channel ``sensor`` (fitted to the view)."""
        self.sensor = int(sensor)
        self._rotation = -1        # forces the geometry (and the fit) to be redone
        self.refresh()

    def raw_to_view(self, xy: np.ndarray) -> np.ndarray:
        """Raw pixels (N, 2) to view coordinates (the rotation of the sensor)."""
        t = self.content.transform()
        xy = np.asarray(xy, float).reshape(-1, 2)
        return np.stack([t.m11() * xy[:, 0] + t.m21() * xy[:, 1] + t.dx(),
                         t.m12() * xy[:, 0] + t.m22() * xy[:, 1] + t.dy()], axis=1)

    def view_to_raw(self, p: QPointF) -> tuple[float, float]:
        q = self.content.mapFromParent(p)
        return q.x(), q.y()

    def raw_to_viewport(self, x: float, y: float) -> QPoint:
        """Widget position of raw pixel (x, y) in this view's viewport (tests click there)."""
        return self.mapFromScene(self.content.mapToScene(QPointF(x, y)))

    def pixel_size(self) -> float:
        """Raw pixels per screen pixel at the current zoom."""
        px = self.vb.viewPixelSize()
        return float(max(px[0], px[1])) or 1.0

    def image_rect(self) -> QRectF:
        w, h = self._sensor_size
        return QRectF(-0.5, -0.5, max(w, 1), max(h, 1))

    def fit(self) -> None:
        """Fit To Window."""
        self.vb.setRange(rect=self.content.mapRectToParent(self.image_rect()), padding=0.02)

    def actual_size(self) -> None:
        """Actual Size: one image pixel per screen pixel, about the current centre."""
        c = self.vb.viewRect().center()
        w, h = self.vb.width(), self.vb.height()
        self.vb.setRange(rect=QRectF(c.x() - w / 2, c.y() - h / 2, w, h), padding=0)

    def center_on(self, xy: np.ndarray) -> bool:
        """Centre the view on raw points ``xy`` (N, 2); False when there are none."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        xy = xy[finite(xy)]
        if not len(xy):
            return False
        c = self.raw_to_view(xy).mean(axis=0)
        r = self.vb.viewRect()
        self.vb.setRange(rect=QRectF(c[0] - r.width() / 2, c[1] - r.height() / 2, r.width(), r.height()),
                         padding=0)
        return True

    def frame_on(self, xy: np.ndarray, margin: float = 40.0) -> bool:
        """Zoom onto raw points ``xy`` with ``margin`` raw pixels around them."""
        xy = np.asarray(xy, float).reshape(-1, 2)
        xy = xy[finite(xy)]
        if not len(xy):
            return False
        v = self.raw_to_view(xy)
        lo, hi = v.min(axis=0) - margin, v.max(axis=0) + margin
        self.vb.setRange(rect=QRectF(lo[0], lo[1], hi[0] - lo[0], hi[1] - lo[1]), padding=0)
        return True

    # ================================================================= drawing
    def refresh(self) -> None:
        """Redraw everything for the current frame (frame change, edit)."""
        self._sync_geometry()
        self.refresh_image()
        self.refresh_overlays()

    def _sync_geometry(self) -> None:
        p = self.session.project
        if p is None or self.sensor >= p.sensor_count:
            self._sensor_size = (0, 0)
            return
        s = p.sensors[self.sensor]
        size = (int(s.width), int(s.height))
        if size != self._sensor_size or s.rotation != self._rotation:
            self._sensor_size, self._rotation = size, s.rotation
            self.content.setTransform(QTransform().rotate(90 * s.rotation))
            rect = self.image_rect()
            self.checker.setRect(rect)
            path = QPainterPath()
            path.addRect(rect)
            self.border.setPath(path)
            margin = max(size) * 0.5
            bounds = self._bounds = rect.adjusted(-margin, -margin, margin, margin)
            self.labels.set_labels(np.zeros((0, 2)), [], [], 10, bounds)
            for it in list(self.items.values()) + list(self.stick_items.values()):
                it.set_bounds(bounds)
            self.fit()

    def refresh_image(self) -> None:
        """The channel image of the current frame (or the checkerboard / grey)."""
        ses, d = self.session, self.session.display
        shown = False
        if ses.project is not None and d.image and self.sensor < ses.project.sensor_count:
            arr = ses.loader.image(self.sensor, ses.frame)
            if arr is not None:
                self.image.set_image(arr)
                shown = True
            elif ses.loader.media_index(self.sensor, ses.frame) is not None:
                shown = self.image.image() is not None   # decoding: keep the last image until it arrives
        self.image.setVisible(shown)
        self.checker.setVisible(not shown and d.border and ses.project is not None)
        self.border.setVisible(ses.project is not None)

    def refresh_overlays(self) -> None:
        """Detections, points, projections, errors, sticks and the selection layers."""
        ses = self.session
        p, fd = ses.project, ses.frame_data()
        items = self.items
        for name, it in items.items():
            if name != "measure":       # the measurement stays until cleared
                it.clear()
        for it in self.stick_items.values():
            it.clear()
        if p is None or fd is None or self.sensor >= p.sensor_count:
            self.labels.set_labels(np.zeros((0, 2)), [], [], 10, self._bounds)
            self._update_info()
            return
        s, f, d = self.sensor, ses.frame, ses.display
        px = self.pixel_size()
        rec = p.detections[s].frame(f)
        if d.detections and len(rec):
            x, y = rec["x"].astype(float), rec["y"].astype(float)
            a, b = rec["major"].astype(float) / 2, rec["minor"].astype(float) / 2
            items["detections"].set_shapes(combine(ellipses(x, y, a, b, rec["angle"].astype(float)),
                                                   crosses(x, y, np.minimum(b, 3 * px) * 0.8)))
        src, uv = fd.src[:, s], fd.uv[:, s]
        has = (src != SRC_NONE) & finite(uv)
        if d.points and has.any():
            self._draw_points(rec, fd, src, uv, has, px)
        if d.projections and len(src):
            pr = fd.proj[:, s]
            okp = finite(pr)
            con, unc = okp & has, okp & (src == SRC_NONE)
            r = PROJ_R * px
            if d.connected and con.any():
                cx, cy = pr[con, 0], pr[con, 1]
                items["connected"].set_shapes(combine(circles(cx, cy, r), crosses(cx, cy, 0.7 * r)))
            if d.unconnected and unc.any():
                ux, uy = pr[unc, 0], pr[unc, 1]
                items["unconnected"].set_shapes(combine(circles(ux, uy, r), xs(ux, uy, 0.5 * r)))
            if d.errors and con.any():
                items["errors"].set_shapes(segments(pr[con, 0], pr[con, 1], uv[con, 0], uv[con, 1]))
        if d.sticks and p.sticks:
            self._draw_sticks(p, fd)
        if d.blob_preview:
            self._draw_preview()
        self.refresh_selection()

    def _draw_points(self, rec, fd, src, uv, has, px) -> None:
        """Blue rings on attached detections (or of fixed size), target tracks and keyframe boxes."""
        s, items = self.sensor, self.items
        det = fd.det[:, s]
        on_det = has & (src == SRC_DETECTION) & (det >= 0) & (det < len(rec))
        rings = []
        if on_det.any():
            r = rec[det[on_det]]
            rings.append(ellipses(uv[on_det, 0], uv[on_det, 1], r["major"].astype(float) / 2 + RING_PAD * px,
                                  r["minor"].astype(float) / 2 + RING_PAD * px, r["angle"].astype(float)))
        other = has & ~on_det & (src != SRC_TARGET) & (src != SRC_KEYFRAME)
        if other.any():
            rings.append(circles(uv[other, 0], uv[other, 1], POINT_R * px))
        items["rings"].set_shapes(combine(*rings))
        tgt = has & (src == SRC_TARGET)
        key = np.flatnonzero(has & (src == SRC_KEYFRAME))
        if tgt.any() or len(key):
            box = np.array([fd.keyboxes.get((r, s), (8.0, 8.0, 16.0, 16.0)) for r in key], float).reshape(-1, 4)
            items["targets"].set_shapes(combine(circles(uv[tgt, 0], uv[tgt, 1], POINT_R * px),
                                                boxes(uv[key, 0], uv[key, 1], box[:, 0], box[:, 1])))
            items["keycircles"].set_shapes(circles(uv[key, 0], uv[key, 1], PROJ_R * px))

    def _stick_segments(self, p, fd, which):
        """Segments of sticks ``which`` (indices) in this view."""
        which = [k for k in which if k < len(p.sticks)]
        if not which:
            return segments([], [], [], [])
        xy = fd.position_2d(self.sensor)
        row = {int(pid): i for i, pid in enumerate(fd.ids)}
        pairs = [(row[p.sticks[k].a], row[p.sticks[k].b]) for k in which
                 if p.sticks[k].a in row and p.sticks[k].b in row]
        a = xy[[i for i, _ in pairs]].reshape(-1, 2)
        b = xy[[j for _, j in pairs]].reshape(-1, 2)
        ok = finite(a) & finite(b)
        return segments(a[ok, 0], a[ok, 1], b[ok, 0], b[ok, 1])

    def _draw_sticks(self, p, fd) -> None:
        xy = fd.position_2d(self.sensor)
        row = {int(pid): i for i, pid in enumerate(fd.ids)}
        groups: dict[tuple, list] = {}
        for st in p.sticks:
            ra, rb = row.get(st.a), row.get(st.b)
            if ra is None or rb is None:
                continue
            groups.setdefault(tuple(st.color), []).append((ra, rb))
        for color, pairs in groups.items():
            item = self.stick_items.get(color)
            if item is None:
                item = self.stick_items[color] = segments_item(self.content, color, 1, z=12)
                item.set_bounds(self._bounds)
            a = xy[[i for i, _ in pairs]]
            b = xy[[j for _, j in pairs]]
            ok = finite(a) & finite(b)
            item.set_shapes(segments(a[ok, 0], a[ok, 1], b[ok, 0], b[ok, 1]))

    def _draw_preview(self) -> None:
        fn = blobpreview.get_preview()
        img = self.image.image() if self.image.isVisible() else None
        if fn is None or img is None:
            return
        try:
            rec = fn(img, self.session.project.properties)
        except Exception as e:  # noqa: BLE001 - a failing preview must not break drawing
            if not self._preview_failed:
                self._preview_failed = True
                import logging

                logging.getLogger("carapost").error(f"blob preview failed: {e}")
            return
        if len(rec):
            self.items["preview"].set_shapes(ellipses(
                rec["x"].astype(float), rec["y"].astype(float), rec["major"].astype(float) / 2 + 1,
                rec["minor"].astype(float) / 2 + 1, rec["angle"].astype(float)))

    def refresh_selection(self) -> None:
        """Selection highlights, pre-selection (hover) and labels."""
        ses = self.session
        p, fd = ses.project, ses.frame_data()
        if p is None or fd is None or self.sensor >= p.sensor_count:
            return
        s, f, px = self.sensor, ses.frame, self.pixel_size()
        xy = fd.position_2d(s)
        sel = ses.selection
        rows = [fd.row_of(pid) for pid in sel.points]
        rows = [r for r in rows if r >= 0]
        sxy = xy[rows] if rows else np.zeros((0, 2))
        ok = finite(sxy)
        self.items["selected"].set_shapes(circles(sxy[ok, 0], sxy[ok, 1], SELECT_R * px))
        self.items["selected_sticks"].set_shapes(self._stick_segments(p, fd, sel.sticks))
        rec = p.detections[s].frame(f)
        dsel = [i for (ds, df, i) in sel.detections if ds == s and df == f and i < len(rec)]
        if dsel:
            r = rec[dsel]
            self.items["selected_detections"].set_shapes(ellipses(
                r["x"].astype(float), r["y"].astype(float), r["major"].astype(float) / 2 + 3 * px,
                r["minor"].astype(float) / 2 + 3 * px, r["angle"].astype(float)))
        else:
            self.items["selected_detections"].clear()
        hover_row = -1
        hv = ses.hover
        hover = combine()
        if hv is not None and hv[0] == "point":
            hover_row = fd.row_of(hv[1])
            if hover_row >= 0 and np.all(np.isfinite(xy[hover_row])):
                hover = circles([xy[hover_row, 0]], [xy[hover_row, 1]], HOVER_R * px)
        elif hv is not None and hv[0] == "detection" and hv[1][0] == s and hv[1][1] == f and hv[1][2] < len(rec):
            r = rec[hv[1][2]]
            hover = ellipses([float(r["x"])], [float(r["y"])], [float(r["major"]) / 2 + 4 * px],
                             [float(r["minor"]) / 2 + 4 * px], [float(r["angle"])])
        self.items["hover"].set_shapes(hover)
        if not len(hover[0]):
            self._flash.stop()
            self.items["hover"].setVisible(True)
        elif not self._flash.isActive():
            self._flash.start()
        self._draw_labels(p, fd, xy, set(rows), hover_row)
        self._draw_key_handles()
        self._update_info()

    def _draw_key_handles(self) -> None:
        """The selected point's keyframe in this view: pattern box, comparison region and handles."""
        t = keyframe_handles.selected_keyframe(self.session, self.sensor)
        if self._key_drag is not None and t is not None and self._key_drag[0].pid == t.pid:
            box = self._key_drag[2]
        elif t is not None:
            box = t.box
        else:
            for name in ("keybox", "keyregion", "keyhandles"):
                self.items[name].clear()
            return
        region, squares = keyframe_handles.shapes(t, box, self.pixel_size())
        self.items["keybox"].set_shapes(boxes([t.x], [t.y], box[0], box[1]))
        self.items["keyregion"].set_shapes(region)
        self.items["keyhandles"].set_shapes(squares)

    def key_handle_at(self, x: float, y: float) -> str | None:
        """The selected keyframe's handle at raw (x, y) in this view (:mod:`.keyframe_handles`), or None."""
        return self._key_handle(keyframe_handles.selected_keyframe(self.session, self.sensor), x, y)

    def _key_handle(self, t, x: float, y: float) -> str | None:
        """The handle of keyframe ``t`` (None: no keyframe) within grabbing reach of raw (x, y), or None."""
        return None if t is None else keyframe_handles.grab(t, x, y, keyframe_handles.GRAB * self.pixel_size())

    def _drag_key_handle(self, ev, start: QPointF, now: QPointF) -> bool:
        """A drag that took a keyframe handle: the box follows; on release, Edit Keyframe Box (one command)."""
        from ..core.target_ops import set_keyframe_box

        if ev.isStart():
            t = keyframe_handles.selected_keyframe(self.session, self.sensor)
            kind = self._key_handle(t, *self.view_to_raw(start))
            self._key_drag = None if kind is None else (t, kind, t.box)
        if self._key_drag is None:
            return False
        t, kind, _ = self._key_drag
        x, y = self.view_to_raw(now)
        box = keyframe_handles.resized(t.box, kind, x - t.x, y - t.y)
        self._key_drag = (t, kind, box)
        if ev.isFinish():
            self._key_drag = None
            if box != t.box:
                self.session.attempt(set_keyframe_box, self.session.project, t.pid, t.frame, [t.sensor], box)
        self._draw_key_handles()
        return True

    def _draw_labels(self, p, fd, xy, sel_rows: set, hover_row: int) -> None:
        props = p.properties
        want = [r for r in picking.label_rows(props, fd.labels, sel_rows, hover_row) if np.all(np.isfinite(xy[r]))]
        colors = [QColor(255, 255, 255) if r in sel_rows else QColor(0, 255, 255) if r == hover_row
                  else QColor(230, 230, 150) for r in want]
        self.labels.set_labels(xy[want] if want else np.zeros((0, 2)), [fd.labels[r] for r in want], colors,
                               props["display.font_size"], self._bounds)

    def refresh_info(self) -> None:
        """The channel name, mode and pixel report, and the frame's colour (active / selected channel)."""
        self._update_info()

    def _update_info(self) -> None:
        ses = self.session
        lines = []
        p = ses.project
        if p is not None and self.sensor < p.sensor_count:
            name = p.sensors[self.sensor].name
            selected = self.sensor in p.channel_selection
            lines.append(name + ("  [selected]" if selected else ""))
            if ses.click_mode == "add":
                lines.append("Add Target Track")
            elif ses.click_mode == "edit":
                lines.append("Edit Target Track")
            if self.measuring:
                lines.append("Measurement: drag a line")
            if ses.display.pixel_report and self._pixel_text:
                lines.append(self._pixel_text)
            if ses.display.blob_preview:
                if blobpreview.get_preview() is None:
                    lines.append(f"Blob preview: {blobpreview.NOT_AVAILABLE}")
                elif not self.image.isVisible():
                    lines.append("Blob preview: needs the image")
            if not ses.loader.has_media(self.sensor) and ses.display.image:
                lines.append("(no media)")
            border = "#ffd84a" if selected else ("#4a90ff" if ses.active_sensor == self.sensor else "#303030")
            if border != self._border:   # the frame colour: yellow for a selected channel, blue for the active view
                self._border = border
                pal = self.palette()
                pal.setColor(QPalette.ColorRole.WindowText, QColor(border))
                self.setPalette(pal)
        text = "\n".join(lines)
        self.info.setText(text)

    # ================================================================= picking
    def candidates(self):
        """Selectable things in this view: ``[(kind, key, x, y)]`` as arrays (raw pixels)."""
        ses = self.session
        p, fd = ses.project, ses.frame_data()
        kinds, keys, pts = [], [], []
        props = p.properties
        s, f = self.sensor, ses.frame
        if props["selection.points"]:
            xy = fd.position_2d(s)
            ok = finite(xy)
            for r in np.flatnonzero(ok):
                kinds.append("point")
                keys.append(int(fd.ids[r]))
                pts.append(xy[r])
        if props["selection.detections"]:
            rec = p.detections[s].frame(f)
            owner = fd.attached(s)
            for i in range(len(rec)):
                if i in owner and props["selection.points"]:
                    continue   # an attached detection is picked as its point
                kinds.append("detection")
                keys.append((s, f, i))
                pts.append((float(rec["x"][i]), float(rec["y"][i])))
        return kinds, keys, np.array(pts, float).reshape(-1, 2)

    def pick(self, x: float, y: float):
        """The thing nearest raw (x, y) within the pick tolerance: ``("point", id)``, ``("detection", key)`` or None."""
        if self.session.project is None:
            return None
        kinds, keys, xy = self.candidates()
        return picking.nearest(kinds, keys, xy, x, y, PICK_TOLERANCE * self.pixel_size())

    def pick_stick(self, x: float, y: float) -> int | None:
        """Index of the stick nearest raw (x, y) within the tolerance."""
        p, fd = self.session.project, self.session.frame_data()
        if not p.sticks or not p.properties["selection.sticks"]:
            return None
        xy = fd.position_2d(self.sensor)
        row = {int(pid): i for i, pid in enumerate(fd.ids)}
        ks = [k for k, st in enumerate(p.sticks) if st.a in row and st.b in row]
        a = xy[[row[p.sticks[k].a] for k in ks]]
        b = xy[[row[p.sticks[k].b] for k in ks]]
        i = picking.nearest_segment(a, b, x, y, PICK_TOLERANCE * self.pixel_size())
        return None if i is None else ks[i]

    # =================================================================== mouse
    def _raw_of(self, ev_pos) -> tuple[float, float]:
        return self.view_to_raw(self.vb.mapToView(ev_pos))

    def handle_click(self, ev) -> None:
        ses = self.session
        btn, mods = ev.button(), ev.modifiers()
        M = Qt.KeyboardModifier
        if ses.project is None:
            return
        if btn == Qt.MouseButton.RightButton:
            ev.accept()
            self.contextRequested.emit(self, ev.screenPos().toPoint())
            return
        if btn != Qt.MouseButton.LeftButton:
            return
        ev.accept()
        ses.set_active_sensor(self.sensor)
        self.activated.emit(self.sensor)
        if mods & M.ShiftModifier and not mods & M.AltModifier:
            if ses.project.properties["selection.sensors"]:
                self.sensorClicked.emit(self.sensor, bool(mods & M.ControlModifier))
            return
        x, y = self._raw_of(ev.pos())
        if ses.click_mode:
            self.targetClicked.emit(self.sensor, x, y)
            return
        hit = self.pick(x, y)
        picking.click(ses, hit, self.pick_stick(x, y) if hit is None else None, bool(mods & M.ControlModifier))

    def handle_drag(self, ev) -> bool:
        """Our drags; False hands the event to pyqtgraph (middle-drag pan, Shift+right-drag zoom)."""
        btn, mods = ev.button(), ev.modifiers()
        M = Qt.KeyboardModifier
        if btn == Qt.MouseButton.MiddleButton:
            return False
        if btn == Qt.MouseButton.RightButton:
            if mods & M.ShiftModifier or mods & M.AltModifier:
                return False
            ev.ignore()
            return True
        if btn != Qt.MouseButton.LeftButton or self.session.project is None:
            ev.ignore()
            return True
        ev.accept()
        start = self.vb.mapToView(ev.buttonDownPos())
        now = self.vb.mapToView(ev.pos())
        if self.measuring:
            self._measure(start, now)
            return True
        if (ev.isStart() or self._key_drag is not None) and self._drag_key_handle(ev, start, now):
            return True
        if ev.isStart() or self._region is None:
            self._region = picking.RegionDrag(start, lasso=bool(mods & M.ShiftModifier and mods & M.AltModifier))
        self._region.move(now)
        self.band.setPath(self._region.path())
        if ev.isFinish():
            self.band.setPath(QPainterPath())
            kinds, keys, xy = self.candidates()
            self.session.set_active_sensor(self.sensor)
            self._region.select(self.session, kinds, keys, self.raw_to_view(xy), add=bool(mods & M.ControlModifier))
            self._region = None
        return True

    def _measure(self, a: QPointF, b: QPointF) -> None:
        ra, rb = self.view_to_raw(a), self.view_to_raw(b)
        self.items["measure"].set_shapes(segments([ra[0]], [ra[1]], [rb[0]], [rb[1]]))
        length = float(np.hypot(rb[0] - ra[0], rb[1] - ra[1]))
        self.measure_text.setText(f"{length:.1f} px")
        self.measure_text.setPos(QPointF(*rb))
        self._measure_line = (ra, rb, length)

    def start_measurement(self) -> None:
        self.measuring = True
        self._update_info()

    def clear_measurement(self) -> None:
        self.measuring = False
        self._measure_line = None
        self.items["measure"].clear()
        self.measure_text.setText("")
        self._update_info()

    def measurement(self) -> float | None:
        """Length in pixels of the measurement line (None when there is none)."""
        return None if self._measure_line is None else self._measure_line[2]

    def handle_hover(self, ev) -> None:
        ses = self.session
        if ses.project is None:
            return
        if ev.isExit():
            self._pixel_text = ""
            ses.set_hover(None)
            self._update_info()
            return
        x, y = self._raw_of(ev.pos())
        if self.key_handle_at(x, y) is not None:
            self.viewport().setCursor(Qt.CursorShape.SizeAllCursor)
        else:
            self.viewport().unsetCursor()
        if ses.display.pixel_report:
            g = ses.loader.pixel(self.sensor, ses.frame, x, y)
            self._pixel_text = f"x {x:.1f}  y {y:.1f}  grey {'-' if g is None else g}"
            self._update_info()
        ses.set_hover(self.pick(x, y))

