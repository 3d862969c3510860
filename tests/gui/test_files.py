"""Files: save, open, recent files, unsaved-changes prompt, imports, relocation, persistence, recovery."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from PySide6.QtCore import Qt

from carapost.core.edits import SetLabels
from carapost.gui.demo_take import make_demo_take, rig_cameras
from guihelpers import click_raw, det_xy, key, make_window, point_at

CTRL = Qt.KeyboardModifier.ControlModifier
pytestmark = pytest.mark.gui
REPO = Path(__file__).resolve().parents[2]


def _merge(qtbot, win, p, marker):
    v0, v1 = win.grid.views[0], win.grid.views[1]
    click_raw(qtbot, v0, *det_xy(p, 0, 0, marker))
    click_raw(qtbot, v1, *det_xy(p, 1, 0, marker), mods=CTRL)
    key(qtbot, win, Qt.Key.Key_M)
    return point_at(p, 0, 0, marker)


def _wait_idle(qtbot, win):
    qtbot.waitUntil(lambda: not win.runner.running, timeout=20000)


def test_save_open_recent_and_unsaved_prompt(qtbot, window, take, tmp_path):
    p, _ = take
    win = window
    pt = _merge(qtbot, win, p, 3)
    assert win.isWindowModified()
    out = tmp_path / "take.cara"
    win.prompts.queue("save_file", str(out))
    key(qtbot, win, Qt.Key.Key_S, CTRL)
    _wait_idle(qtbot, win)
    assert out.exists() and not win.isWindowModified() and "take.cara" in win.windowTitle()
    assert win.files.recent_files()[0] == str(out)

    win.session.run(SetLabels(["Brow"]))                 # an unsaved change
    win.prompts.queue("save_discard_cancel", "cancel")
    win.action("file.clear").trigger()
    assert win.session.doc is not None                  # cancelled: nothing lost
    win.prompts.queue("save_discard_cancel", "discard")
    win.action("file.clear").trigger()
    assert win.session.doc is None and not win.action("file.save").isEnabled()

    win.prompts.queue("open_file", str(out))
    key(qtbot, win, Qt.Key.Key_O, CTRL)
    q = win.session.project
    assert q is not p and q.point(pt.id).det[0, 1] == 3
    np.testing.assert_allclose(q.point(pt.id).pos[0], p.point(pt.id).pos[0])
    # File > Recent Files holds it; opening it from there works too
    win.actionset.fill_recent()
    entries = win.actionset.recent_menu.actions()
    assert str(out) in entries[0].text()
    entries[0].trigger()
    assert win.session.project.path == str(out)


def test_open_errors_go_to_the_log_and_a_message(qtbot, window, tmp_path):
    bad = tmp_path / "broken.cara"
    bad.write_bytes(b"not a project")
    window.prompts.queue("open_file", str(bad))
    key(qtbot, window, Qt.Key.Key_O, CTRL)
    assert window.prompts.errors and "broken.cara" in window.prompts.errors[-1]
    assert window.log_pane.lines[-1][0] >= 40


def test_imports_xcp_and_labels(qtbot, tmp_path):
    from carapost.io.xcp import write_xcp, xcp_from_cameras

    p, _ = make_demo_take(frames=4, markers=4)
    p.rig = None
    win = make_window(qtbot, p)
    xcp = tmp_path / "cal.xcp"
    write_xcp(xcp, xcp_from_cameras([[(0, c)] for c in rig_cameras(4)]))
    win.prompts.queue("open_file", str(xcp))
    win.action("file.import_xcp").trigger()
    assert p.rig is not None and win.session.doc.stack.names()[-1] == "Import XCP"
    labels = tmp_path / "labels.txt"
    labels.write_text("Nose Chin\nBrow\n")
    win.prompts.queue("open_file", str(labels))
    win.action("file.import_labels_text").trigger()
    assert p.labels == ["Nose", "Chin", "Brow"] and win.labelling.list.count() == 3


def test_import_pico_files_and_relocate(qtbot, tmp_path):
    from carapost.io.pico import write_pico

    rng = np.random.default_rng(0)
    for ch in range(2):
        write_pico(tmp_path / f"shot_{ch}.pico", [rng.integers(0, 255, (48, 64), dtype=np.uint8) for _ in range(3)],
                   channel=ch, gop=2)
    win = make_window(qtbot)
    win.prompts.queue("open_files", [str(tmp_path / "shot_1.pico"), str(tmp_path / "shot_0.pico")])
    win.action("file.import_pico").trigger()
    p = win.session.project
    assert p.sensor_count == 2 and p.frame_count == 3 and p.sensors[0].media.kind == "pico"
    assert win.grid.views[0].image.image() is not None and win.grid.views[0].image.image().shape == (48, 64)
    moved = tmp_path / "moved"
    moved.mkdir()
    (tmp_path / "shot_0.pico").rename(moved / "shot_0.pico")
    win.prompts.queue("relocate", {0: str(moved / "shot_0.pico")})
    win.action("edit.relocate_files").trigger()
    assert p.sensors[0].media.path == str(moved / "shot_0.pico")
    assert win.session.loader.has_media(0)


def test_layout_docks_and_recent_files_persist(qtbot, take, tmp_path):
    win = make_window(qtbot, take[0])
    win.docks["log"].hide()
    win.grid.set_layout("1")
    win.views.toggle_display("errors")
    from carapost.gui import settings as st

    st.add_recent(win.settings, str(tmp_path / "a.cara"))
    win.close()
    again = make_window(qtbot)
    assert not again.docks["log"].isVisible() and again.docks["history"].isVisible()
    assert again.grid.layout_name == "1" and not again.session.display.errors
    assert again.files.recent_files() == [str(tmp_path / "a.cara")]
    again.action("file.clear_recent").trigger()
    assert again.files.recent_files() == []


CRASHING_SESSION = textwrap.dedent("""
    import os, signal, sys
    sys.path.insert(0, {tests!r})
    from carapost.gui.app import ensure_app
    app = ensure_app(offscreen=True)
    from carapost.core import editing
    from carapost.core.document import Document
    from carapost.gui.demo_take import make_demo_take
    from carapost.gui.mainwindow import MainWindow
    p, _ = make_demo_take(frames=6, markers=6)
    win = MainWindow(autosave_s=0, synchronous_images=True)
    win.files.show_document(Document(p))
    win.session.run(editing.merge(p, 0, [], [(0, 0, 2), (1, 0, 2)], label="Saved_By_Autosave"))
    assert win.recovery.autosave()
    while win.runner.running:
        app.processEvents()
    print(win.recovery.path, flush=True)
    os.kill(os.getpid(), signal.SIGKILL)     # a crash: no clean exit
