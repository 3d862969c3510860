"""The views' context menus (2D, 3D, Graph, Continuity), switching views, New Floating Workspace."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QPoint, Qt
from PySide6.QtWidgets import QMenu

from carapost.core.actions import CONTEXT_2D, CONTEXT_3D, CONTEXT_CONTINUITY, CONTEXT_GRAPH, CONTEXT_MENUS, \
    menu_actions
from carapost.core.points import SRC_DETECTION, ST_RECONSTRUCTED
from carapost.gui.cameraview import CameraView
from carapost.gui.continuity import ContinuityChart
from carapost.gui.graphview import GraphView
from carapost.gui.view3d import View3D

from guihelpers import make_window

pytestmark = pytest.mark.gui

KIND_OF = {CONTEXT_2D: ("sensor", "Sensor 1"), CONTEXT_3D: ("3d", "3D"), CONTEXT_GRAPH: ("graph", "Graph"),
           CONTEXT_CONTINUITY: ("continuity", "Continuity")}
WIDGET_OF = {"sensor": CameraView, "3d": View3D, "graph": GraphView, "continuity": ContinuityChart}


@pytest.fixture
def win(qtbot, take):
    p, truth = take
    for i in range(truth.shape[1]):
        pt = p.new_point(point_id=i, label=f"M{i:02d}")
        pt.pos[:] = truth[:, i]
        pt.status[:] = ST_RECONSTRUCTED
        pt.src[:] = SRC_DETECTION
        p.add_point(pt)
    return make_window(qtbot, p)


def _titles(menu: QMenu) -> list[str]:
    return [a.text() for a in menu.actions() if not a.isSeparator()]


def _submenu(menu: QMenu, title: str) -> QMenu:
    return next(a.menu() for a in menu.actions() if a.text() == title)


def _switch(grid, index: int, title: str):
    """Choose ``title`` in the View submenu of slot ``index``'s context menu."""
    menu = grid.build_context_menu(grid.slot_widget(index))
    next(a for a in _submenu(menu, "View").actions() if a.text() == title).trigger()
    menu.deleteLater()
    return grid.slot_widget(index)


def test_view_submenu_switches_a_slot_to_every_kind(win):
    grid = win.grid
    menu = grid.build_context_menu(grid.slot_widget(0))
    assert _titles(_submenu(menu, "View")) == ["3D", "Graph", "Continuity", "Sensor 0", "Sensor 1", "Sensor 2",
                                                "Sensor 3"]
    for title, cls in (("3D", View3D), ("Graph", GraphView), ("Continuity", ContinuityChart)):
        w = _switch(grid, 0, title)
        assert isinstance(w, cls) and w.isVisible() and not grid.views[0].isVisible()
        checked = [a.text() for a in _submenu(grid.build_context_menu(w), "View").actions() if a.isChecked()]
        assert checked == [title]
    cam = _switch(grid, 0, "Sensor 2")
    assert cam is grid.views[0] and cam.sensor == 2 and cam.isVisible() and grid.kinds[0] == "sensor"
    assert isinstance(_switch(grid, 0, "3D"), View3D) and grid.kinds[0] == "3d"    # the same 3D view again


@pytest.mark.parametrize("context", CONTEXT_MENUS)
def test_every_registry_item_is_in_its_menu_enabled(win, context):
    kind, title = KIND_OF[context]
    w = _switch(win.grid, 1, title)
    assert isinstance(w, WIDGET_OF[kind])
    menu = win.grid.build_context_menu(w)
    titles = _titles(menu)
    items = menu_actions(context)
    assert items and [a.title for a in items] == [t for t in titles if t in {a.title for a in items}]
    for a in items:
        qa = win.action(a.id)
        assert qa in menu.actions(), a.title
        assert qa.isEnabled() == a.available, a.title
    assert ("Sensor" in titles) == (kind in ("sensor", "graph"))
    # other kinds' items are not in this menu
    others = {a.id for c in CONTEXT_MENUS if c != context for a in menu_actions(c)}
    assert not others & {qa.objectName() for qa in menu.actions()}


@pytest.mark.parametrize("context", CONTEXT_MENUS)
def test_every_item_runs_its_handler(win, monkeypatch, context):
    calls = []
    for a in menu_actions(context):
        if not a.available:
            continue
        owner, method = a.handler.split(".", 1)
        monkeypatch.setattr(getattr(win, owner), method,
                            lambda *args, _h=a.handler: calls.append((_h, args)))
    for a in menu_actions(context):
        win.action(a.id).trigger()
    assert calls == [(a.handler, (a.arg,) if a.arg else ()) for a in menu_actions(context) if a.available]


