"""Render docs/screenshots/main_window.png: the main window on a synthetic take with points.

Run from the repository root:  QT_QPA_PLATFORM=offscreen .venv/bin/python docs/screenshots/make_main_window.py

The take is the GUI's demo take (four rigged 1280x720 channels, markers on a
face-like surface, detections at their projections) written as image folders
and a .cara project, then opened through the window's normal File > Open path.
Points, labels, sticks, ranges and a selection are made with the same commands
the menus run, so the History and Log panes show a real session.
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
OUT = Path(__file__).resolve().parent / "main_window.png"


def build_project(folder: Path):
    """The demo take with image-folder media and 24 tracked points (some labelled)."""
    import cv2

    from carapost.core.points import SRC_DETECTION, ST_RECONSTRUCTED
    from carapost.core.project import MediaRef
    from carapost.gui.demo_take import ArraySource, make_demo_take

    frames, markers = 30, 28
    p, truth = make_demo_take(frames=frames, markers=markers, strays=4, seed=3, noise=1.2)
    for s in range(p.sensor_count):
        d = folder / f"channel_{s}"
        d.mkdir()
        src = ArraySource(p, s)
        for f in range(frames):
            cv2.imwrite(str(d / f"frame_{f:04d}.png"), src.read(f))
        p.sensors[s].media = MediaRef(str(d), kind="images")
        p.sensors[s].frame_count = frames
    cams = [[p.rig.camera(s, f) for f in range(frames)] for s in range(p.sensor_count)]
    for i in range(24):
        pt = p.new_point(point_id=i)
        present = slice(0, frames) if i % 7 else slice(0, 12)        # a few points stop: yellow labels
        pt.pos[present] = truth[present, i]
        pt.status[present] = ST_RECONSTRUCTED
        pt.residual[present] = 0.15
        for s in range(p.sensor_count):
            if (i + s) % 9 == 0:
                continue                                              # not every point in every view
            pt.src[present, s] = SRC_DETECTION
            pt.det[present, s] = i
            pt.uv[:, s] = [(float(r["x"]), float(r["y"])) for r in (p.detections[s].frame(f)[i] for f in range(frames))]
            pt.uv[present.stop:, s] = float("nan")
        p.add_point(pt)
    return p, truth


def open_take(tmp: Path, size=(1920, 1200), adjust=None):
    """The take of :func:`build_project` saved in ``tmp`` and opened in a main window (settings kept in ``tmp``).

    ``adjust(project)`` may change the project before it is saved.  Returns ``(app, window)``.
    """
    from PySide6.QtCore import QSettings

    from carapost.gui.app import ensure_app, settle
    from carapost.gui.mainwindow import MainWindow
    from carapost.io.cara import save_project

    app = ensure_app(offscreen=True)
    QSettings.setPath(QSettings.Format.IniFormat, QSettings.Scope.UserScope, str(tmp))
    os.environ["CARAPOST_DATA_DIR"] = str(tmp)
    project, _truth = build_project(tmp)
    if adjust is not None:
        adjust(project)
    save_project(project, tmp / "face_take.cara")
    win = MainWindow(synchronous_images=True, autosave_s=0, restore=False, persist=False)
    win.resize(*size)
    win.show()
    settle(app)
    assert win.files.open_path(str(tmp / "face_take.cara"))
    return app, win


def main() -> int:
    from carapost.core import editing
    from carapost.core.edits import SetLabels, SetProperties, SetRange
    from carapost.gui.app import settle

    with tempfile.TemporaryDirectory() as tmp:
        app, win = open_take(Path(tmp))
        ses = win.session
        p = ses.project
        names = ["Nose_Tip", "Nose_Bridge", "Chin", "Brow_L", "Brow_R", "Cheek_L", "Cheek_R", "Lip_Upper",
                 "Lip_Lower", "Mouth_L", "Mouth_R", "Jaw_L", "Jaw_R", "Forehead"]
        ses.run(SetLabels(names))
        for pid, name in zip([0, 1, 2, 3, 4, 5, 7, 8, 9], names):
            ses.run(editing.rename_point(p, pid, name))
        ses.run(editing.create_stick_mesh(p, 0))
        ses.run(SetProperties({"tracking.patch_match_threshold": 0.75}))
        ses.run(SetRange("active", 4, 24, name="Set Active Range"))
        win.navigate.set_frame(14)
        # merge a stray-free marker seen in two views into a new point, as a user would with M
        ses.run(editing.merge(p, 14, [], [(0, 14, 25), (1, 14, 25)]))
        ses.run(editing.SetChannelSelection([1]))
        ses.set_current_label("Cheek_R")
        ses.select(points=[2, 3])
        win.action("view2d.labels_all").trigger()
        settle(app)
        for v in win.grid.visible_views():        # Frame Selection on the whole face
            v.frame_on(ses.frame_data().position_2d(v.sensor), margin=35)
        win.docks["properties"].raise_()
        settle(app, 10)
        ok = win.grab().save(str(OUT))
        ses.doc.stack.mark_clean()
        win.close()
    print(OUT if ok else "failed")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
    sys.exit(main())
