"""The 3D view: the current frame's points, brim, cameras, rays, ROM and sticks in world space.

The picture is drawn by :mod:`carapost.gui.render3d` (OpenGL through a
standalone EGL context, read back as an image) and painted here with the
labels on top; without OpenGL the view says so and draws nothing else.

Colours: face points yellow; with Reconstruction Type Colors, orange when the
point holds patch-matched (or target-tracked) 2D data on this frame and red
when it is fully predicted or interpolated; brim points green; ROM points pale
blue; selected points get a white disc, the point under the mouse a cyan one;
rays (selected points to the cameras whose 2D data they use) are yellow lines.

Mouse (the guide's bindings): Alt or Shift + left-drag rotates about the view's
centre, Alt or Shift + right-drag zooms, Alt or Shift + middle-drag (or
left+right) pans, as does a plain middle-drag; the wheel zooms.  Click picks a
point (Ctrl+click toggles), a drag selects the points in its rectangle,
Shift+Alt + drag lassoes, right-click opens the 3D context menu.
"""
from __future__ import annotations

import weakref

import numpy as np
from PySide6.QtCore import QPoint, QPointF, QRectF, Qt, Signal
from PySide6.QtGui import QColor, QFont, QImage, QPainter, QPen
from PySide6.QtWidgets import QWidget

from ..core.points import BRIM, SRC_NONE, SRC_PATCH, SRC_TARGET, ST_INTERPOLATED
from . import picking
from .render3d import OrbitCamera, RenderUnavailable, Scene, shared_renderer

#: RGB 0-255 of what the view draws.
COLORS = {
    "measured": (255, 225, 0), "patch": (255, 140, 0), "predicted": (230, 30, 30), "brim": (70, 210, 90),
    "rom": (170, 205, 255), "selected": (255, 255, 255), "hover": (0, 255, 255), "camera": (140, 160, 210),
    "active_camera": (90, 150, 255), "ray": (255, 225, 0), "background": (36, 36, 38),
}
POINT_PX = 9.0          #: diameter of a point's dot
SELECT_PX = 17.0        #: diameter of the selection disc behind it
HOVER_PX = 21.0         #: diameter of the pre-selection disc
ROM_PX = 6.0
FRUSTUM_MM = 40.0       #: depth at which a camera's frustum is cut
AXIS_MM = 20.0          #: length of the world axes drawn at the origin
DRAG_START_PX = 3       #: a press that moves less is a click


def _rgba(rgb, n: int = 1, alpha: float = 1.0) -> np.ndarray:
    return np.tile(np.array([*(c / 255.0 for c in rgb), alpha]), (n, 1))


def stabilized_or_raw(session, fd) -> np.ndarray:
    """The positions the view shows: stabilised when the document's Show Stabilized is on, else raw.

    Returns
    -------
    ndarray (N, 3)
        One row per row of ``fd`` (NaN where there is no 3D data).
    """
    doc = session.doc
    if doc is None or not getattr(doc, "show_stabilized", False):
        return fd.pos
    try:
        from ..core.stabilize import stabilized_positions
    except ImportError:           # a build without stabilisation: raw data
        return fd.pos
    out = np.asarray(stabilized_positions(session.project, fd.frame, [int(i) for i in fd.ids]), float)
    return out.reshape(-1, 3) if out.size == fd.pos.size else fd.pos


def rom_positions(session) -> np.ndarray:
    """Points of the loaded ROM's frame (M, 3), as aligned by the ROM Tools; empty without a ROM."""
    try:
        from ..core.rom_ops import rom_points_3d
    except ImportError:           # a build without ROM support
        return np.zeros((0, 3))
    X = np.asarray(rom_points_3d(session.project), float).reshape(-1, 3)
    return X[np.all(np.isfinite(X), axis=1)]


