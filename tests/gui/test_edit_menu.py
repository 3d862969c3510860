"""The rest of the Edit and View menus through the window: each item runs one named command."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import QPoint, QPointF, Qt
from PySide6.QtGui import QWheelEvent
from PySide6.QtWidgets import QApplication

from carapost.core.points import SRC_NONE, ST_INTERPOLATED, ST_NONE
from guihelpers import click_raw, det_xy, key, point_at

CTRL, SHIFT = Qt.KeyboardModifier.ControlModifier, Qt.KeyboardModifier.ShiftModifier
pytestmark = pytest.mark.gui


def _points_from(qtbot, win, p, markers):
    """Select detections of ``markers`` in view 0 and Edit > Create Points From Detections."""
    v0 = win.grid.views[0]
    for k, m in enumerate(markers):
        click_raw(qtbot, v0, *det_xy(p, 0, win.session.frame, m), mods=CTRL if k else Qt.KeyboardModifier.NoModifier)
    win.action("edit.create_points").trigger()
    return list(win.session.selection.points)


def test_create_split_clear_and_sticks(qtbot, window, take):
    p, _ = take
    win = window
    a, b, c = _points_from(qtbot, win, p, [1, 2, 3])
    assert win.session.doc.stack.names()[-1] == "Create Points From Detections"
    assert point_at(p, 0, 0, 2).id == b
    win.session.select(points=[a, b])
    key(qtbot, win, Qt.Key.Key_S)                        # Create Stick from Selected Point
    assert [(s.a, s.b) for s in p.sticks] == [(a, b)]
    assert win.grid.views[0].stick_items and sum(i.count() for i in win.grid.views[0].stick_items.values()) == 1
    win.prompts.queue("get_color", (255, 0, 0))
    win.action("edit.edit_stick_color").trigger()
    assert p.sticks[0].color == (255, 0, 0)
    # clicking the stick selects it
    v0 = win.grid.views[0]
    (xa, ya), (xb, yb) = det_xy(p, 0, 0, 1), det_xy(p, 0, 0, 2)
    click_raw(qtbot, v0, 5, 5)
    click_raw(qtbot, v0, (xa + xb) / 2, (ya + yb) / 2)
    assert win.session.selection.sticks == [0] and v0.items["selected_sticks"].count() == 1
    key(qtbot, win, Qt.Key.Key_D, CTRL)                 # Delete Selected deletes the stick
    assert p.sticks == []
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert len(p.sticks) == 1
    win.session.select(points=[a])
    win.action("edit.clear_selected_frame").trigger()
    assert p.point(a).src[0, 0] == SRC_NONE
    # split needs data from the current frame on: give c data on frames 0 and 5
    win.navigate.set_frame(5)
    v0.refresh()
    click_raw(qtbot, v0, *det_xy(p, 0, 5, 3))
    win.session.select(points=[c], detections=[(0, 5, 3)])
    key(qtbot, win, Qt.Key.Key_M)
    win.action("edit.split_point").trigger()
    (new,) = win.session.selection.points
    assert p.point(new).src[5, 0] != SRC_NONE and p.point(c).src[5, 0] == SRC_NONE and p.point(c).src[0, 0] != SRC_NONE
    win.action("edit.clear_active_range").trigger()
    assert all(not np.any(q.src != SRC_NONE) for q in p.points.values())


def test_remove_interpolated_increment_offset_and_blob_parameters(qtbot, window, take):
    p, _ = take
    win = window
    (a,) = _points_from(qtbot, win, p, [4])
    pt = p.point(a)
    pt.status[2:4] = ST_INTERPOLATED
    pt.pos[2:4] = 1.0
    win.session.select(points=[])
    win.action("edit.remove_interpolated").trigger()
    assert (pt.status[2:4] == ST_NONE).all()
    win.session.set_active_sensor(2)
    win.action("edit.increment_offset").trigger()
    assert p.sensors[2].image_offset == 1 and win.session.loader.offsets[2] == 1
    p.pico_blob_parameters = {"blob.black_threshold": "0.55"}
    win.action("edit.read_blob_parameters").trigger()
    assert p.properties["blob.black_threshold"] == pytest.approx(0.55)


def test_keyframe_navigation_view_range_lock_and_timebar_mouse(qtbot, window, take):
    p, truth = take
    win, ses = window, window.session
    key(qtbot, win, Qt.Key.Key_A, SHIFT)
    click_raw(qtbot, win.grid.views[0], *p.rig.camera(0, 0).project(truth[0, 8]))
    (pid,) = ses.selection.points
    win.navigate.set_frame(6)
    key(qtbot, win, Qt.Key.Key_E, SHIFT)
    click_raw(qtbot, win.grid.views[1], *p.rig.camera(1, 6).project(truth[6, 8]))
    key(qtbot, win, Qt.Key.Key_S, SHIFT)
    win.navigate.set_frame(2)
    key(qtbot, win, Qt.Key.Key_Right, SHIFT)           # Next Key Frame
    assert ses.frame == 6
    key(qtbot, win, Qt.Key.Key_Right, SHIFT)           # wraps to the first
    assert ses.frame == 0
    key(qtbot, win, Qt.Key.Key_Left, SHIFT)
    assert ses.frame == 6
    # view range
    win.navigate.set_active_range(2, 7)
    win.action("view.view_to_active").trigger()
    assert p.view_range == (2, 7)
    key(qtbot, win, Qt.Key.Key_End)
    assert ses.frame == 7
    win.action("view.view_reset").trigger()
    assert p.view_range == (0, p.frame_count - 1)
    # timebar: click scrubs, Ctrl+drag sets the active range, the wheel shuttles
    tb = win.time.timebar
    x3, x9 = int(tb.x_of(3)), int(tb.x_of(9))
    qtbot.mouseClick(tb, Qt.MouseButton.LeftButton, pos=QPoint(x3, 10))
    assert ses.frame == 3
    qtbot.mousePress(tb, Qt.MouseButton.LeftButton, CTRL, QPoint(x3, 10))
    qtbot.mouseMove(tb, QPoint(x9, 10))
    qtbot.mouseRelease(tb, Qt.MouseButton.LeftButton, CTRL, QPoint(x9, 10))
    assert p.active_range == (3, 9)
    ev = QWheelEvent(QPointF(x3, 10), QPointF(tb.mapToGlobal(QPoint(x3, 10))), QPoint(0, 0), QPoint(0, -120),
                     Qt.MouseButton.NoButton, Qt.KeyboardModifier.NoModifier, Qt.ScrollPhase.NoScrollPhase, False)
    QApplication.sendEvent(tb, ev)
    assert ses.frame == 4
    # lock to point keeps the selected point centred while stepping
    ses.select(points=[pid])
    win.action("view.lock_to_point").trigger()
    win.navigate.set_frame(6)
    v1 = win.grid.views[1]
    c = v1.vb.viewRect().center()
    assert (c.x(), c.y()) == pytest.approx(tuple(p.point(pid).uv[6, 1]), abs=1.0)


def test_help_and_view_windows(qtbot, window):
    win = window
    win.action("help.about").trigger()
    win.action("help.third_party").trigger()
    win.action("help.licensing").trigger()
    assert any("carapost" in t for t in win.prompts.infos) and any("pyqtgraph" in t for t in win.prompts.infos)
    assert not win.action("help.updates").isEnabled()
    win.action("view.new_workspace").trigger()
    ws = win.views.workspaces[-1]
    assert ws.isVisible()
    assert not win.action("view.show_brim_svg").isEnabled()     # no brim SVG imported
    ws.close()



def test_process_blobs_brims_and_exports(qtbot, window, take, tmp_path):
    from carapost.core.brim import default_brim
    from carapost.io.brim_svg import brim_to_svg

    p, _ = take
    win = window
    before = p.detections[0].frame(0).copy()
    win.action("process.detect_blobs_frame").trigger()     # on the images the views show
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    assert win.session.doc.stack.names()[-1] == "Detect Blobs [Current Frame]"
    after = p.detections[0].frame(0)
    # Measured on the image: as many dots, at sub-pixel centres of their own (not the take's stored ones).
    assert len(after) >= 10
    assert len(after) != len(before) or not np.array_equal(after[["x", "y"]], before[["x", "y"]])
    win.action("process.brim_v20").trigger()
    assert p.brim is not None and p.brim.name == "v2.0"
    svg = tmp_path / "brim.svg"
    svg.write_text(brim_to_svg(default_brim("v1.1")))
    win.prompts.queue("open_file", str(svg))
    win.action("file.import_brim_svg").trigger()
    assert p.brim.svg and win.action("view.show_brim_svg").isEnabled()
    win.prompts.queue("save_file", str(tmp_path / "out.xcp"))
    win.action("file.export_xcp").trigger()
    assert (tmp_path / "out.xcp").exists()
    win.prompts.queue("save_file", str(tmp_path / "out"))
    win.action("file.export_c3d").trigger()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)
    assert (tmp_path / "out.c3d").exists()
