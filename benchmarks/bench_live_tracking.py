"""What watching a track costs: Track Forwards [Sequence] with and without the live display.

160 face points x 4 cameras on a quiet synthetic take, initialised on frame 0,
tracked to the end through the Process menu action in the offscreen main window
(Selected Point pane showing one of the points, a Continuity chart of every
point in the fourth view slot).  Each setting combination (both off; Update
Timeline Every Frame; both Update Timeline and Update 2D View Every Frame) is
timed from the menu action to the command pushed, the runs interleaved.  The
result is the extra CPU time of the process (tracker and GUI threads) against
both settings off, medians: on a shared machine the wall time varies by tens of
percent from run to run, the CPU time much less (wall-time figures are reported
beside it).  Target: Update Timeline Every Frame at most 10 % more.  Also the engine's own cost of
publishing (``Progress.publish`` payloads, nobody drawing them).
Run: ``.venv/bin/python benchmarks/bench_live_tracking.py [--quick]``.
"""
from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

QUIET = dict(jaw_mm=0.0, blinks=0, occlusion_rate=0.0, hidden_markers=0, slips=0)
MODES = {"off": (False, False), "timeline": (True, False), "timeline_2d": (True, True)}


def _engine_cost(project, frames: int) -> dict:
    """Share of the tracking time spent building the published payloads."""
    from carapost.core.progress import Progress
    from carapost.core.tracking import api

    spent = [0.0]
    real = api._publish

    def timed(*a):
        t = time.perf_counter()
        real(*a)
        spent[0] += time.perf_counter() - t

    api._publish = timed
    try:
        t = time.perf_counter()
        api.track(project, 0, +1, end_frame=frames - 1, progress=Progress(listener=lambda f, pl: None))
        total = time.perf_counter() - t
    finally:
        api._publish = real
    share = 100 * spent[0] / total
    return {"benchmark": "live_tracking_publish_share_160_points", "value": round(share, 2), "unit": "%",
            "target": "<= 3", "pass": share <= 3, "ms_per_frame": round(1000 * spent[0] / (frames - 1), 3)}


def run(quick: bool = False) -> list[dict]:
    from PySide6.QtCore import QEventLoop, QSettings

    from carapost.core.document import Document
    from carapost.core.edits import SetProperties
    from carapost.core.tracking.synthetic_take import initialise, make_take
    from carapost.gui.app import ensure_app, settle
    from carapost.gui.demo_take import ArraySource
    from carapost.gui.mainwindow import MainWindow

    frames, reps = (60, 1) if quick else (240, 7)
    sc = make_take(160, frames, seed=4, **QUIET)
    initialise(sc, 0)
    p = sc.project
    out = [_engine_cost(p, frames)]
    app = ensure_app(offscreen=True)
    with tempfile.TemporaryDirectory(dir=os.environ.get("CARAPOST_BENCH_DIR")) as d:
        QSettings.setPath(QSettings.Format.IniFormat, QSettings.Scope.UserScope, d)
        os.environ["CARAPOST_DATA_DIR"] = d
        win = MainWindow(synchronous_images=True, autosave_s=0, restore=False, persist=False)
        win.resize(1400, 900)
        win.show()
        win.files.show_document(Document(p))
        win.session.loader.set_sources([ArraySource(p, s) for s in range(p.sensor_count)],
                                       [s.image_offset for s in p.sensors])
        win.grid.set_slot_kind(3, "continuity")
        settle(app)
        pid = next(q.id for q in p.face_points())

        def once(timeline: bool, views: bool) -> float:
            win.session.run(SetProperties({"tracker.update_timeline_every_frame": timeline,
                                           "tracker.update_2d_view_every_frame": views}))
            win.navigate.set_frame(0)
            win.session.select(points=[])
            loop = QEventLoop()
            win.runner.jobFinished.connect(loop.quit)
            t, c = time.perf_counter(), time.process_time()
            win.action("process.track_fwd_seq").trigger()
            win.session.select(points=[pid])        # every point is tracked; the pane shows one
            if win.runner.running:
                loop.exec()
            dt, dc = time.perf_counter() - t, time.process_time() - c
            win.runner.jobFinished.disconnect(loop.quit)
            win.session.doc.undo()                   # the track, then the settings' edit
            win.session.doc.undo()
            return dt, dc

        once(True, True)                             # warm-up: first paints, caches

        times: dict[str, list[tuple[float, float]]] = {m: [] for m in MODES}
        for _ in range(reps):
            for m, (timeline, views) in MODES.items():
                times[m].append(once(timeline, views))
        win.close()
    def med(m, i):
        return statistics.median(t[i] for t in times[m])

    for m in ("timeline", "timeline_2d"):
        slower = 100 * (med(m, 1) / med("off", 1) - 1)
        res = {"benchmark": f"live_tracking_{m}_extra_cpu_160_points", "value": round(slower, 1), "unit": "%",
               "cpu_median_s": round(med(m, 1), 3), "off_cpu_median_s": round(med("off", 1), 3),
               "wall_median_s": round(med(m, 0), 3), "off_wall_median_s": round(med("off", 0), 3),
               "wall_min_slowdown_pct": round(100 * (min(t[0] for t in times[m]) /
                                                     min(t[0] for t in times["off"]) - 1), 1),
               "runs": reps, "frames": frames - 1}
        if m == "timeline":
            res.update(target="<= 10", **{"pass": slower <= 10})
        out.append(res)
    return out


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(r)
