"""The 3D view: what its OpenGL picture shows where, picking, lasso, navigation, display options."""
from __future__ import annotations

import sys
import types

import numpy as np
import pytest
from PySide6.QtCore import QPoint, Qt

from carapost.core.points import BRIM, SRC_DETECTION, SRC_NONE, SRC_PATCH, ST_INTERPOLATED, ST_RECONSTRUCTED
from carapost.gui import render3d
from carapost.gui.render3d import RenderUnavailable, shared_renderer
from carapost.gui.view3d import COLORS, View3D

from guihelpers import drag_widget, make_window

pytestmark = pytest.mark.gui

try:
    shared_renderer()
    GL_ERROR = ""
except RenderUnavailable as e:       # only a machine without EGL / Mesa
    GL_ERROR = str(e)
needs_gl = pytest.mark.skipif(bool(GL_ERROR), reason=f"no OpenGL context can be created here: {GL_ERROR}")

INTERPOLATED, PATCHED, BRIM_ID = 3, 5, 100


def _populate(p, truth):
    """A point per marker (3D = truth, detections in every sensor), one interpolated, one patch-matched, a brim point."""
    for i in range(truth.shape[1]):
        pt = p.new_point(point_id=i, label=f"M{i:02d}")
        pt.pos[:] = truth[:, i]
        pt.status[:] = ST_RECONSTRUCTED
        pt.src[:] = SRC_DETECTION
        if i == INTERPOLATED:
            pt.status[:] = ST_INTERPOLATED
            pt.src[:] = SRC_NONE
        if i == PATCHED:
            pt.src[:, 1] = SRC_PATCH
        p.add_point(pt)
    b = p.new_point(kind=BRIM, point_id=BRIM_ID, brim_index=0)
    b.pos[:] = [0.0, 130.0, -20.0]
    b.status[:] = ST_RECONSTRUCTED
    p.add_point(b)


@pytest.fixture
def win(qtbot, take):
    p, truth = take
    _populate(p, truth)
    w = make_window(qtbot, p)
    w.grid.set_layout("2")
    w.grid.set_slot_kind(1, "3d")
    qtbot.waitUntil(lambda: w.grid.slot_widget(1).isVisible(), timeout=2000)
    return w


def _view(win) -> View3D:
    return win.grid.slot_widget(1)


def _pixel(img, xy):
    x, y = int(np.floor(xy[0])), int(np.floor(xy[1]))
    return tuple(int(c) for c in img[y, x, :3])


def _projected(view, X):
    """Widget pixels of world points through the camera's OpenGL matrices (not through ``camera.project``)."""
    cam = view.camera
    near, far = cam.clip_planes(100.0)
    M = cam.projection_matrix(near, far) @ cam.view_matrix()
    h = np.c_[np.asarray(X, float).reshape(-1, 3), np.ones(len(X))] @ M.T
    ndc = h[:, :2] / h[:, 3:4]
    return np.stack([(ndc[:, 0] + 1) / 2 * cam.width, (ndc[:, 1] + 1) / 2 * cam.height], axis=1)


def _isolated(xy, min_px=12.0):
    """Indices of positions at least ``min_px`` from every other (no dot covers their centre)."""
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    np.fill_diagonal(d, np.inf)
    return [i for i in range(len(xy)) if d[i].min() >= min_px]


