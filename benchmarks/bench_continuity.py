"""Continuity chart, Selected Point pane and Graph view speed, offscreen.

1. Continuity chart redraw for 250 points x 36,000 frames (4 sensors): the time
   of ``render()`` plus the paint of the widget, warm cache.  Target <= 50 ms.
   The cold build (every point's codes after an edit) is reported too.
2. Switching the selected point: Selected Point pane and Graph view updated
   and painted.  Target <= 30 ms.
"""
from __future__ import annotations

import os
import statistics
import time

import numpy as np

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")


def _take(frames: int, points: int, sensors: int = 4, seed: int = 0):
    from carapost.core.points import SRC_DETECTION, SRC_PATCH, SRC_TARGET, ST_NONE, ST_RECONSTRUCTED
    from carapost.core.project import Project

    rng = np.random.default_rng(seed)
    p = Project(frames, sensors, 60.0, name="continuity")
    t = np.arange(frames)[:, None]
    for i in range(points):
        pt = p.new_point(label=f"M{i:03d}")
        pt.pos[:] = rng.normal(0, 40, 3) + np.sin(t / 50.0 + i)
        pt.status[:] = ST_RECONSTRUCTED
        pt.src[:] = SRC_DETECTION
        pt.uv[:] = rng.uniform(0, 700, 2).astype(np.float32)
        for _ in range(20):                                   # gaps and other sources here and there
            a = int(rng.integers(0, frames - 200))
            n = int(rng.integers(1, 200))
            kind = rng.integers(0, 4)
            if kind == 0:
                pt.status[a:a + n] = ST_NONE
                pt.src[a:a + n] = 0
            else:
                s = int(rng.integers(0, sensors))
                pt.src[a:a + n, s] = (0, SRC_PATCH, SRC_TARGET, SRC_PATCH)[kind]
                pt.score[a:a + n, s] = rng.random(n)
        p.add_point(pt)
    return p


def run(quick: bool = False) -> list[dict]:
    from PySide6.QtWidgets import QApplication

    from carapost.core.document import Document
    from carapost.gui.app import ensure_app, settle
    from carapost.gui.continuity import ContinuityChart
    from carapost.gui.graphview import GraphView
    from carapost.gui.panes.selected_point import SelectedPointPane
    from carapost.gui.session import Session

    app = ensure_app(offscreen=True)
    frames = 3600 if quick else 36_000
    n_points = 250
    p = _take(frames, n_points)
    session = Session()
    session.set_document(Document(p))
    chart = ContinuityChart(session)
    chart.resize(1200, 800)
    chart.show()
    pane = SelectedPointPane(session)
    pane.resize(1200, 140)
    pane.show()
    graph = GraphView(session)
    graph.resize(1200, 600)
    graph.show()
    settle(app)
    out: list[dict] = []

    # ------------------------------------------------------------ cold build
    colds = []
    for _ in range(3 if quick else 5):
        chart.model.invalidate()
        t = time.perf_counter()
        chart.render()
        colds.append((time.perf_counter() - t) * 1e3)

    # ------------------------------------------------------------ redraw (warm)
    times = []
    reps = 5 if quick else 15
    for i in range(reps):
        t = time.perf_counter()
        chart.render()
        chart.viewport().repaint()
        times.append((time.perf_counter() - t) * 1e3)
    full_shape, full_bin = list(chart.image.image.shape), chart.bin
    # zoomed in: a different frame window each time (drawn at one column per frame)
    zoomed = []
    for i in range(reps):
        x0 = (i * 997) % (frames - 2000)
        chart.vb.setRange(xRange=(x0, x0 + 1500), padding=0)
        t = time.perf_counter()
        chart.render()
        chart.viewport().repaint()
        zoomed.append((time.perf_counter() - t) * 1e3)
    med = statistics.median(times)
    out.append({"benchmark": f"continuity_chart_redraw_{n_points}_points_{frames}_frames", "value": round(med, 2),
                "unit": "ms", "target": "<= 50", "pass": med <= 50.0,
                "p95_ms": round(float(np.percentile(times, 95)), 2),
                "zoomed_median_ms": round(statistics.median(zoomed), 2),
                "cold_build_median_ms": round(statistics.median(colds), 2),
                "image_shape": full_shape, "frames_per_column": full_bin})

    # ------------------------------------------------------------ switching the selected point
    ids = list(p.points)
    sw = []
    for i in range(reps * 2):
        pid = ids[(i * 37) % len(ids)]
        t = time.perf_counter()
        session.select(points=[pid])
        pane.bars.viewport().repaint()
        graph.viewport().repaint()
        sw.append((time.perf_counter() - t) * 1e3)
    warm = sw[2:]
    med = statistics.median(warm)
    out.append({"benchmark": f"selected_point_switch_{frames}_frames", "value": round(med, 2), "unit": "ms",
                "target": "<= 30", "pass": med <= 30.0, "p95_ms": round(float(np.percentile(warm, 95)), 2),
                "graph_lines": len(graph.lines), "pane_rows": len(pane.bars.rows),
                "note": "pane + graph updated and repainted; includes the chart's selection highlight"})
    for w in (chart, pane, graph):
        w.close()
    QApplication.processEvents()
    return out


if __name__ == "__main__":  # pragma: no cover
    import json
    import sys

    for r in run(quick="--quick" in sys.argv):
        print(json.dumps(r))
