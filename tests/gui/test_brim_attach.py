"""Attaching detections to brim markers by hand: click detections in the camera views, click the marker in the
Brim window (View > Show Calibration Brim SVG), then Process > Solve Calibration Brim [Manual] from the menu."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt

from carapost.core.points import BRIM, SRC_DETECTION
from guihelpers import click_raw, det_xy, key, make_window, point_at

CTRL = Qt.KeyboardModifier.ControlModifier
pytestmark = pytest.mark.gui


def _brim_svg(markers: np.ndarray) -> str:
    """An SVG brim whose circles sit in a translated group (the Brim window must follow the transform)."""
    lo, hi = markers.min(axis=0) - 8, markers.max(axis=0) + 8
    w, h = hi - lo
    circles = "\n".join(f'    <circle cx="{x - 10:.4f}" cy="{y - 5:.4f}" r="2.5" fill="black"/>' for x, y in markers)
    return (f'<svg xmlns="http://www.w3.org/2000/svg" viewBox="{lo[0]:.4f} {lo[1]:.4f} {w:.4f} {h:.4f}">\n'
            f'  <rect x="{lo[0]:.4f}" y="{lo[1]:.4f}" width="{w:.4f}" height="{h:.4f}" fill="white"/>\n'
            f'  <g transform="translate(10 5)">\n{circles}\n  </g>\n</svg>\n')


def _open_brim_window(qtbot, win):
    act = win.action("view.show_brim_svg")
    assert act.isEnabled()
    act.trigger()
    bw = win.views.brim_window
    qtbot.waitExposed(bw)
    return bw


def _select(qtbot, win, picks):
    """Click detection ``i`` of each ``(sensor, i)``: the first plainly, the others with Ctrl (adds)."""
    p, f = win.session.project, win.session.frame
    for k, (s, i) in enumerate(picks):
        click_raw(qtbot, win.grid.views[s], *det_xy(p, s, f, i), mods=CTRL if k else Qt.KeyboardModifier.NoModifier)
    assert win.session.selection.detections == [(s, f, i) for s, i in picks]


def _click_marker(qtbot, bw, index):
    qtbot.mouseClick(bw.canvas, Qt.MouseButton.LeftButton, pos=bw.canvas.marker_point(index).toPoint())


def _menu_action(win, menu, title):
    """The QAction of ``menu > title`` in the window's menu bar (what a user clicks)."""
    top = next(a for a in win.menuBar().actions() if a.text().replace("&", "") == menu)
    return next(a for a in top.menu().actions() if a.text().replace("&", "") == title)


def _separated(p, frame, sensor, index, gap=10.0) -> bool:
    rec = p.detections[sensor].frame(frame)
    d = np.hypot(rec["x"] - rec["x"][index], rec["y"] - rec["y"][index])
    d[index] = np.inf
    return bool(d.min() > gap)


def test_attach_brim_markers_by_clicking_then_solve_from_the_menu(qtbot, tmp_path):
    from carapost.core.calib.synthetic import make_scene

    sc = make_scene(markers=35, frames=3, seed=0)
    p = sc.project
    svg = tmp_path / "brim.svg"
    svg.write_text(_brim_svg(sc.brim.markers[:, :2]))
    win = make_window(qtbot, p)
    stack = win.session.doc.stack
    win.prompts.queue("open_file", str(svg))
    _menu_action(win, "File", "Import Calibration Brim [svg]").trigger()
    assert p.brim.name == "brim.svg"
    np.testing.assert_allclose(p.brim.markers, sc.brim.markers, atol=1e-3)
    bw = _open_brim_window(qtbot, win)
    assert bw.windowTitle() == "Calibration Brim brim.svg"
    assert bw.canvas.attached == {} and "0 of 20 markers attached" in bw.status.text()

    # Markers seen by every camera, whose detections are clear of their neighbours, spread along the brim.
    ok = [b for b in range(len(p.brim)) if all(sc.brim_det[0, s, b] >= 0 and _separated(p, 0, s, sc.brim_det[0, s, b])
                                               for s in range(4))]
    chosen = [ok[k] for k in np.linspace(0, len(ok) - 1, 5).round().astype(int)]
    assert len(set(chosen)) == 5
    xcp = [c.position.copy() for c in p.rig.cameras]
    for n, b in enumerate(chosen):
        picks = [(s, int(sc.brim_det[0, s, b])) for s in range(4)]
        _select(qtbot, win, picks)
        assert "4 detection(s) selected in channel(s) 0, 1, 2, 3" in bw.status.text()
        d0 = p.digest()
        _click_marker(qtbot, bw, b)
        assert not win.prompts.errors, win.prompts.errors
        assert stack.names()[-1] == f"Attach To Brim Marker {b}" and len(stack) == n + 2   # + the brim import
        bp = [q for q in p.points.values() if q.kind == BRIM and q.brim_index == b]
        assert len(bp) == 1
        assert [(s, int(bp[0].det[0, s])) for s in range(4) if bp[0].src[0, s] == SRC_DETECTION] == picks
        assert bw.canvas.attached[b] == [0, 1, 2, 3] and bw.canvas.selected == {b}
        if n == 0:          # one undoable command: Ctrl+Z (pressed in the Brim window) restores the project exactly
            d1 = p.digest()
            qtbot.keyClick(bw.canvas, Qt.Key.Key_Z, CTRL)
            assert p.digest() == d0 and b not in bw.canvas.attached
            qtbot.keyClick(bw.canvas, Qt.Key.Key_Y, CTRL)
            assert p.digest() == d1 and bw.canvas.attached[b] == [0, 1, 2, 3]

    # Drawn filled (green) where attached; the SVG's own black dot shows through where not.
    img = bw.canvas.grab().toImage()
    dpr = img.devicePixelRatio()
    colour = lambda i: img.pixelColor((bw.canvas.marker_point(i) * dpr).toPoint())
    free = next(b for b in range(len(p.brim)) if b not in chosen)
    assert colour(chosen[0]).green() > 150 and colour(chosen[0]).red() < 150
    assert max(colour(free).red(), colour(free).green(), colour(free).blue()) < 80
    assert "5 of 20 markers attached" in bw.status.text()

    # Brim points are points of the camera views: clicking a brim detection selects its point, ringed in the window.
    b = chosen[2]
    click_raw(qtbot, win.grid.views[1], *det_xy(p, 1, 0, int(sc.brim_det[0, 1, b])))
    assert bw.canvas.selected == {b}

    _menu_action(win, "Process", "Solve Calibration Brim [Manual]").trigger()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=30000)
    assert not win.prompts.errors, win.prompts.errors
    assert stack.names()[-1] == "Solve Calibration Brim [Manual]"
    truth = sc.cameras[0]
    err = [np.linalg.norm(c.position - t.position) for c, t in zip(p.rig.cameras, truth)]
    before = [np.linalg.norm(c - t.position) for c, t in zip(xcp, truth)]
    assert max(err) < 0.5 and max(err) < 0.2 * min(before), (err, before)
    ang = [np.degrees(np.arccos(np.clip((np.trace(c.rotation @ t.rotation.T) - 1) / 2, -1, 1)))
           for c, t in zip(p.rig.cameras, truth)]
    assert max(ang) < 0.1, ang
    assert len(bw.canvas.attached) >= 18                  # the solve matched the other markers


