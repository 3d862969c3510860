"""Continuity chart, Selected Point pane and Graph view on a synthetic take with known gaps."""
from __future__ import annotations

import numpy as np
import pytest

from carapost.core import continuity as C
from carapost.core.commands import Command
from carapost.core.points import SRC_DETECTION, SRC_KEYFRAME, SRC_PATCH, SRC_TARGET, ST_INTERPOLATED, ST_NONE, \
    ST_RECONSTRUCTED
from carapost.gui.continuity import ContinuityChart
from carapost.gui.graphview import GraphView

pytestmark = pytest.mark.gui


def _add_points(p):
    """Point A: 4 channels, a gap on frames 4-5, frame 8 interpolated; B: 2 channels, patch/target in sensor 1."""
    a = p.new_point(label="A")
    a.status[:] = ST_RECONSTRUCTED
    a.src[:] = SRC_DETECTION
    a.pos[:] = [1.0, 2.0, 3.0]
    a.uv[:, 0] = [100.0, 200.0]
    a.status[4:6] = ST_NONE
    a.src[4:6] = 0
    a.status[8] = ST_INTERPOLATED
    a.src[8] = 0
    p.add_point(a)
    b = p.new_point(label="B")
    b.status[:] = ST_RECONSTRUCTED
    b.src[:, 0] = SRC_DETECTION
    b.src[:, 1] = SRC_PATCH
    b.src[2, 1] = SRC_KEYFRAME
    b.src[3, 1] = SRC_TARGET
    b.score[3, 1] = 0.0
    b.pos[:] = [5.0, 6.0, 7.0]
    p.add_point(b)
    return a, b


@pytest.fixture
def win(window, take):
    a, b = _add_points(take[0])
    window.session.doc._notify("project")
    window.pts = (a, b)
    return window


def _switch(grid, index, text):
    menu = grid.build_context_menu(grid.slot_widget(index))
    view_menu = next(a.menu() for a in menu.actions() if a.text() == "View")
    next(a for a in view_menu.actions() if a.text() == text).trigger()
    menu.deleteLater()
    return grid.slot_widget(index)


def test_view_menu_switches_slot_to_continuity_graph_and_back(qtbot, win):
    grid = win.grid
    chart = _switch(grid, 1, "Continuity")
    assert isinstance(chart, ContinuityChart) and chart.isVisible() and not grid.views[1].isVisible()
    assert grid.views[1] not in grid.visible_views()
    menu = grid.build_context_menu(chart)
    titles = [a.text() for a in menu.actions()]
    assert {"View", "Collapse All", "Expand All", "Fit To Data"} <= set(titles)
    view_menu = next(a.menu() for a in menu.actions() if a.text() == "View")
    three_d = next(a for a in view_menu.actions() if a.text() == "3D")
    assert three_d.isEnabled()
    graph = _switch(grid, 2, "Graph")
    assert isinstance(graph, GraphView) and graph.isVisible()
    titles = [a.text() for a in grid.build_context_menu(graph).actions()]
    assert {"Fit To Data", "Track Data", "Recon Data", "Sensor"} <= set(titles)
    cam = _switch(grid, 1, "Sensor 3")
    assert cam is grid.views[1] and cam.sensor == 3 and cam.isVisible() and grid.kinds[1] == "sensor"