@needs_gl
def test_points_drawn_at_their_projection_in_reconstruction_colours(win, take):
    p, truth = take
    v = _view(win)
    img = v.image()
    assert img.shape == (v.height(), v.width(), 4)
    f = win.session.frame
    ids = list(range(truth.shape[1])) + [BRIM_ID]
    X = np.array([p.points[i].pos[f] for i in ids], float)
    xy = _projected(v, X)
    np.testing.assert_allclose(xy, v.camera.project(X), atol=1e-6)
    inside = (xy[:, 0] > 5) & (xy[:, 0] < v.width() - 5) & (xy[:, 1] > 5) & (xy[:, 1] < v.height() - 5)
    assert inside.all(), "Fit on open shows every point"
    checked = set()
    for k in _isolated(xy):
        pid = ids[k]
        want = {INTERPOLATED: "predicted", PATCHED: "patch", BRIM_ID: "brim"}.get(pid, "measured")
        assert _pixel(img, xy[k]) == COLORS[want], (pid, want)
        checked.add(want)
    assert {"measured", "predicted", "patch", "brim"} <= checked
    # far from every point and line: the background
    assert _pixel(img, (2, v.height() - 3)) == COLORS["background"]


@needs_gl
def test_reconstruction_type_colors_off_draws_every_face_point_yellow(win, take):
    v = _view(win)
    xy = v.point_position(INTERPOLATED)
    assert _pixel(v.image(), xy) == COLORS["predicted"]
    win.action("view3d.reconstruction_colors").trigger()
    assert not win.session.display.reconstruction_colors
    assert _pixel(v.image(), xy) == COLORS["measured"]
    win.action("view3d.face_points").trigger()          # Face Points off: nothing there, brim still drawn
    img = v.image()
    assert _pixel(img, xy) == COLORS["background"]
    assert v.point_position(INTERPOLATED) is None and v.point_position(BRIM_ID) is not None


@needs_gl
def test_click_picks_the_point_under_the_mouse(qtbot, win, take):
    v = _view(win)
    xy = v.camera.project(np.array([p.pos[win.session.frame] for p in take[0].points.values()]))
    ids = list(take[0].points)
    a, b = [ids[k] for k in _isolated(xy, 25)[:2]]
    pa, pb = v.point_position(a), v.point_position(b)
    qtbot.mouseClick(v, Qt.MouseButton.LeftButton, pos=QPoint(int(pa[0] + 2), int(pa[1] - 2)))
    assert win.session.selection.points == [a]
    qtbot.mouseClick(v, Qt.MouseButton.LeftButton, Qt.KeyboardModifier.ControlModifier,
                     QPoint(int(pb[0]), int(pb[1])))
    assert win.session.selection.points == [a, b]
    img = v.image()
    assert _pixel(img, (pa[0] + 6, pa[1])) == COLORS["selected"]        # the white disc around it
    qtbot.mouseClick(v, Qt.MouseButton.LeftButton, pos=QPoint(3, v.height() - 3))
    assert win.session.selection.points == []


@needs_gl
def test_rectangle_and_lasso_select_what_they_enclose(qtbot, win, take):
    v = _view(win)
    kinds, keys, xy = v.candidates()
    xs = np.sort(xy[:, 0])
    k = int(np.argmax(np.diff(xs[3:-3]))) + 3          # split between two points, a few on each side
    c = np.array([(xs[k] + xs[k + 1]) / 2, np.nanmedian(xy[:, 1])])
    drag_widget(v, [(c[0], c[1] - 400), (c[0] + 400, c[1] - 400), (c[0] + 400, c[1] + 400)])
    right = {k for k, (x, y) in zip(keys, xy) if x > c[0]}
    assert right and set(win.session.selection.points) == right
    # Shift+Alt lasso: a triangle left of the centre
    tri = [(c[0] - 1, c[1] - 500), (c[0] - 1, c[1] + 500), (c[0] - 600, c[1])]
    drag_widget(v, tri + [tri[0]], Qt.KeyboardModifier.ShiftModifier | Qt.KeyboardModifier.AltModifier)
    from PySide6.QtCore import QPointF
    from PySide6.QtGui import QPolygonF

    poly = QPolygonF([QPointF(*t) for t in tri])
    inside = {k for k, (x, y) in zip(keys, xy) if poly.containsPoint(QPointF(x, y), Qt.FillRule.OddEvenFill)}
    assert inside and set(win.session.selection.points) == inside


