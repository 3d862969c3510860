"""Process > Stabilize Data [Manual] / [Assisted], Align Data and View > Toggle Show Stabilized (Ctrl+Shift+S)
through the window's menus and shortcut, on a synthetic take with rig slip."""
from __future__ import annotations

import numpy as np
import pytest
from PySide6.QtCore import Qt

from carapost.core.stabilize_ops import stabilized_positions
from carapost.core.stabilize_synthetic import make_slip_take
from guihelpers import key, make_window

CTRL = Qt.KeyboardModifier.ControlModifier
CTRL_SHIFT = Qt.KeyboardModifier.ControlModifier | Qt.KeyboardModifier.ShiftModifier
pytestmark = pytest.mark.gui


@pytest.fixture
def slip():
    return make_slip_take(markers=32, frames=90, seed=1, brim=False)


def _menu_item(win, menu: str, title: str):
    """The QAction titled ``title`` in menu-bar menu ``menu`` (what a user clicks)."""
    for top in win.menuBar().actions():
        if top.text().replace("&", "") == menu:
            for a in top.menu().actions():
                if a.text().replace("&", "") == title:
                    return a
    raise AssertionError(f"no {menu} > {title}")


def _click(qtbot, win, menu, title):
    item = _menu_item(win, menu, title)
    assert item.isEnabled(), item.toolTip()
    item.trigger()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=30000)


def _log(win) -> list[str]:
    return [m for _lvl, m in win.log_pane.lines]


def _rigid(slip):
    return [slip.face_ids[i] for i in np.flatnonzero(slip.rigid & slip.gap_free)]


def test_stabilize_manual_and_assisted_from_the_process_menu_undo_exactly(qtbot, slip):
    p = slip.project
    win = make_window(qtbot, p)
    doc = win.session.doc
    rigid = _rigid(slip)
    moving = [slip.face_ids[i] for i in np.flatnonzero(~slip.rigid & slip.gap_free)]
    d0 = p.digest()
    doc.set_frame(10)                                    # the base frame is the current frame
    doc.select_points(rigid[:2] + moving[:2])            # a poor choice
    _click(qtbot, win, "Process", "Stabilize Data [Manual]")
    assert not win.prompts.errors, win.prompts.errors
    assert doc.stack.names()[-1] == "Stabilize Data [Manual]"
    assert p.stabilization.method == "manual" and p.stabilization.base_frame == 10
    manual = p.stabilization.errors["weighted"]
    assert any(m.startswith("Stabilize Data [Manual]: frames 0-89 onto frame 10") and "stabilisation error" in m
               for m in _log(win))
    d1 = p.digest()

    _click(qtbot, win, "Process", "Stabilize Data [Assisted]")
    assert not win.prompts.errors, win.prompts.errors
    assert doc.stack.names()[-2:] == ["Stabilize Data [Manual]", "Stabilize Data [Assisted]"]
    assert p.stabilization.errors["weighted"] < manual
    assert any(m.startswith("Stabilize Data [Assisted]") for m in _log(win))

    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.digest() == d1
    key(qtbot, win, Qt.Key.Key_Z, CTRL)
    assert p.digest() == d0 and p.stabilization is None


def test_too_few_selected_points_is_an_error_not_an_edit(qtbot, slip):
    win = make_window(qtbot, slip.project)
    win.session.doc.select_points(_rigid(slip)[:2])
    _click(qtbot, win, "Process", "Stabilize Data [Manual]")
    assert win.prompts.errors and "at least three" in win.prompts.errors[-1]
    assert len(win.session.doc.stack) == 0 and slip.project.stabilization is None


def test_align_data_and_toggle_show_stabilized(qtbot, slip):
    p = slip.project
    win = make_window(qtbot, p)
    doc = win.session.doc
    a, b, c = _rigid(slip)[:3]
    doc.set_frame(5)
    doc.select_points([a, b, c])
    _click(qtbot, win, "Process", "Align Data")
    assert not win.prompts.errors, win.prompts.errors
    o, x, xy = stabilized_positions(p, 5, [a, b, c])
    assert np.allclose(o, 0, atol=1e-9) and np.allclose(x[1:], 0, atol=1e-9) and abs(xy[2]) < 1e-9
    assert any(m.startswith("Align Data: origin at") for m in _log(win))

    # Ctrl+Shift+S is a view setting: it flips the document's flag and the check mark, and is no edit
    item = _menu_item(win, "View", "Toggle Show Stabilized")
    n, d = len(doc.stack), p.digest()
    assert not doc.show_stabilized and not item.isChecked()
    key(qtbot, win, Qt.Key.Key_S, CTRL_SHIFT)
    assert doc.show_stabilized and item.isChecked()
    assert any(m == "Show Stabilized: on" for m in _log(win))
    key(qtbot, win, Qt.Key.Key_S, CTRL_SHIFT)
    assert not doc.show_stabilized and not item.isChecked()
    assert len(doc.stack) == n and p.digest() == d


def test_show_stabilized_belongs_to_the_document(qtbot, slip):
    from carapost.core.document import Document

    win = make_window(qtbot, slip.project)
    item = _menu_item(win, "View", "Toggle Show Stabilized")
    item.trigger()
    assert win.session.doc.show_stabilized and item.isChecked()
    assert any("not stabilised yet" in m for m in _log(win))
    win.files.show_document(Document(make_slip_take(markers=20, frames=10, seed=2, brim=False).project))
    assert not win.session.doc.show_stabilized and not item.isChecked()
