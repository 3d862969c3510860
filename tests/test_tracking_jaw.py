"""Tracking through a fast jaw opening (issue 7): the failure modes of rendered sample takes.

On rendered takes the lower lip and chin are seen at grazing angles once the jaw
opens: often by two cameras of one side only (~10 degrees apart), whose blobs
are detected 1-3 px off.  These tests rebuild those situations on a synthetic
take with ground truth, small enough to run in a few seconds.
"""
import copy

import numpy as np
import pytest

from carapost.core.tracking import elastic, track
from carapost.core.tracking.evaluate import identify
from carapost.core.tracking.synthetic_take import initialise, make_take

QUIET = dict(jaw_mm=0.0, blinks=0, occlusion_rate=0.0, hidden_markers=0, slips=0)
#: Cameras 0-1 and 2-3 of the synthetic rig are pairs ~10 degrees apart (one side of the face each).
PAIR, OTHER = (0, 1), (2, 3)


def test_prediction_follows_the_neighbours_that_moved_with_the_point():
    """A lower lip between three upper-lip and three jaw markers, lost while the jaw goes on opening.

    The plain median of the six neighbours leaves it half way; once the jaw has moved while the
    lip was seen, the weighted prediction follows the jaw markers.
    """
    upper = np.array([[-8.0, -6, 0], [0, -7, 0], [8, -6, 0]])
    jaw = np.array([[-8.0, 6, 0], [0, 8, 0], [8, 6, 0]])
    lip = np.zeros((1, 3))
    X = np.concatenate([lip, upper, jaw])
    nb = elastic.neighbours(X)
    off = np.full(nb.shape + (3,), np.nan)
    motion = np.zeros(nb.shape + (2,))
    measured = np.ones(len(X), bool)
    elastic.update_offsets(off, nb, X, measured, motion)
    down = np.array([0.0, 1.0, 0.0])
    for step in range(1, 5):                       # the jaw (and the lip with it) opens 2 mm a frame
        Xf = X.copy()
        Xf[[0, 4, 5, 6]] += 2.0 * step * down
        elastic.update_offsets(off, nb, Xf, measured, motion)
    Xf = X.copy()
    Xf[[0, 4, 5, 6]] += 16.0 * down                 # 8 mm more while the lip is hidden
    seen = measured.copy()
    seen[0] = False
    plain, _ = elastic.predict(Xf, seen, nb, off)
    weighted, _ = elastic.predict(Xf, seen, nb, off, weight=elastic.weights(motion))
    assert np.linalg.norm(plain[0] - Xf[0]) > 3.0
    assert np.linalg.norm(weighted[0] - Xf[0]) < 0.5


@pytest.fixture(scope="module")
def quiet():
    """35 markers, 30 frames of slow head motion, initialised on frame 0."""
    sc = make_take(35, 30, seed=4, **QUIET)
    initialise(sc, 0)
    return sc


def biased_pair(sc, m, frames, depth_mm, drop):
    """Marker ``m`` seen by the close pair as if ``depth_mm`` farther along their view, ``drop`` cameras blind.

    Both blobs move ~1 px, consistently (a point that far off in depth projects there), so their
    residuals stay small: only a camera of the other side, or the neighbours, can tell.
    """
    from support import remove_marker_detection

    for f in frames:
        X = sc.face[f, m]
        u = sum((X - sc.cameras[f][s].position) / np.linalg.norm(X - sc.cameras[f][s].position) for s in PAIR)
        Xb = X + depth_mm * u / np.linalg.norm(u)
        for s in PAIR:
            table = sc.project.detections[s]
            rec = table.frame(f).copy()
            i = sc.face_det[f, s, m]
            rec["x"][i], rec["y"][i] = sc.cameras[f][s].project(Xb[None])[0]
            table.set_frame(f, rec)
        for s in drop:
            remove_marker_detection(sc, f, s, m)


def tracked_errors(sc, m, frames):
    track(sc.project, 0, 1).do(sc.project)
    pid = next(pid for pid, mm in identify(sc, 0).items() if mm == m)
    p = sc.project.points[pid]
    return np.array([np.linalg.norm(p.pos[f] - sc.face[f, m]) for f in frames])


@pytest.mark.parametrize("drop", [OTHER[1:], OTHER], ids=["third-view-good", "pair-only"])
def test_close_pair_with_biased_blobs_does_not_pull_the_point_off(quiet, drop):
    """A chin marker's two close views detected off along their epipolar line for ten frames.

    With a good third view, the held-out test dropped that view (the close pair agrees with
    itself); with the pair alone nothing checked it: either way the point sat 4 mm deep.  Now a
    point seen only by close cameras keeps its depth within ``NARROW_DEPTH_MM`` of its
    neighbours' prediction, and the clamped frames do not refresh its neighbour offsets (else the
    prediction would walk after the biased pair).
    """
    from carapost.core.tracking.engine import NARROW_DEPTH_MM

    sc = copy.deepcopy(quiet)
    m, frames = 5, range(10, 20)
    biased_pair(sc, m, frames, 4.0, drop)
    err = tracked_errors(sc, m, frames)
    assert np.all(np.isfinite(err)), err                       # still tracked on every frame
    assert err.max() < NARROW_DEPTH_MM + 0.5, err