def test_chart_colours_expand_click_and_marker(qtbot, win):
    a, b = win.pts
    chart = _switch(win.grid, 0, "Continuity")
    img = chart.image.image
    assert chart.bin == 1 and chart.first == 0 and img.shape[:2] == (2, 12)   # one image: rows x frames
    ra, rb = chart.row_of(a.id), chart.row_of(b.id)
    want = C.point_rgba(a)
    np.testing.assert_array_equal(img[ra], want)
    assert tuple(img[ra, 0]) == C.COLORS["dark_green"]
    assert img[ra, 4, 3] == 0 and img[ra, 5, 3] == 0                  # the gap is transparent
    assert chart.color_at(a.id, 8) == C.COLORS["red"]
    assert chart.color_at(b.id, 0) == C.COLORS["yellow"]
    # the drawn pixels: a gap shows the background, a bar its colour
    qtbot.waitExposed(chart)
    shot = chart.grab().toImage()
    pt = chart.mapFromScene(chart.vb.mapViewToScene(chart.vb.mapToView(chart.vb.mapFromView(
        __import__("PySide6.QtCore", fromlist=["QPointF"]).QPointF(0, ra + 0.5)))))
    px = shot.pixelColor(pt)
    assert (px.red(), px.green(), px.blue()) == C.COLORS["dark_green"][:3]
    # double-click expands B into its channel rows
    chart.click_at(0, rb, double=True)
    assert b.id in chart.expanded and chart.row_of(b.id, 1) == rb + 2
    assert chart.color_at(b.id, 0, 1) == C.COLORS["patch"]
    assert chart.color_at(b.id, 2, 1) == C.COLORS["key"]
    assert chart.color_at(b.id, 3, 1) == C.target_color(0.0)
    assert chart.color_at(b.id, 0, 0) == C.COLORS["blob"]
    assert chart.color_at(b.id, 0, 2) == C.COLORS["gap"]
    chart.expand_all()
    assert len(chart.rows) == 10
    chart.collapse_all()
    assert len(chart.rows) == 2
    # click selects the point and goes to the frame; the marker follows
    chart.click_at(7, chart.row_of(a.id))
    assert win.session.selection.points == [a.id] and win.session.frame == 7
    assert chart.marker.value() == 7
    chart.fit_to_data()
    (x0, x1), (y0, y1) = chart.vb.viewRange()
    assert y0 == pytest.approx(ra) and y1 == pytest.approx(ra + 1)


def test_chart_follows_edits(qtbot, win):
    a, _b = win.pts
    chart = _switch(win.grid, 0, "Continuity")
    assert chart.color_at(a.id, 10) == C.COLORS["dark_green"]

    class Cut(Command):
        name = "cut"

        def do(self, project):
            self.saved = a.slice_copy(10, 11)
            a.clear_range(10, 11)

        def undo(self, project):
            a.restore_slice(10, self.saved)

    win.session.run(Cut())
    assert chart.color_at(a.id, 10) == C.COLORS["gap"]
    assert win.selected_point.color_at(10) is None             # nothing selected
    win.session.doc.undo()
    assert chart.color_at(a.id, 10) == C.COLORS["dark_green"]


def test_selected_point_pane(qtbot, win):
    a, b = win.pts
    pane = win.selected_point
    assert pane.color_at(0) is None and pane.label() == ""
    win.session.select(points=[a.id])
    bars = pane.bars
    img = bars.image.image
    assert img.shape[:2] == (5, 12) and pane.label() == "A"
    np.testing.assert_array_equal(img[0], C.point_rgba(a))
    np.testing.assert_array_equal(img[1:], C.channel_rgba(a))
    assert pane.color_at(4) == C.COLORS["gap"] and pane.color_at(8) == C.COLORS["red"]
    assert pane.color_at(0, 3) == C.COLORS["blob"]
    win.session.select(points=[b.id])
    assert pane.label() == "B" and pane.color_at(3, 1) == C.target_color(0.0)
    win.session.select(points=[a.id, b.id])
    assert pane.color_at(0) is None                             # several: empty
    assert not bars.image.isVisible()


def test_graph_lines(qtbot, win):
    a, b = win.pts
    graph = _switch(win.grid, 3, "Graph")
    win.session.select(points=[a.id])
    assert [n for _p, n in graph.lines] == ["x", "y", "z", "u", "v"]       # seen in sensor 0: five lines
    assert graph.curves[0].opts["pen"].color().getRgb()[:3] == (230, 50, 50)
    np.testing.assert_allclose(graph.curves[2].yData[0], 3.0)
    np.testing.assert_allclose(graph.curves[3].yData[0], 100.0)
    graph.set_sensor(1)
    assert len(graph.lines) == 3                                              # not seen in sensor 1
    graph.set_recon_data(False)
    assert graph.lines == []
    graph.set_recon_data(True)
    win.session.select(points=[a.id, b.id])
    assert len(graph.lines) == 6
    win.session.doc.set_frame(6)
    assert graph.marker.value() == 6
