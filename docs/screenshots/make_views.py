"""Render docs/screenshots/view3d.png, graph_view.png and continuity.png on a tracked synthetic take.

Run from the repository root:  QT_QPA_PLATFORM=offscreen .venv/bin/python docs/screenshots/make_views.py

The take is the one of ``make_main_window.py`` (the GUI's demo take with 24
tracked points, labels and a stick mesh); a few points get patch-matched and
interpolated stretches so the 3D view's reconstruction colours and the
continuity colours all show.  Each view is shown in a one-view workspace of
the main window, chosen through the slot's View menu as a user would, and
grabbed on its own.
"""
from __future__ import annotations

import importlib.util
import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
HERE = Path(__file__).resolve().parent


def _main_window_script():
    spec = importlib.util.spec_from_file_location("make_main_window", HERE / "make_main_window.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _patched_and_interpolated(project) -> None:
    from carapost.core.points import SRC_NONE, SRC_PATCH, ST_INTERPOLATED

    for pid in (6, 11, 16):                      # patch-matched in two sensors on frames 8-20
        project.points[pid].src[8:21, 1:3] = SRC_PATCH
    for pid in (10, 13):                         # a gap filled by Interpolate Gaps on frames 12-18
        pt = project.points[pid]
        pt.status[12:19] = ST_INTERPOLATED
        pt.src[12:19] = SRC_NONE
        pt.det[12:19] = -1


def main() -> int:
    from carapost.core import editing
    from carapost.core.edits import SetLabels
    from carapost.gui.app import settle

    with tempfile.TemporaryDirectory() as tmp:
        app, win = _main_window_script().open_take(Path(tmp), (1600, 1000), _patched_and_interpolated)
        ses = win.session
        p = ses.project
        names = ["Nose_Tip", "Nose_Bridge", "Chin", "Brow_L", "Brow_R", "Cheek_L", "Cheek_R", "Lip_Upper",
                 "Lip_Lower", "Mouth_L", "Mouth_R", "Jaw_L"]
        ses.run(SetLabels(names))
        for pid, name in zip(range(12), names):
            ses.run(editing.rename_point(p, pid, name))
        ses.run(editing.create_stick_mesh(p, 0))
        win.navigate.set_frame(14)
        grid = win.grid
        grid.set_layout("1")
        ok = True

        win.views.toggle_docks()                 # Ctrl+F: the views only
        win.resize(1100, 800)
        grid.set_slot_kind(0, "3d")
        v = grid.slot_widget(0)
        settle(app)
        v.fit_to_points()                        # nothing selected: every point
        v.camera.orbit(-80, 50)                  # a three-quarter view, as after an Alt+drag
        v.camera.zoom(2.2)                       # and a Shift+right-drag: the cameras come into view
        ses.select(points=[2])                   # its rays go to the four cameras
        win.action("view3d.labels_all").trigger()
        settle(app, 5)
        ok &= v.grab().save(str(HERE / "view3d.png"))

        grid.set_slot_kind(0, "graph")
        g = grid.slot_widget(0)
        ses.select(points=[10, 2])
        settle(app, 5)
        g.fit_to_data()
        settle(app, 5)
        ok &= g.grab().save(str(HERE / "graph_view.png"))

        grid.set_slot_kind(0, "continuity")
        c = grid.slot_widget(0)
        c.set_expanded(6, True)
        ses.select(points=[6])
        settle(app, 5)
        ok &= c.grab().save(str(HERE / "continuity.png"))
        ses.doc.stack.mark_clean()
        win.close()
    print("written" if ok else "failed")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.path.insert(0, str(HERE.parents[1]))
    sys.exit(main())