@needs_gl
def test_rotate_zoom_pan_with_the_guides_bindings(qtbot, win):
    v = _view(win)
    v.image()
    cam = v.camera
    c = (v.width() / 2, v.height() / 2)
    R0, d0, t0 = cam.rotation.copy(), cam.distance, cam.target.copy()
    drag_widget(v, [c, (c[0] + 60, c[1] + 20)], Qt.KeyboardModifier.AltModifier)          # rotate
    assert not np.allclose(cam.rotation, R0) and np.allclose(cam.target, t0) and cam.distance == d0
    assert win.session.selection.points == []                                            # not a selection
    drag_widget(v, [c, (c[0], c[1] + 80)], Qt.KeyboardModifier.ShiftModifier, Qt.MouseButton.RightButton)
    assert cam.distance > d0 * 1.3                                                       # dragging down zooms out
    R1, d1, t1 = cam.rotation.copy(), cam.distance, cam.target.copy()
    before = cam.project(t1)
    drag_widget(v, [c, (c[0] + 40, c[1])], Qt.KeyboardModifier.ShiftModifier, Qt.MouseButton.MiddleButton)
    assert not np.allclose(cam.target, t1) and np.allclose(cam.rotation, R1) and cam.distance == d1
    # what was under the mouse moved with it, 40 px to the right
    np.testing.assert_allclose(cam.project(t1) - before, [[40.0, 0.0]], atol=0.5)


@needs_gl
def test_center_and_frame_selection_and_fit_to_points(win, take):
    v = _view(win)
    v.image()
    win.session.select(points=[2])
    win.grid.note_context(v)
    win.action("view3d.center_selection").trigger()
    np.testing.assert_allclose(v.point_position(2), (v.width() / 2, v.height() / 2), atol=1.0)
    win.session.select(points=[0, 1])
    win.action("view3d.frame_selection").trigger()
    a, b = np.array(v.point_position(0)), np.array(v.point_position(1))
    span = np.abs(a - b).max() / min(v.width(), v.height())
    assert 0.3 < span < 1.0 and all(0 < q[0] < v.width() and 0 < q[1] < v.height() for q in (a, b))
    win.session.select()
    win.action("view3d.fit_to_points").trigger()          # nothing selected: every point
    _k, _keys, xy = v.candidates()
    assert np.all((xy > 0) & (xy < [v.width(), v.height()]))


@needs_gl
def test_rays_cameras_and_sticks_in_the_scene(win, take):
    from carapost.core.project import Stick

    p = take[0]
    v = _view(win)
    f = win.session.frame
    win.session.select(points=[0])
    scene = v.build_scene()
    cams = [p.rig.camera(k, f).position for k in range(4)]
    ends = {tuple(np.round(s[1], 3)) for s in scene.lines if np.allclose(s[0], p.points[0].pos[f])}
    assert ends == {tuple(np.round(c, 3)) for c in cams}            # a ray to each camera with its 2D data
    win.session.select(points=[INTERPOLATED])                        # no 2D data: no ray
    assert not any(np.allclose(s[0], p.points[INTERPOLATED].pos[f]) for s in v.build_scene().lines)
    n = len(v.build_scene().lines)
    win.action("view3d.cameras").trigger()
    assert len(v.build_scene().lines) == n - 4 * 9                   # nine segments per frustum
    p.sticks.append(Stick(0, 1, (255, 0, 255)))
    win.session.doc._notify("project")
    scene = v.build_scene()
    k = [i for i, s in enumerate(scene.lines) if np.allclose(s, [p.points[0].pos[f], p.points[1].pos[f]])]
    assert k and np.allclose(scene.line_colors[k[0]], [1, 0, 1, 1])
    win.action("view3d.sticks").trigger()
    assert not any(np.allclose(s, [p.points[0].pos[f], p.points[1].pos[f]]) for s in v.build_scene().lines)


