"""Continuity colours computed from points (Qt-free)."""
from __future__ import annotations

import time

import numpy as np

from carapost.core import continuity as C
from carapost.core.points import (SRC_DETECTION, SRC_KEYFRAME, SRC_PATCH, SRC_TARGET, ST_INTERPOLATED,
                                  ST_NONE, ST_RECONSTRUCTED, ST_SINGLE)
from carapost.core.project import Project


def _point(p, label="P"):
    pt = p.new_point(label=label)
    p.add_point(pt)
    return pt


def test_point_bar_colours_follow_channel_count_and_status():
    p = Project(10, 4)
    pt = _point(p)
    pt.status[:] = ST_RECONSTRUCTED
    for f, n in enumerate([4, 3, 2, 1, 0]):
        pt.src[f, :n] = SRC_DETECTION
    pt.status[3] = ST_SINGLE
    pt.status[4] = ST_INTERPOLATED
    pt.status[5:7] = ST_NONE                  # gap
    pt.src[5, :] = SRC_DETECTION              # 2D data but no 3D point: still a gap
    pt.src[7:, :2] = SRC_PATCH
    rgba = C.point_rgba(pt)
    want = ["dark_green", "light_green", "yellow", "orange", "red", "gap", "gap", "yellow", "yellow", "yellow"]
    for f, name in enumerate(want):
        assert tuple(rgba[f]) == C.COLORS[name], (f, name)
    assert rgba[5, 3] == 0                    # transparent


def test_channel_rows_by_source_and_score():
    p = Project(6, 4)
    pt = _point(p)
    pt.src[0, 0] = SRC_DETECTION
    pt.src[1, 0] = SRC_PATCH
    pt.src[2, 0] = SRC_KEYFRAME
    pt.src[3:6, 1] = SRC_TARGET
    pt.score[3:6, 1] = [1.0, 0.0, np.nan]
    pt.keyframes[(5, 2)] = (5, 5, 10, 10)
    rgba = C.channel_rgba(pt)
    assert rgba.shape == (4, 6, 4)
    assert tuple(rgba[0, 0]) == C.COLORS["blob"]
    assert tuple(rgba[0, 1]) == C.COLORS["patch"]
    assert tuple(rgba[0, 2]) == C.COLORS["key"]
    assert tuple(rgba[0, 3]) == C.COLORS["gap"]
    good, bad = rgba[1, 3], rgba[1, 4]
    assert good[1] > 200 and good[0] < 100 and bad[0] > 200 and bad[1] < 100
    assert tuple(rgba[1, 5]) == tuple(good)            # no score: drawn as good
    assert tuple(rgba[2, 5]) == C.COLORS["key"]        # keyframe from the keyframes dict
    assert C.target_color(1.0) == tuple(good)


def test_model_caches_bins_and_invalidates():
    p = Project(100, 4)
    a, b = _point(p, "A"), _point(p, "B")
    for pt in (a, b):
        pt.status[:] = ST_RECONSTRUCTED
        pt.src[:] = SRC_DETECTION
    a.status[41] = ST_NONE                                 # a one-frame gap
    m = C.ContinuityModel(p)
    codes, step, first = m.codes([(a.id, -1), (b.id, -1), (a.id, 2)])
    assert step == 1 and first == 0 and codes.shape == (3, 100)
    assert codes[0, 41] == C.C_GAP and codes[1, 41] == C.C_DGREEN and codes[2, 41] == C.C_BLOB
    codes, step, first = m.codes([(a.id, -1)], 0, 100, columns=30)
    assert step == 4 and codes.shape[1] <= 30 and codes[0, 41 // 4] == C.C_GAP   # the gap survives binning
    codes, step, first = m.codes([(a.id, -1)], 37, 60, columns=1000)
    assert first == 37 and codes[0, 41 - 37] == C.C_GAP
    a.status[41] = ST_RECONSTRUCTED
    assert m.bar(a.id)[41] == C.C_GAP                       # cached until invalidated
    m.invalidate([a.id])
    assert m.bar(a.id)[41] == C.C_DGREEN


def test_250_points_36000_frames_build_fast():
    F, n = 36_000, 250
    p = Project(F, 4)
    rng = np.random.default_rng(1)
    for i in range(n):
        pt = _point(p, f"M{i}")
        pt.status[:] = ST_RECONSTRUCTED
        pt.src[:] = rng.integers(0, 3, (F, 4), dtype=np.uint8)
    rows = [(pid, -1) for pid in p.points]
    best = np.inf
    for _ in range(3):
        m = C.ContinuityModel(p)
        t = time.perf_counter()
        img = np.stack([C.LUT[m.bar(pid)] for pid, _c in rows[:1]])   # warm numpy
        t = time.perf_counter()
        codes, _b, _f = m.codes(rows)
        best = min(best, time.perf_counter() - t)
    assert codes.shape == (n, F) and img.shape == (1, F, 4)
    assert best < 0.15, f"{best * 1e3:.0f} ms"          # ~25 ms on an idle core; generous for shared machines