""")


def test_autosave_and_crash_recovery(qtbot, tmp_path):
    env = dict(os.environ, QT_QPA_PLATFORM="offscreen", CARAPOST_DATA_DIR=os.environ["CARAPOST_DATA_DIR"])
    r = subprocess.run([sys.executable, "-c", CRASHING_SESSION.format(tests=str(Path(__file__).parent))],
                       capture_output=True, text=True, env=env, cwd=REPO, timeout=120)
    assert r.returncode == -signal.SIGKILL, r.stderr
    recovery_file = Path(r.stdout.strip().splitlines()[-1])
    assert recovery_file.exists()
    win = make_window(qtbot)
    win.prompts.queue("confirm", True)
    assert win.recovery.offer()
    p = win.session.project
    assert p.point_by_label("Saved_By_Autosave") is not None
    assert win.session.is_modified() and win.isWindowModified()
    assert not win.recovery.orphans()                   # offered once
    win.close()                                         # discards (scripted), a clean exit
    assert not any(Path(os.environ["CARAPOST_DATA_DIR"], "recovery").glob("session-*"))


def test_declined_recovery_is_discarded(qtbot):
    from carapost.gui.recovery import Recovery

    win = make_window(qtbot)
    folder = win.recovery.folder
    folder.mkdir(parents=True)
    p, _ = make_demo_take(frames=3, markers=2)
    from carapost.io.cara import save_project

    dead = 2 ** 22 + 12345                              # no such process
    save_project(p, folder / f"session-{dead}.cara")
    (folder / f"session-{dead}.json").write_text(f'{{"pid": {dead}, "original": "", "saved_at": "x"}}')
    assert isinstance(win.recovery, Recovery) and len(win.recovery.orphans()) == 1
    win.prompts.queue("confirm", False)
    assert not win.recovery.offer()
    assert not list(folder.glob("session-*"))


def test_screenshot_command(qtbot, take, tmp_path):
    from carapost.gui.cli_entry import gui_main
    from carapost.io.cara import save_project
    from PySide6.QtGui import QImage

    p, _ = take
    save_project(p, tmp_path / "shot.cara")
    out = tmp_path / "shot.png"
    assert gui_main(SimpleNamespace(file=str(tmp_path / "shot.cara"), screenshot=str(out), frame=2)) == 0
    img = QImage(str(out))
    assert img.width() == 1600 and img.height() == 1000


def test_background_job_progress_cancel_and_result(qtbot, window):
    import time

    from carapost.core.edits import SetLabels
    from carapost.gui.background import run_in_background

    win = window
    before = win.session.project.digest()

    def slow(progress):
        progress.start(50, "working")
        for _ in range(50):
            time.sleep(0.02)
            progress.step()
        return SetLabels(["never"])

    assert run_in_background(win, slow, "Slow job")
    assert win.session.busy and win.time.progress.isVisible()
    assert not win.action("edit.merge").isEnabled() and win.action("view.next_frame").isEnabled()
    qtbot.waitUntil(lambda: win.time.progress.bar.value() > 2, timeout=5000)   # the GUI keeps updating
    win.time.progress.cancel.click()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=5000)
    assert win.session.project.digest() == before and not win.time.progress.isVisible()
    assert "cancelled" in win.log_pane.lines[-1][1]

    assert run_in_background(win, lambda progress: SetLabels(["Done"]), "Quick job")
    qtbot.waitUntil(lambda: not win.runner.running, timeout=5000)
    assert win.session.project.labels == ["Done"] and win.session.doc.stack.names()[-1] == "Edit Labels"
    win.action("edit.remove_unused_detections").trigger()
    qtbot.waitUntil(lambda: not win.runner.running, timeout=5000)
    assert win.session.doc.stack.names()[-1] == "Remove Unused Detections"
    assert win.session.project.detections[0].count(0) == 0