def _display_listener(view):
    """A document listener redrawing ``view`` on ``"display"`` that does not keep the view alive."""
    ref = weakref.ref(view)

    def listener(what: str) -> None:
        v = ref()
        if v is not None and what == "display":
            try:
                v.refresh()
            except RuntimeError:      # the widget was deleted with its window
                pass

    return listener


class View3D(QWidget):
    """The 3D view of a session (see the module docstring).

    Parameters
    ----------
    session : Session
    """

    contextRequested = Signal(object, QPoint)    #: view, global position

    def __init__(self, session, parent=None):
        super().__init__(parent)
        self.session = session
        self.camera = OrbitCamera()
        self.setMouseTracking(True)
        self.setFocusPolicy(Qt.FocusPolicy.ClickFocus)
        self.setMinimumSize(80, 60)
        self.setAttribute(Qt.WidgetAttribute.WA_OpaquePaintEvent, True)
        try:
            self.renderer = shared_renderer()
            self.error = ""
        except RenderUnavailable as e:
            self.renderer = None
            self.error = f"The 3D view needs OpenGL: {e}"
        self._image: np.ndarray | None = None
        self._qimage: QImage | None = None
        self._dirty = True
        self._needs_fit = True
        self._rows = np.zeros(0, np.int64)          # fd rows of the pickable points
        self._xy = np.zeros((0, 2))                 # their widget pixels in the last picture
        self._labels: list[tuple[float, float, str, QColor]] = []
        self._cam_labels: list[tuple[float, float, str]] = []
        self._sticks: tuple[list[int], np.ndarray, np.ndarray] = ([], np.zeros((0, 2)), np.zeros((0, 2)))
        self._fd_cache: tuple = (None, None)
        self._press: tuple | None = None           # (button, modifiers, position) of the press
        self._mode = ""                            # "", "click", "region", "rotate", "zoom", "pan"
        self._last = QPointF()
        self._region: picking.RegionDrag | None = None
        self.renders = 0                           #: pictures drawn (tests, benchmark)
        self._doc = None
        s = session
        s.documentChanged.connect(self.on_document)
        s.projectChanged.connect(self.refresh)
        s.frameChanged.connect(self.on_frame)
        for sig in (s.selectionChanged, s.hoverChanged, s.displayChanged):
            sig.connect(self.refresh)
        self._listener = _display_listener(self)
        self.on_document()

    # ================================================================= state
    def on_document(self) -> None:
        # the document's own display switch (Toggle Show Stabilized) reaches views through its listeners
        if self._doc is not None:
            self._doc.remove_listener(self._listener)
        self._doc = self.session.doc
        if self._doc is not None:
            self._doc.add_listener(self._listener)
        self._needs_fit = True
        self.refresh()

    def on_frame(self, _frame: int) -> None:
        self.refresh()

    def refresh(self) -> None:
        """Redraw on the next paint (several changes in one event-loop pass cost one picture)."""
        self._dirty = True
        self.update()

    def home(self) -> None:
        """Look the way the take's cameras look and fit every point (a new take, or Fit To Points on nothing)."""
        p = self.session.project
        self._needs_fit = False
        if p is None:
            return
        if p.rig is not None:
            self.camera.look_like([p.rig.camera(k, self.session.frame).rotation for k in range(p.rig.sensors)])
        self.camera.width, self.camera.height = max(self.width(), 1), max(self.height(), 1)
        fd = self.session.frame_data()
        X = stabilized_or_raw(self.session, fd)[fd.has3d] if fd is not None else np.zeros((0, 3))
        if not len(X) and p.rig is not None:
            X = np.array([p.rig.camera(k, self.session.frame).position for k in range(p.rig.sensors)])
        self.camera.frame(X)

    # ============================================================ navigation
    def _positions(self, rows) -> np.ndarray:
        fd = self.session.frame_data()
        if fd is None:
            return np.zeros((0, 3))
        return stabilized_or_raw(self.session, fd)[list(rows)].reshape(-1, 3)

    def _selected_rows(self) -> list[int]:
        fd = self.session.frame_data()
        if fd is None:
            return []
        rows = [fd.row_of(pid) for pid in self.session.selection.points]
        return [r for r in rows if r >= 0]

    def _selected_stick_rows(self) -> list[int]:
        p, fd = self.session.project, self.session.frame_data()
        rows = []
        for k in self.session.selection.sticks:
            if k < len(p.sticks):
                rows += [fd.row_of(p.sticks[k].a), fd.row_of(p.sticks[k].b)]
        return [r for r in rows if r >= 0]

    def fit_to_points(self) -> bool:
        """Fit To Points: the selected points fill the view; with none selected, every point."""
        self._size_camera()
        fd = self.session.frame_data()
        if fd is None:
            return False
        rows = self._selected_rows() or list(np.flatnonzero(fd.has3d))
        done = self.camera.frame(self._positions(rows))
        self.refresh()
        return done

    def center_selection(self) -> bool:
        """Center Selection: turn about the selection's centre, which moves to the middle of the view."""
        done = self.camera.center_on(self._positions(self._selected_rows() + self._selected_stick_rows()))
        self.refresh()
        return done

    def frame_selection(self) -> bool:
        """Frame Selection: centre and zoom onto the selected points and sticks."""
        self._size_camera()
        done = self.camera.frame(self._positions(self._selected_rows() + self._selected_stick_rows()))
        self.refresh()
        return done

    def _size_camera(self) -> None:
        self.camera.width, self.camera.height = max(self.width(), 1), max(self.height(), 1)

    # =============================================================== drawing
    def _frame_extras(self, fd):
        """Per row of ``fd``: brim flag, fully predicted flag, patch-matched flag (cached per frame data)."""
        if self._fd_cache[0] is fd:
            return self._fd_cache[1]
        pts = self.session.project.points
        brim = np.array([pts[int(i)].kind == BRIM for i in fd.ids], bool)
        status = np.array([pts[int(i)].status[fd.frame] for i in fd.ids], np.uint8)
        src = fd.src
        patch = np.any((src == SRC_PATCH) | (src == SRC_TARGET), axis=1) if src.size else np.zeros(len(fd.ids), bool)
        extras = (brim, status == ST_INTERPOLATED, patch)
        self._fd_cache = (fd, extras)
        return extras

    def build_scene(self) -> Scene:
        """What to draw for the current frame, display options and selection.

        Also records where each pickable point lands (``self._rows``), the labels and the sticks' ends.
        """
        ses, d = self.session, self.session.display
        p, fd = ses.project, ses.frame_data()
        scene = Scene(background=tuple(c / 255.0 for c in COLORS["background"]))
        self._rows = np.zeros(0, np.int64)
        self._labels, self._cam_labels = [], []
        self._sticks = ([], np.zeros((0, 2)), np.zeros((0, 2)))
        if p is None or fd is None:
            return scene
        self._size_camera()
        cam = self.camera
        pos = stabilized_or_raw(ses, fd)
        brim, predicted, patch = self._frame_extras(fd)
        ok = fd.has3d & np.all(np.isfinite(pos), axis=1)
        shown = ok & np.where(brim, d.brim_points, d.face_points)
        rows = np.flatnonzero(shown)
        colors = _rgba(COLORS["measured"], len(fd.ids))
        if d.reconstruction_colors:
            colors[patch] = _rgba(COLORS["patch"])
            colors[predicted] = _rgba(COLORS["predicted"])
        colors[brim] = _rgba(COLORS["brim"])
        sel = [r for r in self._selected_rows() if shown[r]]
        hv = ses.hover
        hover_row = fd.row_of(hv[1]) if hv is not None and hv[0] == "point" else -1
        pts, cols, sizes = [], [], []
        if hover_row >= 0 and shown[hover_row]:
            pts.append(pos[[hover_row]])
            cols.append(_rgba(COLORS["hover"]))
            sizes.append([HOVER_PX])
        if sel:
            pts.append(pos[sel])
            cols.append(_rgba(COLORS["selected"], len(sel)))
            sizes.append(np.full(len(sel), SELECT_PX))
        pts.append(pos[rows])
        cols.append(colors[rows])
        sizes.append(np.full(len(rows), POINT_PX))
        rom = rom_positions(ses) if d.rom_3d else np.zeros((0, 3))
        if len(rom):
            pts.insert(0, rom)
            cols.insert(0, _rgba(COLORS["rom"], len(rom)))
            sizes.insert(0, np.full(len(rom), ROM_PX))
        scene.points = np.concatenate(pts)
        scene.point_colors = np.concatenate(cols)
        scene.point_sizes = np.concatenate([np.asarray(s, float) for s in sizes])

        lines, lcols = [self._axes()], [np.array([[1, .25, .25, 1], [.25, 1, .25, 1], [.3, .5, 1, 1]])]
        if d.sticks_3d and p.sticks:
            self._add_sticks(p, fd, pos, shown, lines, lcols)
        cams = [p.rig.camera(k, fd.frame) for k in range(p.rig.sensors)] if p.rig is not None else []
        if d.cameras and cams:
            for k, c in enumerate(cams):
                seg = self._frustum(c)
                lines.append(seg)
                color = COLORS["active_camera"] if k == ses.active_sensor else COLORS["camera"]
                lcols.append(_rgba(color, len(seg)))
        if d.rays and sel and cams:
            ray = [(pos[r], cams[k].position) for r in sel for k in range(min(len(cams), fd.src.shape[1]))
                   if fd.src[r, k] != SRC_NONE]
            if ray:
                lines.append(np.array(ray, float))
                lcols.append(_rgba(COLORS["ray"], len(ray), 0.8))
        scene.lines = np.concatenate(lines)
        scene.line_colors = np.concatenate(lcols)

        # where things land, for picking and the QPainter layer
        if p.properties["selection.points"]:
            self._rows = rows
        self._xy = cam.project(pos[self._rows]) if len(self._rows) else np.zeros((0, 2))
        want = picking.label_rows(p.properties, fd.labels, set(sel), hover_row)
        want = [r for r in want if shown[r]]
        if want:
            xy = cam.project(pos[want])
            for r, (x, y) in zip(want, xy):
                if np.isfinite(x):
                    color = QColor(255, 255, 255) if r in sel else QColor(0, 255, 255) if r == hover_row \
                        else QColor(230, 230, 150)
                    self._labels.append((float(x), float(y), fd.labels[r], color))
        if d.cameras and cams:
            xy = cam.project(np.array([c.position for c in cams]))
            self._cam_labels = [(float(x), float(y), f"Sensor {k}") for k, (x, y) in enumerate(xy)
                                if np.isfinite(x)]
        return scene

    def _add_sticks(self, p, fd, pos, shown, lines, lcols) -> None:
        row = {int(pid): i for i, pid in enumerate(fd.ids)}
        idx, a, b, cols = [], [], [], []
        selected = set(self.session.selection.sticks)
        for k, st in enumerate(p.sticks):
            ra, rb = row.get(st.a), row.get(st.b)
            if ra is None or rb is None or not (shown[ra] and shown[rb]):
                continue
            idx.append(k)
            a.append(pos[ra])
            b.append(pos[rb])
            cols.append(COLORS["selected"] if k in selected else st.color)
        if not idx:
            return
        seg = np.stack([np.array(a), np.array(b)], axis=1)
        lines.append(seg)
        lcols.append(np.array([[*(c / 255.0 for c in col), 1.0] for col in cols]))
        if p.properties["selection.sticks"]:
            self._sticks = (idx, self.camera.project(seg[:, 0]), self.camera.project(seg[:, 1]))

    @staticmethod
    def _axes() -> np.ndarray:
        o = np.zeros(3)
        return np.array([[o, np.eye(3)[i] * AXIS_MM] for i in range(3)])

    @staticmethod
    def _frustum(cam) -> np.ndarray:
        """Line segments of a camera's pyramid, cut at :data:`FRUSTUM_MM` (with a tick on the image's top edge)."""
        w, h = cam.sensor_size
        corners = np.array([[0, 0], [w, 0], [w, h], [0, h]], float)
        centre, dirs = cam.ray(corners)
        if not np.all(np.isfinite(dirs)):
            centre, dirs = cam.position, np.tile(cam.rotation[2], (4, 1))
        depth = dirs @ cam.rotation[2]
        ends = centre + dirs * (FRUSTUM_MM / np.maximum(depth, 1e-6))[:, None]
        segs = [(centre, e) for e in ends] + [(ends[i], ends[(i + 1) % 4]) for i in range(4)]
        top = (ends[0] + ends[1]) / 2
        segs.append((top, top - cam.rotation[1] * FRUSTUM_MM * 0.25))   # image up
        return np.array(segs, float)

    def render_image(self) -> np.ndarray | None:
        """Draw the current picture now; the RGBA image (None without OpenGL)."""
        if self.renderer is None:
            return None
        if self._needs_fit and self.session.project is not None:
            self.home()
        self.renderer.resize(max(self.width(), 1), max(self.height(), 1))
        scene = self.build_scene()
        img = self.renderer.render(scene, self.camera)
        self._image = img        # QImage borrows this buffer: keep it alive
        h, w = img.shape[:2]
        self._qimage = QImage(img.data, w, h, 4 * w, QImage.Format.Format_RGBA8888)
        self._dirty = False
        self.renders += 1
        return img

    def image(self) -> np.ndarray | None:
        """The last picture (drawn now if anything changed since)."""
        if self._dirty or self._image is None or self._image.shape[:2] != (self.height(), self.width()):
            return self.render_image()
        return self._image

    def paintEvent(self, ev) -> None:  # noqa: N802 - Qt name
        painter = QPainter(self)
        if self.renderer is None:
            painter.fillRect(self.rect(), QColor(*COLORS["background"]))
            painter.setPen(QColor(255, 180, 120))
            painter.drawText(QRectF(self.rect()).adjusted(12, 12, -12, -12),
                             Qt.AlignmentFlag.AlignCenter | Qt.TextFlag.TextWordWrap, self.error)
            painter.end()
            return
        self.image()
        if self._qimage is not None:
            painter.drawImage(0, 0, self._qimage)
        font = QFont(painter.font())
        p = self.session.project
        if p is not None:
            font.setPointSize(int(p.properties["display.font_size"]))
        painter.setFont(font)
        for x, y, text, color in self._labels:
            painter.setPen(QColor(0, 0, 0))
            painter.drawText(QPointF(x + 9, y - 7), text)
            painter.setPen(color)
            painter.drawText(QPointF(x + 8, y - 8), text)
        painter.setPen(QColor(*COLORS["camera"]))
        for x, y, text in self._cam_labels:
            painter.drawText(QPointF(x + 6, y + 14), text)
        if self._region is not None:
            painter.setPen(QPen(QColor(255, 255, 255), 1, Qt.PenStyle.DashLine))
            painter.drawPath(self._region.path())
        painter.setPen(QColor(200, 200, 200))
        painter.drawText(QPointF(6, 16), self._hud())
        painter.end()

    def _hud(self) -> str:
        ses = self.session
        if ses.project is None:
            return "3D"
        text = f"3D  frame {ses.frame}"
        if getattr(ses.doc, "show_stabilized", False):
            text += "  (stabilized)"
        return text

    # =============================================================== picking
    def candidates(self):
        """Selectable points in this view: ``(kinds, keys, xy)`` with xy in widget pixels (last picture)."""
        self.image()
        fd = self.session.frame_data()
        if fd is None or not len(self._rows):
            return [], [], np.zeros((0, 2))
        return ["point"] * len(self._rows), [int(fd.ids[r]) for r in self._rows], self._xy

    def pick(self, x: float, y: float):
        """``("point", id)`` nearest widget pixel (x, y) within the pick tolerance, else None."""
        kinds, keys, xy = self.candidates()
        return picking.nearest(kinds, keys, xy, x, y, picking.PICK_TOLERANCE)

    def pick_stick(self, x: float, y: float) -> int | None:
        idx, a, b = self._sticks
        i = picking.nearest_segment(a, b, x, y, picking.PICK_TOLERANCE)
        return None if i is None else idx[i]

    def point_position(self, pid: int) -> tuple[float, float] | None:
        """Widget pixel where point ``pid`` is drawn (None when it is not)."""
        kinds, keys, xy = self.candidates()
        if pid not in keys:
            return None
        x, y = xy[keys.index(pid)]
        return (float(x), float(y)) if np.isfinite(x) else None

    # ================================================================= mouse
    def mousePressEvent(self, ev) -> None:  # noqa: N802
        M, B = Qt.KeyboardModifier, Qt.MouseButton
        mods, btn, buttons = ev.modifiers(), ev.button(), ev.buttons()
        nav = bool(mods & (M.ShiftModifier | M.AltModifier))
        both = bool(mods & M.ShiftModifier) and bool(mods & M.AltModifier)
        self._press = (btn, mods, ev.position())
        self._last = ev.position()
        if self.session.project is None:
            self._mode = ""
        elif btn == B.MiddleButton or (nav and buttons & B.LeftButton and buttons & B.RightButton):
            self._mode = "pan"
        elif btn == B.RightButton:
            self._mode = "zoom" if nav else "menu"
        elif btn == B.LeftButton:
            if both:
                self._mode = "lasso"
            elif nav:
                self._mode = "rotate"
            else:
                self._mode = "click"
        ev.accept()

    def mouseMoveEvent(self, ev) -> None:  # noqa: N802
        pos = ev.position()
        if self._press is None:
            if self.session.project is not None:
                self.session.set_hover(self.pick(pos.x(), pos.y()))
            return
        dx, dy = pos.x() - self._last.x(), pos.y() - self._last.y()
        self._last = pos
        start = self._press[2]
        moved = (pos - start).manhattanLength() >= DRAG_START_PX
        if self._mode == "rotate":
            self.camera.orbit(dx, dy)
        elif self._mode == "zoom":
            self.camera.zoom(float(np.exp(dy / 150.0)))
        elif self._mode == "pan":
            self.camera.pan(dx, dy)
        elif self._mode in ("click", "lasso") and moved:
            self._region = picking.RegionDrag(start, lasso=self._mode == "lasso")
            self._mode = "region"
        elif self._mode == "menu" and moved:
            self._mode = ""
        if self._mode == "region":
            self._region.move(pos)
        self.refresh()

    def mouseReleaseEvent(self, ev) -> None:  # noqa: N802
        M = Qt.KeyboardModifier
        if self._press is None:
            return
        mods = ev.modifiers()
        pos = ev.position()
        ses = self.session
        mode, self._mode, self._press = self._mode, "", None
        if mode == "click":
            hit = self.pick(pos.x(), pos.y())
            picking.click(ses, hit, self.pick_stick(pos.x(), pos.y()) if hit is None else None,
                          bool(mods & M.ControlModifier))
        elif mode == "region" and self._region is not None:
            kinds, keys, xy = self.candidates()
            self._region.select(ses, kinds, keys, xy, add=bool(mods & M.ControlModifier))
        elif mode == "menu":
            self.contextRequested.emit(self, ev.globalPosition().toPoint())
        self._region = None
        self.refresh()

    def wheelEvent(self, ev) -> None:  # noqa: N802
        steps = ev.angleDelta().y() / 120.0
        if steps:
            self.camera.zoom(0.85 ** steps)
            self.refresh()
        ev.accept()

    def leaveEvent(self, ev) -> None:  # noqa: N802
        if self.session.project is not None and self._press is None:
            self.session.set_hover(None)
        super().leaveEvent(ev)
