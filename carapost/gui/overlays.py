"""Batched drawing of a camera view's overlays.

A view shows hundreds of detections, rings and projections; one graphics item
per marker would make stepping a frame cost tens of milliseconds.  Instead
every kind of marker is one :class:`SegmentsItem`: its shapes are built as
numpy arrays of line segments and drawn with a single ``QPainter.drawLines``
call, and labels are one item that paints all its texts.
"""
from __future__ import annotations

import numpy as np
from PySide6.QtCore import QLineF, QPointF, QRectF, Qt
from PySide6.QtGui import QBrush, QColor, QFont, QImage, QPainterPath, QPen, QPixmap
from PySide6.QtWidgets import QGraphicsItem, QGraphicsObject, QGraphicsPathItem

_N = 12   # segments per ellipse: round enough at marker sizes, half the cost of 24
_T = np.linspace(0, 2 * np.pi, _N + 1)
_COS, _SIN = np.cos(_T), np.sin(_T)

#: Line segments as four arrays: x0, y0, x1, y1.
Segs = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]


def _empty() -> Segs:
    z = np.zeros(0)
    return z, z, z, z


def _column(v) -> np.ndarray:
    """A per-shape parameter as a column (or a scalar) to broadcast against the unit circle."""
    v = np.asarray(v, float)
    return v[:, None] if v.ndim else v


def _closed(X: np.ndarray, Y: np.ndarray) -> Segs:
    """Segments of closed polylines given as (shapes, vertices) arrays whose last vertex is the first."""
    return X[:, :-1].ravel(), Y[:, :-1].ravel(), X[:, 1:].ravel(), Y[:, 1:].ravel()


def ellipses(x, y, a, b, angle_deg=0.0) -> Segs:
    """Ellipses with semi-axes ``a``, ``b`` rotated by ``angle_deg`` (degrees, from +x towards +y)."""
    x = np.asarray(x, float)
    if not len(x):
        return _empty()
    ang = np.deg2rad(_column(angle_deg))
    ca, sa = np.cos(ang), np.sin(ang)
    ex, ey = _column(a) * _COS, _column(b) * _SIN
    X = x[:, None] + ex * ca - ey * sa
    Y = np.asarray(y, float)[:, None] + ex * sa + ey * ca
    return _closed(X, Y)


def circles(x, y, r) -> Segs:
    """Circles of radius ``r``."""
    x = np.asarray(x, float)
    if not len(x):
        return _empty()
    r = _column(r)
    return _closed(x[:, None] + r * _COS, np.asarray(y, float)[:, None] + r * _SIN)


def segments(x0, y0, x1, y1) -> Segs:
    """Separate line segments."""
    return (np.asarray(x0, float).ravel(), np.asarray(y0, float).ravel(), np.asarray(x1, float).ravel(),
            np.asarray(y1, float).ravel())


