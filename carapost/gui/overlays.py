"""Batched drawing of a camera view's overlays.

A view shows hundreds of detections, rings and projections; one graphics item
per marker would make stepping a frame cost tens of milliseconds.  Instead
every kind of marker is one :class:`QGraphicsPathItem` whose path is built
from numpy vertex arrays in a single :func:`pyqtgraph.arrayToQPath` call, and
labels are one item that paints all its texts.
"""
from __future__ import annotations

import numpy as np
import pyqtgraph as pg
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QBrush, QColor, QFont, QImage, QPainterPath, QPen, QPixmap
from PySide6.QtWidgets import QGraphicsItem, QGraphicsObject, QGraphicsPathItem

_N = 24
_T = np.linspace(0, 2 * np.pi, _N + 1)
_COS, _SIN = np.cos(_T), np.sin(_T)

Shapes = tuple[np.ndarray, np.ndarray, np.ndarray]   # x, y, connect-to-next


def _empty() -> Shapes:
    z = np.zeros(0)
    return z, z, np.zeros(0, np.int32)


def ellipses(x, y, a, b, angle_deg=0.0) -> Shapes:
    """Closed polylines of ellipses with semi-axes ``a``, ``b`` rotated by ``angle_deg``."""
    x = np.asarray(x, float)
    if not len(x):
        return _empty()
    y = np.asarray(y, float)
    a = np.broadcast_to(np.asarray(a, float), x.shape)[:, None]
    b = np.broadcast_to(np.asarray(b, float), x.shape)[:, None]
    ang = np.deg2rad(np.broadcast_to(np.asarray(angle_deg, float), x.shape))[:, None]
    ca, sa = np.cos(ang), np.sin(ang)
    ex, ey = a * _COS, b * _SIN
    X = x[:, None] + ex * ca - ey * sa
    Y = y[:, None] + ex * sa + ey * ca
    con = np.ones(X.shape, np.int32)
    con[:, -1] = 0
    return X.ravel(), Y.ravel(), con.ravel()


def circles(x, y, r) -> Shapes:
    return ellipses(x, y, r, r)


def segments(x0, y0, x1, y1) -> Shapes:
    """Separate line segments."""
    x0 = np.asarray(x0, float)
    if not len(x0):
        return _empty()
    X = np.stack([x0, np.asarray(x1, float)], axis=1).ravel()
    Y = np.stack([np.asarray(y0, float), np.asarray(y1, float)], axis=1).ravel()
    con = np.tile(np.array([1, 0], np.int32), len(x0))
    return X, Y, con


def crosses(x, y, r) -> Shapes:
    """Upright crosses (+) of half-size ``r``."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    return combine(segments(x - r, y, x + r, y), segments(x, y - r, x, y + r))


def xs(x, y, r) -> Shapes:
    """Diagonal crosses (x) of half-size ``r``."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    return combine(segments(x - r, y - r, x + r, y + r), segments(x - r, y + r, x + r, y - r))


def boxes(x, y, hw, hh) -> Shapes:
    """Axis-aligned rectangles of half sizes ``hw``, ``hh``."""
    x = np.asarray(x, float)
    if not len(x):
        return _empty()
    y = np.asarray(y, float)
    hw = np.broadcast_to(np.asarray(hw, float), x.shape)
    hh = np.broadcast_to(np.asarray(hh, float), x.shape)
    X = np.stack([x - hw, x + hw, x + hw, x - hw, x - hw], axis=1)
    Y = np.stack([y - hh, y - hh, y + hh, y + hh, y - hh], axis=1)
    con = np.ones(X.shape, np.int32)
    con[:, -1] = 0
    return X.ravel(), Y.ravel(), con.ravel()


def combine(*parts: Shapes) -> Shapes:
    parts = [p for p in parts if len(p[0])]
    if not parts:
        return _empty()
    return (np.concatenate([p[0] for p in parts]), np.concatenate([p[1] for p in parts]),
            np.concatenate([p[2] for p in parts]))


def to_path(shapes: Shapes) -> QPainterPath:
    """One QPainterPath of all the shapes (empty path when there are none)."""
    x, y, con = shapes
    if not len(x):
        return QPainterPath()
    return pg.arrayToQPath(x, y, connect=con, finiteCheck=False)