def test_default_brim_drawing_replace_take_over_and_refusals(qtbot, window, take):
    from carapost.core.brim import default_brim
    from carapost.core.edits import SetProperties

    p, _ = take
    win = window
    stack = win.session.doc.stack
    assert not win.action("view.show_brim_svg").isEnabled()           # no brim yet
    win.action("process.brim_v20").trigger()
    bw = _open_brim_window(qtbot, win)
    assert bw.windowTitle() == "Calibration Brim v2.0"
    np.testing.assert_allclose(bw.canvas.markers, default_brim("v2.0").markers[:, :2])
    pts = [bw.canvas.marker_point(i) for i in range(len(p.brim))]
    assert all(bw.canvas.rect().contains(q.toPoint()) for q in pts)
    assert min(np.hypot(a.x() - b.x(), a.y() - b.y()) for k, a in enumerate(pts) for b in pts[k + 1:]) > 20
    base, n0 = p.digest(), len(stack)

    # Nothing selected: refused with a message, nothing changes.
    win.session.select()
    _click_marker(qtbot, bw, 3)
    assert "Attach To Brim Marker 3 needs detections selected" in win.prompts.errors[-1]
    assert p.digest() == base and len(stack) == n0

    # Two detections in one view: refused.
    _select(qtbot, win, [(0, 0), (0, 1)])
    _click_marker(qtbot, bw, 3)
    assert "two selected detections are in channel 0" in win.prompts.errors[-1]
    assert p.digest() == base and len(stack) == n0

    _select(qtbot, win, [(0, 0), (1, 0)])
    _click_marker(qtbot, bw, 3)
    bp = point_at(p, 0, 0, 0)
    assert bp is not None and bp.kind == BRIM and bp.brim_index == 3 and point_at(p, 0, 1, 0) is bp
    assert bw.canvas.attached == {3: [0, 1]}

    # Attaching again in channel 0 replaces the marker's earlier detection there; channel 1 is kept.
    _select(qtbot, win, [(0, 5)])
    _click_marker(qtbot, bw, 3)
    assert point_at(p, 0, 0, 5) is bp and point_at(p, 0, 0, 0) is None and point_at(p, 0, 1, 0) is bp
    assert stack.names()[-2:] == ["Attach To Brim Marker 3"] * 2

    # A detection belongs to one point: attaching one held by another point takes it from that point.
    win.session.run(SetProperties({"selection.points": False}))       # attached detections become clickable
    _select(qtbot, win, [(0, 5), (2, 5)])
    _click_marker(qtbot, bw, 7)
    other = point_at(p, 0, 0, 5)
    assert other is not bp and other.brim_index == 7 and point_at(p, 0, 2, 5) is other
    assert bp.src[0, 0] != SRC_DETECTION and point_at(p, 0, 1, 0) is bp
    assert bw.canvas.attached == {3: [1], 7: [0, 2]}

    # Another frame has its own attachments.
    win.navigate.set_frame(4)
    assert bw.canvas.attached == {} and "Frame 4: 0 of 19 markers attached" in bw.status.text()
    win.navigate.set_frame(0)
    while stack.index > n0:
        key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.digest() == base