def crosses(x, y, r) -> Segs:
    """Upright crosses (+) of half-size ``r``."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    return combine(segments(x - r, y, x + r, y), segments(x, y - r, x, y + r))


def xs(x, y, r) -> Segs:
    """Diagonal crosses (x) of half-size ``r``."""
    x, y = np.asarray(x, float), np.asarray(y, float)
    return combine(segments(x - r, y - r, x + r, y + r), segments(x - r, y + r, x + r, y - r))


def boxes(x, y, hw, hh) -> Segs:
    """Axis-aligned rectangles of half sizes ``hw``, ``hh``."""
    x = np.asarray(x, float)
    if not len(x):
        return _empty()
    y = np.asarray(y, float)
    hw, hh = np.broadcast_to(np.asarray(hw, float), x.shape), np.broadcast_to(np.asarray(hh, float), x.shape)
    X = np.stack([x - hw, x + hw, x + hw, x - hw, x - hw], axis=1)
    Y = np.stack([y - hh, y - hh, y + hh, y + hh, y - hh], axis=1)
    return _closed(X, Y)


def combine(*parts: Segs) -> Segs:
    """All the segments of ``parts`` together."""
    parts = [p for p in parts if len(p[0])]
    if not parts:
        return _empty()
    if len(parts) == 1:
        return parts[0]
    return tuple(np.concatenate([p[k] for p in parts]) for k in range(4))


class FastPathItem(QGraphicsPathItem):
    """A path item whose bounds are the path's control points.

    QGraphicsPathItem computes its bounding rect by stroking the whole path
    with its pen, which for thousands of segments costs milliseconds per
    frame; markers are drawn with thin cosmetic pens, so a few pixels of
    margin are enough.
    """

    _MARGIN = 4.0

    def __init__(self, parent=None):
        super().__init__(parent)
        self._rect = QRectF()

    def setPath(self, path: QPainterPath) -> None:  # noqa: N802 - Qt name
        self.prepareGeometryChange()
        m = self._MARGIN
        self._rect = path.controlPointRect().adjusted(-m, -m, m, m) if not path.isEmpty() else QRectF()
        super().setPath(path)

    def boundingRect(self) -> QRectF:  # noqa: N802 - Qt name
        return self._rect

    def shape(self) -> QPainterPath:
        return self.path()


class SegmentsItem(QGraphicsItem):
    """Line segments drawn with one ``QPainter.drawLines`` call from a numpy buffer.

    Cheaper than a QPainterPath of the same shapes: no path is built per
    frame, the vertex arrays go to Qt without a Python loop.
    """

    def __init__(self, parent=None):
        super().__init__(parent)
        from pyqtgraph.Qt import internals

        self._lines = internals.PrimitiveArray(QLineF, 4)
        self._n = 0
        self._rect = QRectF(-1e4, -1e4, 2e4, 2e4)
        self._pen = QPen()
        self.setAcceptedMouseButtons(Qt.MouseButton.NoButton)

    def setPen(self, pen: QPen) -> None:  # noqa: N802 - Qt-like name
        self._pen = QPen(pen)
        self.update()

    def set_shapes(self, segs: Segs) -> None:
        """Draw ``segs`` (see :func:`ellipses`, :func:`segments`...)."""
        self._n = len(segs[0])
        self._lines.resize(self._n)
        if self._n:
            mem = self._lines.ndarray()
            mem[:, 0], mem[:, 1], mem[:, 2], mem[:, 3] = segs
        self.update()

    def set_bounds(self, rect: QRectF) -> None:
        """Where the segments may be: fixed per view (computing it per frame costs more than it saves)."""
        self.prepareGeometryChange()
        self._rect = QRectF(rect)

    def clear(self) -> None:
        if self._n:
            self.set_shapes(_empty())

    def count(self) -> int:
        """Segments drawn (tests)."""
        return self._n

    def boundingRect(self) -> QRectF:
        return self._rect

    def paint(self, painter, option, widget=None) -> None:
        if self._n:
            painter.setPen(self._pen)
            painter.drawLines(*self._lines.drawargs())


def _pen(color, width: float, dashed: bool) -> QPen:
    pen = QPen(QColor(*color) if isinstance(color, tuple) else QColor(color), width)
    pen.setCosmetic(True)
    if dashed:
        pen.setStyle(Qt.PenStyle.DashLine)
    return pen


def segments_item(parent: QGraphicsItem, color, width: float = 1, z: float = 10, dashed: bool = False) -> SegmentsItem:
    """A marker layer drawn with a cosmetic pen (width in screen pixels at any zoom)."""
    item = SegmentsItem(parent)
    item.setPen(_pen(color, width, dashed))
    item.setZValue(z)
    return item


def path_item(parent: QGraphicsItem, color, width: float = 1.5, z: float = 10, dashed: bool = False,
              fill=None) -> QGraphicsPathItem:
    """A cosmetic-pen path item (rubber band, lasso, border), not mouse-interactive."""
    item = FastPathItem(parent)
    item.setPen(_pen(color, width, dashed))
    item.setBrush(QBrush(QColor(*fill)) if fill else QBrush(Qt.BrushStyle.NoBrush))
    item.setZValue(z)
    item.setAcceptedMouseButtons(Qt.MouseButton.NoButton)
    return item


def finite(*arrays) -> np.ndarray:
    """Mask of rows where every array is finite."""
    m = np.ones(len(arrays[0]), bool)
    for a in arrays:
        a = np.isfinite(np.asarray(a, float))
        m &= a.all(axis=tuple(range(1, a.ndim))) if a.ndim > 1 else a
    return m


class GreyImageItem(QGraphicsItem):
    """A grey ``uint8`` image drawn without a copy (raw pixel (c, r) is centred on (c, r)).

    What is drawn is converted once per image to RGB32, which Qt's raster
    engine scales several times faster than 8-bit grey; when the view shows
    the image smaller than half size, a decimated copy is converted instead
    (like pyqtgraph's autoDownsample).
    """

    def __init__(self, parent=None):
        super().__init__(parent)
        self._arr = None
        self._qimg = None
        self._small: tuple[int, QImage, None] | None = None   # (decimation, what is drawn)
        self._w = self._h = 0
        self.setAcceptedMouseButtons(Qt.MouseButton.NoButton)

    def set_image(self, arr: np.ndarray | None) -> None:
        self._small = None
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

    def _image_for(self, scale: float) -> QImage:
        k = max(1, int(1.0 / scale)) if scale < 0.5 else 1
        if self._small is None or self._small[0] != k:
            src = self._qimg
            if k > 1:
                small = np.ascontiguousarray(self._arr[::k, ::k])
                src = QImage(small.data, small.shape[1], small.shape[0], small.strides[0],
                             QImage.Format.Format_Grayscale8)
            self._small = (k, src.convertToFormat(QImage.Format.Format_RGB32), None)
        return self._small[1]

    def paint(self, painter, option, widget=None) -> None:
        if self._qimg is None:
            return
        t = painter.worldTransform()
        scale = max(abs(t.m11()) + abs(t.m21()), abs(t.m12()) + abs(t.m22()))
        painter.drawImage(QRectF(-0.5, -0.5, self._w, self._h), self._image_for(scale))


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


class HudItem(QGraphicsItem):
    """A few lines of text at a fixed place of the view (channel name, mode, pixel report).

    Drawn by the scene in the same pass as the image: a QLabel over the view
    would be a second widget repainted on every frame.
    """

    PAD = 4

    def __init__(self):
        super().__init__()
        self._text = ""
        self._lines: list[str] = []
        self._rect = QRectF()
        self._font = QFont()
        self.setZValue(1e9)
        self.setAcceptedMouseButtons(Qt.MouseButton.NoButton)

    def text(self) -> str:
        return self._text

    def setText(self, text: str) -> None:  # noqa: N802 - QLabel-like name
        if text == self._text:
            return
        from PySide6.QtGui import QFontMetricsF

        self.prepareGeometryChange()
        self._text = text
        self._lines = text.split("\n") if text else []
        fm = QFontMetricsF(self._font)
        w = max((fm.horizontalAdvance(t) for t in self._lines), default=0.0)
        self._line_h = fm.height()
        self._ascent = fm.ascent()
        self._rect = QRectF(0, 0, w + 2 * self.PAD, len(self._lines) * self._line_h + 2 * self.PAD) \
            if self._lines else QRectF()
        self.update()

    def boundingRect(self) -> QRectF:
        return self._rect

    def paint(self, painter, option, widget=None) -> None:
        if not self._lines:
            return
        painter.fillRect(self._rect, QColor(0, 0, 0, 110))
        painter.setFont(self._font)
        painter.setPen(QColor(240, 240, 240))
        for i, t in enumerate(self._lines):
            painter.drawText(QPointF(self.PAD, self.PAD + self._ascent + i * self._line_h), t)