@needs_gl
def test_frame_step_redraws_the_moving_points(win, take):
    p = take[0]
    v = _view(win)
    a = v.point_position(0)
    win.navigate.step(1)
    b = v.point_position(0)
    assert not np.allclose(a, b)
    np.testing.assert_allclose(b, v.camera.project(p.points[0].pos[1])[0], atol=1e-6)


@needs_gl
def test_shows_stabilized_positions_when_the_document_asks(win, take, monkeypatch):
    """The view reads ``carapost.core.stabilize.stabilized_positions`` (stand-in here: x + 10 mm)."""
    p = take[0]
    fake = types.ModuleType("carapost.core.stabilize")

    def stabilized_positions(project, frame, point_ids):
        return np.array([project.points[i].pos[frame] for i in point_ids], float) + [10.0, 0, 0]

    fake.stabilized_positions = stabilized_positions
    monkeypatch.setitem(sys.modules, "carapost.core.stabilize", fake)
    v = _view(win)
    f = win.session.frame
    raw = v.point_position(0)
    win.session.doc.set_show_stabilized(True)          # what Ctrl+Shift+S does
    moved = v.point_position(0)
    np.testing.assert_allclose(moved, v.camera.project(p.points[0].pos[f] + [10.0, 0, 0])[0], atol=1e-6)
    assert not np.allclose(raw, moved)


@needs_gl
def test_rom_points_are_pale_blue_dots(win, monkeypatch):
    """The view draws what ``carapost.core.rom_ops.rom_points_3d`` gives (stand-in here: one point)."""
    from carapost.core import rom_ops

    v = _view(win)
    X = np.array([[0.0, -130.0, -20.0]])
    monkeypatch.setattr(rom_ops, "rom_points_3d", lambda project: X)
    v.refresh()
    xy = v.camera.project(X)[0]
    assert _pixel(v.image(), xy) == COLORS["rom"]
    win.action("view3d.rom").trigger()
    assert _pixel(v.image(), xy) == COLORS["background"]
    monkeypatch.setattr(rom_ops, "rom_points_3d", lambda project: np.zeros((0, 3)))    # no ROM loaded
    win.action("view3d.rom").trigger()
    assert _pixel(v.image(), xy) == COLORS["background"]


@needs_gl
def test_labels_follow_point_labels_all(win):
    v = _view(win)
    v.image()
    assert v._labels == []
    win.action("view3d.labels_all").trigger()
    v.image()
    texts = {t for _x, _y, t, _c in v._labels}
    assert {f"M{i:02d}" for i in range(12)} <= texts
    x, y, _t, _c = next(lb for lb in v._labels if lb[2] == "M00")
    np.testing.assert_allclose((x, y), v.point_position(0), atol=1e-6)


def test_without_opengl_the_view_says_so(qtbot, take, monkeypatch):
    monkeypatch.setattr(render3d, "_shared", {"error": RenderUnavailable("no OpenGL context on EGL: test")})
    w = make_window(qtbot, take[0])
    w.grid.set_slot_kind(0, "3d")
    v = w.grid.slot_widget(0)
    assert v.renderer is None and "needs OpenGL" in v.error and "EGL" in v.error
    assert v.image() is None and v.pick(10, 10) is None
    img = v.grab().toImage()                 # paints the message, no exception
    assert img.width() == v.width()
    qtbot.mouseClick(v, Qt.MouseButton.LeftButton, pos=QPoint(10, 10))
    assert w.session.selection.points == []


@needs_gl
def test_show_stabilized_without_a_stabilisation_shows_the_raw_data(win, take):
    """Through the real ``stabilized_positions``: with nothing stabilised it gives the raw positions."""
    v = _view(win)
    raw = v.point_position(0)
    win.session.doc.set_show_stabilized(True)
    np.testing.assert_allclose(v.point_position(0), raw, atol=1e-6)
    assert "(stabilized)" in v._hud()
