"""Process > Load ROM, Initialize from ROM [Brim Only], the ROM Tools and the 2D ROM display, as a user drives them."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt

from carapost.core import rom_ops
from carapost.core.points import BRIM
from carapost.io.cara import save_project
from guihelpers import click_raw, drag_widget, key, make_window
from rom_support import bare, rom_project, score, take

CTRL = Qt.KeyboardModifier.ControlModifier
FRAME = 3


@pytest.fixture
def rom_file(tmp_path):
    path = tmp_path / "ROM.cara"
    save_project(rom_project(take(), 0), path)
    return path


def _wait(qtbot, win):
    qtbot.waitUntil(lambda: not win.runner.running, timeout=30000)


def test_load_rom_initialize_undo_and_correspondence(qtbot, rom_file):
    scene = take(rig_move=(5.0, 3.0), motion_seed=77)
    p = bare(scene)
    win = make_window(qtbot, p)
    win.navigate.set_frame(FRAME)
    stack = win.session.doc.stack

    # Without a ROM: an error in the log and a message box, nothing changes (the guide's "does nothing").
    win.action("process.init_from_rom").trigger()
    _wait(qtbot, win)
    assert any("no ROM is loaded" in e for e in win.prompts.errors) and len(stack) == 0
    win.prompts.errors.clear()

    # Load ROM through its menu item and the (scripted) open dialog.
    assert win.action("process.load_rom").isEnabled()
    win.prompts.queue("open_file", str(rom_file))
    win.action("process.load_rom").trigger()
    _wait(qtbot, win)
    assert stack.names() == ["Load ROM"] and p.rom_path == str(rom_file)
    # The 3D view draws the ROM frame's points too: its face points and brim markers.
    from carapost.gui.view3d import rom_positions
    rom = rom_ops.loaded_rom(p).rom
    assert len(rom_positions(win.session)) == sum(1 for q in rom.face_points()) + len(rom.brim.markers)

    # The 2D context menu's ROM switch draws the ROM points, pale blue, in every view.
    titles = [a.text() for a in win.grid.build_context_menu(win.grid.views[0]).actions()]
    assert "ROM" in titles
    win.action("view2d.rom").trigger()
    assert win.action("view2d.rom").isChecked() and win.rom.show_rom
    layer = win.rom._layers[id(win.grid.views[0])][1]
    assert layer.count() > 0

    # Initialize from ROM from the Process menu: labelled points appear on the current frame.
    d0 = p.digest()
    win.action("process.init_from_rom").trigger()
    _wait(qtbot, win)
    assert not win.prompts.errors, win.prompts.errors
    assert stack.names()[-1] == "Initialize from ROM"
    got = score(p, scene, FRAME)
    assert got["fraction"] >= 0.98 and got["wrong"] == 0
    assert all(q.label.startswith("M") for q in p.face_points())
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.digest() == d0

    # Ctrl+L: click a pale blue ROM point, Ctrl+click its detection, Ctrl+L.
    view = win.grid.views[0]
    rom = rom_ops.loaded_rom(p).rom
    brim_ids = {q.brim_index: q.id for q in rom.points.values() if q.kind == BRIM}
    proj = rom_ops.rom_projections(p)
    row = {int(i): k for k, i in enumerate(proj["ids"])}
    w, h = p.sensors[0].width, p.sensors[0].height
    b = next(b for b in sorted(brim_ids) if scene.brim_det[FRAME, 0, b] >= 0
             and 40 < proj["uv"][row[brim_ids[b]], 0, 0] < w - 40 and 40 < proj["uv"][row[brim_ids[b]], 0, 1] < h - 40)
    click_raw(qtbot, view, *proj["uv"][row[brim_ids[b]], 0])
    assert win.rom.selected_rom_point == brim_ids[b]
    det = int(scene.brim_det[FRAME, 0, b])
    rec = p.detections[0].frame(FRAME)[det]
    click_raw(qtbot, view, float(rec["x"]), float(rec["y"]), CTRL)
    assert win.session.selection.detections == [(0, FRAME, det)]
    key(qtbot, win, Qt.Key.Key_L, CTRL)
    assert stack.names()[-1] == "Add 2D To ROM Correspondence"
    corr = rom_ops.loaded_rom(p).correspondences
    assert [(k.rom_point, k.sensor, k.frame, k.detection) for k in corr] == [(brim_ids[b], 0, FRAME, det)]
    win.action("process.rom_clear_2d").trigger()
    assert rom_ops.loaded_rom(p).correspondences == ()


def test_brim_only_and_rom_timebar(qtbot, rom_file):
    scene = take(rig_move=(5.0, 3.0), motion_seed=77)
    p = bare(scene)
    win = make_window(qtbot, p)
    win.navigate.set_frame(FRAME)
    win.prompts.queue("open_file", str(rom_file))
    win.action("process.load_rom").trigger()
    _wait(qtbot, win)
    win.action("process.init_from_rom_brim").trigger()
    _wait(qtbot, win)
    assert not win.prompts.errors, win.prompts.errors
    assert win.session.doc.stack.names()[-1] == "Initialize from ROM [Brim Only]"
    assert not list(p.face_points()) and sum(q.kind == BRIM for q in p.points.values()) >= 15
    for cam, true in zip(p.rig.cameras_at(FRAME), scene.cameras[FRAME]):
        assert np.linalg.norm(cam.position - true.position) < 1.0

    # Display ROM Timebar: the ROM take's frames in a window; where a click or drag ends is the ROM Frame Index,
    # one undo step.
    win.action("process.rom_timebar").trigger()
    bar = win.rom._timebar
    last = rom_ops.loaded_rom(p).rom.frame_count - 1
    assert bar.isVisible() and bar.strip.last == last == bar.spin.maximum()
    n = len(win.session.doc.stack.names())
    strip = bar.strip
    drag_widget(strip, [(strip.x_of(0), 10), (strip.x_of(1), 10), (strip.x_of(2), 10)])
    assert p.properties["initialize_from_rom.rom_frame_index"] == 2 and strip.frame == 2 and bar.spin.value() == 2
    assert len(win.session.doc.stack.names()) == n + 1
    assert win.session.doc.stack.names()[-1] == "Set ROM Frame Index"
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.properties["initialize_from_rom.rom_frame_index"] == 0 and strip.frame == 0 and bar.spin.value() == 0
    bar.set_frame(last + 5)                     # past the end: the last frame
    assert p.properties["initialize_from_rom.rom_frame_index"] == last
