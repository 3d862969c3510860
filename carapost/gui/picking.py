"""Picking and selecting with the mouse, shared by the camera views and the 3D view.

A view lists what can be selected as candidates (kind, key, position in its
own 2D coordinates); these functions choose among them and turn a click or a
drag into a change of the session's selection, so every view selects alike:
click picks the nearest thing within the tolerance (points win ties with the
detection under them), Ctrl+click toggles, a click on nothing clears (or picks
a stick), a drag selects what its rectangle (or Shift+Alt lasso) encloses,
Ctrl+drag adds.
"""
from __future__ import annotations

import numpy as np
from PySide6.QtCore import QPointF, QRectF, Qt
from PySide6.QtGui import QPainterPath, QPolygonF

#: A click picks the nearest point or detection within this many screen pixels.
PICK_TOLERANCE = 9.0


def nearest(kinds: list, keys: list, xy: np.ndarray, x: float, y: float, tolerance: float):
    """The candidate nearest ``(x, y)`` within ``tolerance``: ``(kind, key)`` or None.

    Parameters
    ----------
    kinds, keys : list
        Per candidate: ``"point"`` or ``"detection"``, and its id / detection key.
    xy : ndarray (N, 2)
        Candidate positions (NaN: not pickable).
    x, y, tolerance : float
        In the same units as ``xy``.
    """
    xy = np.asarray(xy, float).reshape(-1, 2)
    if not len(xy):
        return None
    d = np.hypot(xy[:, 0] - x, xy[:, 1] - y)
    d = np.where(np.isfinite(d), d, np.inf)
    d = d + np.array([0.0 if k == "point" else 1e-3 for k in kinds])   # points win ties
    i = int(np.argmin(d))
    if not d[i] <= tolerance:
        return None
    return kinds[i], keys[i]


def nearest_segment(a: np.ndarray, b: np.ndarray, x: float, y: float, tolerance: float) -> int | None:
    """Index of the segment ``a[i]-b[i]`` (each (N, 2)) nearest ``(x, y)`` within ``tolerance``."""
    a, b = np.asarray(a, float).reshape(-1, 2), np.asarray(b, float).reshape(-1, 2)
    if not len(a):
        return None
    q = np.array([x, y])
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", q - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-9), 0, 1)
    d = np.linalg.norm(a + t[:, None] * ab - q, axis=1)
    d = np.where(np.isfinite(d), d, np.inf)
    i = int(np.argmin(d))
    return i if d[i] < tolerance else None


def click(session, hit, stick: int | None, toggle: bool) -> None:
    """Apply a left click that picked ``hit`` (or nothing, then ``stick``) to the selection."""
    if hit is None:
        if stick is not None:
            session.select_sticks([stick], add=toggle)
        elif not toggle:
            session.select()
        return
    if hit[0] == "point":
        session.select(points=[hit[1]], toggle=toggle)
    else:
        session.select(detections=[hit[1]], toggle=toggle)


class RegionDrag:
    """The rectangle (or lasso) of a selection drag, in a view's 2D coordinates."""

    def __init__(self, start: QPointF, lasso: bool):
        self.start = QPointF(start)
        self.now = QPointF(start)
        self.lasso = lasso
        self.trail = [QPointF(start)]

    def move(self, p: QPointF) -> None:
        self.now = QPointF(p)
        if self.lasso:
            self.trail.append(QPointF(p))

    def path(self) -> QPainterPath:
        """The outline to draw."""
        path = QPainterPath()
        if self.lasso:
            path.addPolygon(QPolygonF(self.trail))
            path.closeSubpath()
        else:
            path.addRect(QRectF(self.start, self.now).normalized())
        return path

    def contains(self, x: float, y: float) -> bool:
        q = QPointF(x, y)
        if self.lasso:
            return QPolygonF(self.trail).containsPoint(q, Qt.FillRule.OddEvenFill)
        return QRectF(self.start, self.now).normalized().contains(q)

    def select(self, session, kinds: list, keys: list, xy: np.ndarray, add: bool) -> None:
        """Select the candidates inside (``add``: keep the selection, Ctrl held)."""
        pts, dets = [], []
        for k, key, (x, y) in zip(kinds, keys, np.asarray(xy, float).reshape(-1, 2)):
            if np.isfinite(x) and np.isfinite(y) and self.contains(x, y):
                (pts if k == "point" else dets).append(key)
        session.select(points=pts, detections=dets, add=add)


def label_rows(props, labels: list[str], sel_rows: set, hover_row: int) -> list[int]:
    """Rows whose label a view shows: all (Point Labels : All), else the selected and pre-selected ones.

    Parameters
    ----------
    props : Properties
        The project's (``display.point_labels_*``).
    labels : list of str
        Per row ("" for unlabelled points, which show nothing).
    sel_rows : set of int
    hover_row : int
        The pre-selected row (-1: none).
    """
    show_all = props["display.point_labels_all"]
    show_sel = props["display.point_labels_selected"]
    show_pre = props["display.point_labels_pre_selected"]
    return [r for r, lb in enumerate(labels)
            if lb and (show_all or (show_sel and r in sel_rows) or (show_pre and r == hover_row))]
