"""Helpers of the GUI tests: scripted dialogs, a window on a synthetic take, clicks at image pixels."""
from __future__ import annotations

import numpy as np
from PySide6.QtCore import Qt

from carapost.core.document import Document
from carapost.gui.demo_take import ArraySource


class ScriptedPrompts:
    """Stands in for the window's dialogs: answers queued per question, every message recorded.

    An unexpected question fails the test instead of blocking on a modal dialog.
    """

    def __init__(self):
        self.answers: dict[str, list] = {}
        self.errors: list[str] = []
        self.infos: list[str] = []
        self.asked: list[tuple] = []

    def queue(self, method: str, *answers) -> "ScriptedPrompts":
        self.answers.setdefault(method, []).extend(answers)
        return self

    def _answer(self, method: str, *args):
        self.asked.append((method, args))
        queued = self.answers.get(method)
        if not queued:
            raise AssertionError(f"unexpected dialog {method}{args}")
        return queued.pop(0)

    def open_file(self, *a):
        return self._answer("open_file", *a)

    def open_files(self, *a):
        return self._answer("open_files", *a)

    def save_file(self, *a):
        return self._answer("save_file", *a)

    def get_text(self, *a, **k):
        return self._answer("get_text", *a)

    def get_int(self, *a):
        return self._answer("get_int", *a)

    def get_item(self, *a):
        return self._answer("get_item", *a)

    def get_color(self, *a):
        return self._answer("get_color", *a)

    def confirm(self, *a):
        return self._answer("confirm", *a)

    def relocate(self, *a):
        return self._answer("relocate", *a)

    def save_discard_cancel(self, *a):
        queued = self.answers.get("save_discard_cancel")
        return queued.pop(0) if queued else "discard"     # closing at teardown discards

    def error(self, title, text):
        self.errors.append(text)

    def info(self, title, text):
        self.infos.append(text)


def make_window(qtbot, project=None, **kw):
    from carapost.gui.mainwindow import MainWindow

    kw.setdefault("synchronous_images", True)
    kw.setdefault("autosave_s", 0)
    win = MainWindow(**kw)
    win.prompts = ScriptedPrompts()
    qtbot.addWidget(win)
    win.resize(1400, 900)
    win.show()
    qtbot.waitExposed(win)
    win.activateWindow()
    win.raise_()
    if project is not None:
        win.files.show_document(Document(project))
        win.session.loader.set_sources([ArraySource(project, s) for s in range(project.sensor_count)],
                                       [s.image_offset for s in project.sensors])
        win.grid.refresh()
    qtbot.waitUntil(win.isActiveWindow, timeout=2000)
    return win


def key(qtbot, win, k, mods=Qt.KeyboardModifier.NoModifier):
    """Press a key on the window as a user would (shortcuts included)."""
    qtbot.keyClick(win.grid.views[0] if win.grid.views[0].isVisible() else win, k, mods)


def click_raw(qtbot, view, x, y, mods=Qt.KeyboardModifier.NoModifier, button=Qt.MouseButton.LeftButton):
    """Click a view's viewport where raw image pixel (x, y) is shown."""
    pos = view.raw_to_viewport(x, y)
    assert view.viewport().rect().contains(pos), f"({x}, {y}) is not on screen in {view.sensor}"
    qtbot.mouseClick(view.viewport(), button, mods, pos)
    return pos


def det_xy(project, sensor, frame, index) -> tuple[float, float]:
    rec = project.detections[sensor].frame(frame)[index]
    return float(rec["x"]), float(rec["y"])


def point_at(project, frame, sensor, det_index):
    """The point attached to detection ``det_index`` of ``sensor`` on ``frame`` (or None)."""
    from carapost.core.points import SRC_DETECTION

    for p in project.points.values():
        if p.src[frame, sensor] == SRC_DETECTION and p.det[frame, sensor] == det_index:
            return p
    return None


def assert_close(a, b, tol=1e-2):
    np.testing.assert_allclose(np.asarray(a, float), np.asarray(b, float), atol=tol)


def _press(widget, pos, button, mods) -> None:
    """Press ``button`` at ``pos`` (widget coordinates) straight to ``widget``, as the drags' moves are sent.

    Through the window system's queue (``QTest.mousePress``) the press could arrive after the moves on a
    loaded machine: the scene then saw moves with no press, then a click, and cleared the selection (seen
    once in a full test run).
    """
    from PySide6.QtCore import QEvent, QPointF
    from PySide6.QtGui import QMouseEvent
    from PySide6.QtWidgets import QApplication

    local = QPointF(pos)
    QApplication.sendEvent(widget, QMouseEvent(QEvent.Type.MouseButtonPress, local,
                                               QPointF(widget.mapToGlobal(local.toPoint())), button, button, mods))
    QApplication.processEvents()


def drag_raw(qtbot, view, a, b, mods=Qt.KeyboardModifier.NoModifier, button=Qt.MouseButton.LeftButton,
             via=(), steps: int = 4):
    """Drag in a view from raw pixel ``a`` to ``b`` (through the raw points ``via``), holding ``mods``."""
    from PySide6.QtCore import QEvent, QPointF
    from PySide6.QtGui import QMouseEvent
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication

    vp = view.viewport()
    corners = [a, *via, b]
    pts = []
    for (x0, y0), (x1, y1) in zip(corners, corners[1:]):
        pts += [(x0 + (x1 - x0) * t, y0 + (y1 - y0) * t) for t in np.linspace(0, 1, steps + 1)[1:]]
    _press(vp, view.raw_to_viewport(*a), button, mods)
    for q in pts:
        # QTest.mouseMove sends no modifiers; a user holding Shift does.
        local = QPointF(view.raw_to_viewport(*q))
        ev = QMouseEvent(QEvent.Type.MouseMove, local, QPointF(vp.mapToGlobal(local.toPoint())), Qt.MouseButton.NoButton,
                         button, mods)
        QApplication.sendEvent(vp, ev)
    QTest.mouseRelease(vp, button, mods, view.raw_to_viewport(*b))
    QApplication.processEvents()


def drag_widget(widget, points, mods=Qt.KeyboardModifier.NoModifier, button=Qt.MouseButton.LeftButton):
    """Press ``button`` at the first widget position of ``points``, move through the others, release at the last.

    Moves carry ``mods`` and the held button, as a user's do (``QTest.mouseMove`` sends neither).
    """
    from PySide6.QtCore import QEvent, QPoint, QPointF
    from PySide6.QtGui import QMouseEvent
    from PySide6.QtTest import QTest
    from PySide6.QtWidgets import QApplication

    pts = [QPoint(int(round(x)), int(round(y))) for x, y in points]
    _press(widget, pts[0], button, mods)
    for q in pts[1:]:
        local = QPointF(q)
        ev = QMouseEvent(QEvent.Type.MouseMove, local, QPointF(widget.mapToGlobal(q)), Qt.MouseButton.NoButton,
                         button, mods)
        QApplication.sendEvent(widget, ev)
    QTest.mouseRelease(widget, button, mods, pts[-1])
