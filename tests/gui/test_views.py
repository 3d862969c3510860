"""Camera views: selection by click, rectangle and lasso; sensors; rotation; zoom; display options."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt

from carapost.core.detections import make_detections
from guihelpers import click_raw, det_xy, drag_raw, key

CTRL, SHIFT, ALT = Qt.KeyboardModifier.ControlModifier, Qt.KeyboardModifier.ShiftModifier, Qt.KeyboardModifier.AltModifier
pytestmark = pytest.mark.gui


def _dets_in(p, s, f, lo, hi):
    rec = p.detections[s].frame(f)
    x, y = rec["x"], rec["y"]
    return {(s, f, int(i)) for i in np.flatnonzero((x >= lo[0]) & (x <= hi[0]) & (y >= lo[1]) & (y <= hi[1]))}


def test_rectangle_and_lasso_select_detections(qtbot, window, take):
    p, _ = take
    v = window.grid.views[2]
    rec = p.detections[2].frame(0)
    lo = (float(np.min(rec["x"][:12])) - 5, float(np.min(rec["y"][:12])) - 5)
    mid = (float(np.median(rec["x"][:12])), float(np.median(rec["y"][:12])))
    drag_raw(qtbot, v, lo, mid)
    want = _dets_in(p, 2, 0, lo, mid)
    assert want and set(window.session.selection.detections) == want
    # Ctrl+drag adds; a lasso (Shift+Alt) around one detection selects only it
    x, y = det_xy(p, 2, 0, 5)
    ring = [(x + 15 * np.cos(t), y + 15 * np.sin(t)) for t in np.linspace(0, 2 * np.pi, 9)]
    drag_raw(qtbot, v, ring[0], ring[-1], mods=SHIFT | ALT, via=ring[1:-1])
    assert window.session.selection.detections == [(2, 0, 5)]


def test_click_empty_clears_and_ctrl_click_toggles(qtbot, window, take):
    p, _ = take
    v = window.grid.views[0]
    click_raw(qtbot, v, *det_xy(p, 0, 0, 4))
    click_raw(qtbot, v, *det_xy(p, 0, 0, 4), mods=CTRL)
    assert window.session.selection.detections == []
    click_raw(qtbot, v, *det_xy(p, 0, 0, 4))
    click_raw(qtbot, v, 5, 5)
    assert window.session.selection.is_empty()


def test_selection_switches_gate_what_clicks_select(qtbot, window, take):
    p, _ = take
    window.properties.editor("selection.detections").click()
    assert p.properties["selection.detections"] is False
    click_raw(qtbot, window.grid.views[0], *det_xy(p, 0, 0, 4))
    assert window.session.selection.detections == []


def test_shift_click_selects_sensor_and_ctrl_right_rotates_it(qtbot, window, take):
    p, _ = take
    v1 = window.grid.views[1]
    click_raw(qtbot, v1, 300, 300, mods=SHIFT)
    assert p.channel_selection == [1]
    assert window.selection_pane.boxes[1].isChecked()
    assert "[selected]" in v1.info.text()
    key(qtbot, window, Qt.Key.Key_Right, CTRL)
    assert p.sensors[1].rotation == 1 and p.sensors[0].rotation == 0
    # the view shows it rotated, and clicks still find the right detection
    assert v1.content.transform().m12() == pytest.approx(1.0)
    click_raw(qtbot, v1, *det_xy(p, 1, 0, 6))
    assert window.session.selection.detections == [(1, 0, 6)]
    key(qtbot, window, Qt.Key.Key_Left, CTRL)
    assert p.sensors[1].rotation == 0
    click_raw(qtbot, v1, 300, 300, mods=SHIFT)
    assert p.channel_selection == []


def test_center_and_frame_selection(qtbot, window, take):
    p, _ = take
    v = window.grid.views[0]
    click_raw(qtbot, v, *det_xy(p, 0, 0, 7))
    key(qtbot, window, Qt.Key.Key_C)
    for view in window.grid.visible_views():
        c = view.vb.viewRect().center()
        x, y = det_xy(p, view.sensor, 0, 7) if view.sensor == 0 else (None, None)
        if x is not None:
            assert (c.x(), c.y()) == pytest.approx((x, y), abs=1.0)
    w0 = v.vb.viewRect().width()
    key(qtbot, window, Qt.Key.Key_C, SHIFT)
    assert v.vb.viewRect().width() < w0 / 3          # zoomed onto the selection


def test_hover_pre_selects_and_pixel_report(qtbot, window, take):
    p, _ = take
    v = window.grid.views[0]
    window.views.toggle_display("pixel_report")
    x, y = det_xy(p, 0, 0, 2)
    qtbot.mouseMove(v.viewport(), v.raw_to_viewport(x, y))
    qtbot.waitUntil(lambda: window.session.hover == ("detection", (0, 0, 2)), timeout=2000)
    assert "grey" in v.info.text()
    assert v.items["hover"].count() > 0


def test_mouse_zoom_pan_fit_and_actual_size(qtbot, window):
    v = window.grid.views[0]
    r0 = v.vb.viewRect()
    drag_raw(qtbot, v, (640, 360), (640, 200), mods=SHIFT, button=Qt.MouseButton.RightButton)
    assert v.vb.viewRect().width() != pytest.approx(r0.width())
    v1 = window.grid.views[1]
    r1 = v1.vb.viewRect()
    drag_raw(qtbot, v1, (400, 300), (250, 300), mods=SHIFT, button=Qt.MouseButton.MiddleButton)
    assert v1.vb.viewRect().center().x() == pytest.approx(r1.center().x() + 150, abs=10)
    window.grid.context_view = v
    window.action("view2d.actual_size").trigger()
    assert v.pixel_size() == pytest.approx(1.0, rel=0.05)
    window.action("view2d.fit").trigger()
    assert v.vb.viewRect().contains(v.content.mapRectToParent(v.image_rect()).center())


def test_measurement(qtbot, window):
    v = window.grid.views[0]
    window.grid.context_view = v
    window.action("view2d.start_measurement").trigger()
    drag_raw(qtbot, v, (100, 100), (400, 500))
    assert v.measurement() == pytest.approx(500.0, abs=6)
    assert window.session.selection.is_empty()         # measuring does not select
    window.action("view2d.clear_measurement").trigger()
    assert v.measurement() is None


def test_display_options_and_blob_preview(qtbot, window, take):
    from carapost.gui import blobpreview

    v = window.grid.views[0]
    assert v.image.isVisible()
    window.grid.context_view = v
    window.action("view2d.image").trigger()
    assert not window.session.display.image and not v.image.isVisible() and v.checker.isVisible()
    window.action("view2d.image").trigger()
    assert v.image.isVisible()
    window.action("view2d.detections").trigger()
    assert v.items["detections"].count() == 0
    window.action("view2d.detections").trigger()
    assert v.items["detections"].count() > 0
    blobpreview.set_preview(None)                     # a build without blob detection says so
    try:
        key(qtbot, window, Qt.Key.Key_B, CTRL)
        assert window.session.display.blob_preview and window.action("view.blob_preview").isChecked()
        assert window.action("view2d.blob_preview").isChecked()
        assert "not available" in v.info.text()
        blobpreview.set_preview(lambda img, props: make_detections([100.0, 200.0], [100.0, 150.0], 10.0))
        window.grid.refresh()
        assert v.items["preview"].count() == 2 * 12 and "not available" not in v.info.text()
        blobpreview.reset()                           # the real detector finds the dark markers
        window.grid.refresh()
        assert v.items["preview"].count() >= 12 * 10
    finally:
        blobpreview.reset()
    key(qtbot, window, Qt.Key.Key_B, CTRL)
    assert not window.session.display.blob_preview


def test_layout_buttons_and_context_menu(qtbot, window):
    grid = window.grid
    one = next(b for b in grid.buttons.buttons() if b.text() == "1")
    qtbot.mouseClick(one, Qt.MouseButton.LeftButton)
    assert len(grid.visible_views()) == 1
    four = next(b for b in grid.buttons.buttons() if b.text() == "1x4")
    qtbot.mouseClick(four, Qt.MouseButton.LeftButton)
    assert len(grid.visible_views()) == 4
    menu = grid.build_context_menu(grid.views[0])
    titles = [a.text() for a in menu.actions() if not a.isSeparator()]
    for t in ("View", "Sensor", "Fit To Window", "Actual Size", "Start Measurement", "Clear Measurement",
              "Center Selection", "Frame Selection", "Border", "Image", "Detections", "Points", "Projections",
              "Connected", "Unconnected", "Errors", "Blob Preview", "Pixel Report", "ROM", "Sticks",
              "Point Labels: All"):
        assert t in titles, t
    sensor_menu = next(a.menu() for a in menu.actions() if a.text() == "Sensor")
    sensor_menu.actions()[3].trigger()
    assert grid.views[0].sensor == 3


def test_add_and_edit_target_track_modes(qtbot, window, take):
    p, truth = take
    v0, v3 = window.grid.views[0], window.grid.views[3]
    key(qtbot, window, Qt.Key.Key_A, SHIFT)
    assert window.session.click_mode == "add" and "Add Target Track" in v0.info.text()
    uv0 = p.rig.camera(0, 0).project(truth[0, 9])
    click_raw(qtbot, v0, *uv0)
    (pid,) = window.session.selection.points
    assert (0, 0) in p.point(pid).keyframes
    key(qtbot, window, Qt.Key.Key_E, SHIFT)
    assert "Edit Target Track" in v3.info.text()
    click_raw(qtbot, v3, *p.rig.camera(3, 0).project(truth[0, 9]))
    np.testing.assert_allclose(p.point(pid).pos[0], truth[0, 9], atol=0.5)
    key(qtbot, window, Qt.Key.Key_S, SHIFT)
    assert window.session.click_mode == "" and "Target Track" not in v0.info.text()


def test_labels_are_drawn(qtbot, window, take):
    p, _ = take
    v = window.grid.views[0]
    click_raw(qtbot, v, *det_xy(p, 0, 0, 1))
    click_raw(qtbot, window.grid.views[1], *det_xy(p, 1, 0, 1), mods=CTRL)
    key(qtbot, window, Qt.Key.Key_M)
    window.prompts.queue("get_text", "Chin")
    key(qtbot, window, Qt.Key.Key_R, CTRL)
    assert v.labels._texts == ["Chin"]            # selected point's label
    click_raw(qtbot, v, 5, 5)
    assert v.labels._texts == []
    window.grid.context_view = v
    window.action("view2d.labels_all").trigger()
    assert p.properties["display.point_labels_all"] and v.labels._texts == ["Chin"]
