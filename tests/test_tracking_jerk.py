"""A region that changes speed at once (issue 7): the neighbours' vote on the 2-D displacement.

On the rendered 156-marker take the jaw jumped 7-9 mm in one frame; every lower-face
prediction fell 5-15 px short and points took the blob of the neighbour ahead
(Lip_Area_R_2 took Lip_Lower_C's).  :mod:`carapost.core.tracking.vote` moves such
predictions onto the displacement most of the region agrees on.
"""
import numpy as np
import pytest

from carapost.core.detections import make_detections
from carapost.core.tracking import elastic, track, vote
from carapost.core.tracking.engine import FrameData
from carapost.core.tracking.evaluate import evaluate
from carapost.core.tracking.synthetic_take import initialise, make_take


class _IdentityRig:
    """Corrected pixels are raw pixels (FrameData only asks the rig to correct)."""

    def correct(self, s, xy):
        return np.asarray(xy, float)

    def correct_all(self, sensor, xy):
        return np.asarray(xy, float).copy()


def _frame(xy):
    n = len(xy)
    rec = make_detections(xy[:, 0], xy[:, 1], np.full(n, 8.0), np.full(n, 6.0), np.zeros(n), np.ones(n))
    return FrameData(_IdentityRig(), [rec])


def _asked(fd, pred):
    """The views the frame tracker puts to the vote: nearest blob more than ``ASK_PX`` off, a second in reach."""
    d = np.sort(np.hypot(*(fd.xy[0][None] - pred[:, None]).transpose(2, 0, 1)), axis=1)
    return ((d[:, 0] > vote.ASK_PX) & (d[:, 1] <= 35.0))[:, None]


def _region(rng, centre, n=7, spread=14.0, gap=9.0):
    """``n`` dots around ``centre`` at least ``gap`` px apart, irregular as painted dots are."""
    out = []
    while len(out) < n:
        q = centre + rng.uniform(-spread, spread, 2)
        if all(np.hypot(*(q - o)) >= gap for o in out):
            out.append(q)
    return np.array(out)


def test_a_region_that_jumped_is_moved_onto_its_own_blobs():
    """Seven dots jump 13 px along their row; seven others stay.  Most jumped dots' nearest blob is
    a neighbour's; the vote moves each onto its own, and leaves the still dots alone."""
    rng = np.random.default_rng(3)
    moving = _region(rng, np.array([200.0, 300.0]))
    still = _region(rng, np.array([200.0, 200.0]))
    jump = np.array([13.0, 2.0])
    pred = np.concatenate([moving, still])
    fd = _frame(np.concatenate([moving + jump, still]))
    X3 = np.column_stack([pred, np.zeros(len(pred))])
    nb = elastic.neighbours(X3)
    assert not np.any(np.isin(nb[:7], np.arange(7, 14)))        # premise: two separate regions
    nearest = np.hypot(*(fd.xy[0][None] - pred[:7, None]).transpose(2, 0, 1)).argmin(1)
    assert np.count_nonzero(nearest != np.arange(7)) >= 3      # premise: the nearest blob is often another's
    uv = pred[:, None, :]
    slots = np.ones((14, 1), bool)
    ask = _asked(fd, pred)
    out = vote.nudges(uv, slots, ask, fd, 35.0, nb, np.ones(nb.shape))
    got = uv + out
    # Each moving dot whose own blob was not the nearest is now on it; the still dots did not move.
    wrong = nearest != np.arange(7)
    assert np.allclose(got[:7][wrong, 0], (moving + jump)[wrong], atol=1e-3)
    assert np.all(out[7:] == 0)


def test_unsteady_neighbours_are_outvoted_by_steady_ones():
    """A dot between two regions (a lower lip between the upper lip and the chin): the region whose
    offsets to it stayed steady decides.  With even weights the still side ties and nothing moves."""
    rng = np.random.default_rng(5)
    chin = _region(rng, np.array([200.0, 330.0]), n=3, spread=8.0, gap=8.0)
    upper = _region(rng, np.array([200.0, 270.0]), n=3, spread=8.0, gap=8.0)
    lip = np.array([[200.0, 300.0]])
    pred = np.concatenate([lip, chin, upper])
    jump = np.array([0.0, 12.0])
    moved = np.concatenate([lip + jump, chin + jump, upper])
    # A stray dot 1 px from the lip's prediction: the nearest, and what pass 1 would take.
    fd = _frame(np.concatenate([moved, [[201.0, 300.0]]]))
    # Each dot's six neighbours are the other six; offsets within the jaw (lip and chin) and within the
    # upper lip stayed steady, offsets across changed.
    nb = np.array([[j for j in range(7) if j != i] for i in range(7)])
    side = np.array([0, 0, 0, 0, 1, 1, 1])
    steady = np.where(side[nb] == side[:, None], 100.0, 1.0)
    uv = pred[:, None, :]
    slots = np.ones((7, 1), bool)
    ask = _asked(fd, pred)
    assert ask[1:4].all()                           # the chin is asked (the lip for its neighbours' unrest)
    out = vote.nudges(uv, slots, ask, fd, 35.0, nb, steady)
    assert np.allclose(uv[0, 0] + out[0, 0], lip[0] + jump)
    out_even = vote.nudges(uv, slots, ask, fd, 35.0, nb, np.ones(nb.shape))
    assert np.all(out_even[0] == 0)


def test_a_view_without_its_blob_stays_where_its_neighbours_did():
    """A dot undetected in one camera while its neighbours sit on their blobs (rendered 100-marker take
    backwards: Cheek_R_7 was sent 30 px onto another dot on 11 frames, and a chin point lost track).
    Staying put is a candidate of the vote, and the neighbours vote for it: over 30 random layouts
    nothing moves (voting among the blobs alone moved 8 of them)."""
    for seed in range(30):
        rng = np.random.default_rng(seed)
        dots = _region(rng, np.array([200.0, 200.0]), n=12, spread=40.0, gap=10.0)
        fd = _frame(np.delete(dots, 0, axis=0) + rng.normal(0, 0.2, (len(dots) - 1, 2)))
        nb = elastic.neighbours(np.column_stack([dots, np.zeros(len(dots))]))
        slots = np.ones((len(dots), 1), bool)
        ask = np.zeros_like(slots)
        ask[0] = True
        out = vote.nudges(dots[:, None, :], slots, ask, fd, 35.0, nb, np.ones(nb.shape))
        assert np.all(out == 0), seed


@pytest.fixture(scope="module")
def jerk_take():
    """100 markers, 40 frames; the jaw opens 8 mm at the chin in one frame (and closes so, later)."""
    return dict(markers=100, frames=40, seed=4, jaw_mm=8.0, jaw_frames=1, blinks=0, occlusion_rate=0.0,
                hidden_markers=0, slips=0)


def _tracked(kw):
    sc = make_take(**kw)
    initialise(sc, 0)
    track(sc.project, 0, 1).do(sc.project)
    return evaluate(sc, 0, range(1, kw["frames"]))


def test_tracking_through_a_jaw_jerk_swaps_nothing(jerk_take, monkeypatch):
    """Without the vote three lower-face points took their neighbours' blobs (159 wrong samples)."""
    r = _tracked(jerk_take)
    assert r["swaps"] == 0 and r["wrong_samples"] == 0, r
    assert r["coverage"] > 0.999
    monkeypatch.setattr(vote, "nudges", lambda uv, slots, *a: np.zeros(slots.shape + (2,)))
    r0 = _tracked(jerk_take)
    assert r0["wrong_samples"] > 0                   # the premise: the jerk defeats point-by-point matching