def test_3d_display_toggles_change_what_is_drawn(win):
    v = _switch(win.grid, 0, "3D")
    v.image()
    d = win.session.display
    for aid, name in (("view3d.face_points", "face_points"), ("view3d.brim_points", "brim_points"),
                      ("view3d.reconstruction_colors", "reconstruction_colors"), ("view3d.cameras", "cameras"),
                      ("view3d.rays", "rays"), ("view3d.rom", "rom_3d"), ("view3d.sticks", "sticks_3d")):
        qa = win.action(aid)
        assert qa.isChecked() and getattr(d, name)
        qa.trigger()
        assert not qa.isChecked() and not getattr(d, name), aid
    assert v.candidates()[0] == []          # no face points drawn: nothing to pick
    assert len(v.build_scene().lines) == 3  # the world axes only


def test_graph_and_continuity_items_act_on_the_view_right_clicked(win):
    grid = win.grid
    g1, g2 = _switch(grid, 1, "Graph"), _switch(grid, 2, "Graph")
    chart = _switch(grid, 3, "Continuity")
    grid.show_context_menu(g2, QPoint(0, 0))
    win.action("graph.track_data").trigger()
    assert g1.track_data and not g2.track_data
    grid.show_context_menu(g1, QPoint(0, 0))
    assert win.action("graph.track_data").isChecked()       # the menu shows the clicked graph's own state
    win.action("graph.recon_data").trigger()
    assert not g1.recon_data and g2.recon_data
    grid.show_context_menu(g2, QPoint(0, 0))
    assert not win.action("graph.track_data").isChecked() and win.action("graph.recon_data").isChecked()
    win.session.select(points=[0, 1])
    grid.show_context_menu(chart, QPoint(0, 0))
    win.action("continuity.expand_all").trigger()
    assert chart.rows == chart.build_rows() and len(chart.rows) == 12 * 5
    win.action("continuity.collapse_all").trigger()
    assert len(chart.rows) == 12


def test_right_click_in_the_3d_view_opens_its_menu(qtbot, win):
    v = _switch(win.grid, 0, "3D")
    qtbot.mouseClick(v, Qt.MouseButton.RightButton, pos=QPoint(20, 20))
    menu = win.grid.open_menu
    assert menu is not None and menu.isVisible()
    titles = _titles(menu)
    assert titles[0] == "View" and [a.title for a in menu_actions(CONTEXT_3D)] == titles[1:]
    assert win.grid.context_target("3d") is v
    menu.close()
    qtbot.waitUntil(lambda: win.grid.open_menu is None, timeout=2000)


def test_new_floating_workspace_opens_a_3d_window(qtbot, win):
    win.action("view.new_workspace").trigger()
    assert len(win.views.workspaces) == 1
    ws = win.views.workspaces[0]
    qtbot.waitExposed(ws)
    grid = win.views.grids[0]
    assert ws.isVisible() and ws.isWindow() and grid.window() is ws
    v = grid.slot_widget(0)
    assert isinstance(v, View3D) and v.isVisible() and grid.kinds[0] == "3d"
    assert [s.isVisibleTo(grid) for s in grid.slots] == [True, False, False, False]
    # the workspace has every choice of the main one, and its menu acts on its own view
    main3d = _switch(win.grid, 0, "3D")
    main3d.image()
    v.image()
    win.session.select(points=[4])
    grid.show_context_menu(v, QPoint(0, 0))
    before = main3d.camera.target.copy()
    win.action("view3d.center_selection").trigger()
    np.testing.assert_allclose(v.point_position(4), (v.width() / 2, v.height() / 2), atol=1.0)
    np.testing.assert_allclose(main3d.camera.target, before)
    cam = _switch(grid, 0, "Sensor 3")
    assert isinstance(cam, CameraView) and cam.sensor == 3
    win.action("view.new_workspace").trigger()
    assert len(win.views.workspaces) == 2 and win.views.workspaces[1] is not ws
    # closing a workspace deletes it; the session's next changes reach only the live views
    ws.close()
    qtbot.waitUntil(lambda: len(win.views.workspaces) == 1 and len(win.views.grids) == 1, timeout=2000)
    assert win.views.grids[0] is not grid
    win.navigate.step(1)
    win.session.select(points=[5])
    qtbot.wait(10)
    assert win.views.grids[0].slot_widget(0).image() is not None