def path_item(parent: QGraphicsItem, color, width: float = 1.5, z: float = 10, dashed: bool = False,
              fill=None) -> QGraphicsPathItem:
    """A cosmetic-pen path item (width in screen pixels at any zoom), not mouse-interactive."""
    item = QGraphicsPathItem(parent)
    pen = QPen(QColor(*color) if isinstance(color, tuple) else QColor(color), width)
    pen.setCosmetic(True)
    if dashed:
        pen.setStyle(Qt.PenStyle.DashLine)
    item.setPen(pen)
    item.setBrush(QBrush(QColor(*fill)) if fill else QBrush(Qt.BrushStyle.NoBrush))
    item.setZValue(z)
    item.setAcceptedMouseButtons(Qt.MouseButton.NoButton)
    return item


def finite(*arrays) -> np.ndarray:
    """Mask of rows where every array is finite."""
    m = np.ones(len(arrays[0]), bool)
    for a in arrays:
        a = np.asarray(a, float)
        m &= np.all(np.isfinite(a.reshape(len(a), -1)), axis=1)
    return m


class GreyImageItem(QGraphicsItem):
    """A grey ``uint8`` image drawn without a copy (raw pixel (c, r) is centred on (c, r))."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self._arr = None
        self._qimg = None
        self._w = self._h = 0
        self.setAcceptedMouseButtons(Qt.MouseButton.NoButton)

    def set_image(self, arr: np.ndarray | None) -> None:
        if arr is None:
            self._arr = self._qimg = None
            self.update()
            return
        arr = np.ascontiguousarray(arr, dtype=np.uint8)
        h, w = arr.shape[:2]
        if (w, h) != (self._w, self._h):
            self.prepareGeometryChange()
            self._w, self._h = w, h
        self._arr = arr  # QImage only borrows the buffer
        self._qimg = QImage(arr.data, w, h, arr.strides[0], QImage.Format.Format_Grayscale8)
        self.update()

    def image(self) -> np.ndarray | None:
        return self._arr

    def boundingRect(self) -> QRectF:
        return QRectF(-0.5, -0.5, self._w, self._h)

    def paint(self, painter, option, widget=None) -> None:
        if self._qimg is not None:
            painter.drawImage(QRectF(-0.5, -0.5, self._w, self._h), self._qimg)


def checker_brush(size: int = 16) -> QBrush:
    """The Border option's checkerboard (two greys)."""
    img = QImage(2 * size, 2 * size, QImage.Format.Format_RGB32)
    img.fill(QColor(90, 90, 90))
    dark = QColor(60, 60, 60)
    for y in range(2 * size):
        for x in range(2 * size):
            if (x < size) != (y < size):
                img.setPixelColor(x, y, dark)
    return QBrush(QPixmap.fromImage(img))


class LabelsItem(QGraphicsObject):
    """Point labels at a constant screen size beside their points, drawn by one item."""

    def __init__(self, parent=None):
        super().__init__(parent)
        self._xy = np.zeros((0, 2))
        self._texts: list[str] = []
        self._colors: list[QColor] = []
        self._font = QFont()
        self._bounds = QRectF()
        self.setAcceptedMouseButtons(Qt.MouseButton.NoButton)

    def set_labels(self, xy: np.ndarray, texts: list[str], colors: list[QColor], point_size: int,
                   bounds: QRectF) -> None:
        self._xy, self._texts, self._colors = np.asarray(xy, float).reshape(-1, 2), texts, colors
        self._font.setPointSize(int(point_size))
        if bounds != self._bounds:
            self.prepareGeometryChange()
            self._bounds = QRectF(bounds)
        self.update()

    def boundingRect(self) -> QRectF:
        return self._bounds

    def paint(self, painter, option, widget=None) -> None:
        if not self._texts:
            return
        tr = painter.transform()
        painter.save()
        painter.resetTransform()   # text at a constant size whatever the zoom and rotation
        painter.setFont(self._font)
        for (x, y), text, color in zip(self._xy, self._texts, self._colors):
            p = tr.map(QPointF(x, y))
            painter.setPen(QColor(0, 0, 0))
            painter.drawText(p + QPointF(9, -7), text)
            painter.setPen(color)
            painter.drawText(p + QPointF(8, -8), text)
        painter.restore()
