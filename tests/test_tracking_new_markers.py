"""A marker that no point follows is given a point while tracking (engine step 10, issue 7).

On the rendered 100-marker take of seed 3, Initialize 3D on the last frame found no point for two
chin dots seen at grazing angles there (undetected on that frame); tracking backwards left them
without a point for the 220 frames they were visible: coverage 0.983.  Tracking now matches the
detections no point took, and a match on the face, clear of every point, found on two frames in a
row becomes a new point (Tracking Parameters > Add Points For New Markers).
"""
import copy

import numpy as np
import pytest

from carapost.core.edits import DeletePoints
from carapost.core.points import SRC_DETECTION, ST_NONE, ST_RECONSTRUCTED
from carapost.core.tracking import elastic, spawn, track
from carapost.core.tracking.evaluate import identify
from carapost.core.tracking.geometry import RigState
from test_tracking_returns import hide

import test_tracking

#: 35 markers of slow head motion, initialised on frame 0.
quiet = test_tracking.quiet

M = 7


def without_point(sc, m=M, sure_from=0):
    """A copy of ``sc`` whose marker ``m`` has no point (as if Initialize 3D had not found it), its blobs
    scored as surely dots from frame ``sure_from`` on and as doubtful ones before (the synthetic take's
    scores are drawn at random, 0.6-1)."""
    sc = copy.deepcopy(sc)
    for f in range(sc.project.frame_count):
        for s in range(sc.project.sensor_count):
            if sc.face_det[f, s, m] >= 0:
                rec = sc.project.detections[s].frame(f).copy()
                rec["score"][sc.face_det[f, s, m]] = 0.99 if f >= sure_from else 0.7
                sc.project.detections[s].set_frame(f, rec)
    pid = next(p for p, mm in identify(sc, 0).items() if mm == m)
    DeletePoints([pid]).do(sc.project)
    return sc


def run(sc, **kw):
    before = set(sc.project.points)
    cmd = track(sc.project, 0, 1, **kw)
    cmd.do(sc.project)
    return cmd, [q for q in sc.project.face_points() if q.id not in before], before


def test_a_marker_without_a_point_is_given_one_that_follows_it(quiet):
    sc = without_point(quiet)
    cmd, new, before = run(sc)
    assert len(new) == 1 and cmd.report["new_points"] == 1
    assert "1 new points" in cmd.summary
    q = new[0]
    f = np.flatnonzero(q.status == ST_RECONSTRUCTED)
    # Found on frames 1 and 2, made on 2, then tracked to the end like any other point (and back to frame 1).
    assert np.array_equal(f, np.arange(1, sc.project.frame_count))
    assert np.max(np.linalg.norm(q.pos[f] - sc.face[f, M], axis=1)) < 0.2
    # Its views are the marker's own detections.
    for fr in f:
        for s in np.flatnonzero(q.src[fr] == SRC_DETECTION):
            assert q.det[fr, s] == sc.face_det[fr, s, M]
    assert q.label == "" and q.status[0] == ST_NONE
    # One undo step takes the tracking and the new point back.
    cmd.undo(sc.project)
    assert set(sc.project.points) == before
    cmd.do(sc.project)
    assert np.array_equal(sc.project.points[q.id].status, q.status)


def test_a_new_point_is_tracked_back_over_the_frames_before_it_was_sure(quiet):
    # The marker's blobs score 0.7 until frame 10 (a dot half under the hair): no point is made from them, but
    # once one is made on frame 11 it is tracked back to frame 1 (frame 0 is the start frame: left as it is).
    sc = without_point(quiet, sure_from=10)
    cmd, new, _ = run(sc)
    assert len(new) == 1
    q = new[0]
    f = np.flatnonzero(q.status == ST_RECONSTRUCTED)
    assert np.array_equal(f, np.arange(1, sc.project.frame_count))
    assert np.max(np.linalg.norm(q.pos[f] - sc.face[f, M], axis=1)) < 0.2
    for fr in range(1, 11):
        assert set(q.det[fr][q.src[fr] == SRC_DETECTION]) <= set(sc.face_det[fr, :, M])


def test_no_point_is_made_when_the_property_is_off_or_a_point_is_left_out(quiet):
    sc = without_point(quiet)
    sc.project.properties.set("tracking.add_points_for_new_markers", False)
    assert run(sc)[1] == []
    sc.project.properties.set("tracking.add_points_for_new_markers", True)
    # Tracking only some points: the others' markers are not where the tracker could see them.
    some = [q.id for q in sc.project.face_points()][:20]
    cmd, new, _ = run(sc, point_ids=some)
    assert new == [] and "no points made for new markers: 14 face point(s) not tracked" in cmd.summary


def test_a_lost_marker_coming_back_is_picked_up_by_its_own_point_not_given_another(quiet):
    sc = copy.deepcopy(quiet)
    hide(sc, M, range(4, 14), {})
    pid = next(p for p, mm in identify(sc, 0).items() if mm == M)
    cmd, new, _ = run(sc)
    assert new == []
    q = sc.project.points[pid]
    assert q.status[8] == ST_NONE and q.status[15] == ST_RECONSTRUCTED


def frame_geometry(sc, f=5):
    """The frame's true cameras and markers."""
    rig = RigState(sc.cameras[f])
    return rig, sc.face[f]


def test_candidates_keep_to_the_face_and_clear_of_every_point(quiet):
    sc = quiet
    rig, X = frame_geometry(sc)
    others = np.delete(X, M, axis=0)
    spacing = elastic.spacing(X)
    # The marker's projections, and those of a point 10 mm in front of the face (a stray match).
    centre = X.mean(axis=0)
    stray = X[M] + 10.0 * (X[M] - centre) / np.linalg.norm(X[M] - centre)
    proj = rig.project(np.array([X[M], stray]))
    xy = [proj[:, s] for s in range(rig.S)]
    choice, Xn = spawn.candidates(rig, xy, others, others, np.delete(spacing, M))
    assert len(Xn) == 1 and np.linalg.norm(Xn[0] - X[M]) < 1e-6
    assert np.all(choice[0] == 0)                       # seen by all four cameras
    # Where a lost point is predicted, the match is that point's marker.
    known = np.concatenate([others, X[M][None] + 1.0])
    assert len(spawn.candidates(rig, xy, others, known, np.r_[np.delete(spacing, M), spacing[M]])[1]) == 0
    # Blobs unlike a marker's: a low classifier score in one view, or half a marker's size (a freckle).
    D = spawn.view_depth(rig, X[M][None])[0]
    marker_px = 3.0 * rig.K[:, 0, 0] / D                     # a 3 mm dot's major axis in each camera
    def blobs(scale, score):
        return [np.array([[scale * marker_px[s], score], [marker_px[s], 1.0]]) for s in range(rig.S)]
    assert len(spawn.candidates(rig, xy, others, others, np.delete(spacing, M), blobs=blobs(1.0, 0.99),
                                marker_mm=3.0)[1]) == 1
    assert len(spawn.candidates(rig, xy, others, others, np.delete(spacing, M), blobs=blobs(1.0, 0.5),
                                marker_mm=3.0)[1]) == 0
    assert len(spawn.candidates(rig, xy, others, others, np.delete(spacing, M), blobs=blobs(0.55, 0.99),
                                marker_mm=3.0)[1]) == 0
    # Seen by two cameras only (a grazing dot): still a candidate.
    two = [proj[:1, s] if s < 2 else np.zeros((0, 2)) for s in range(rig.S)]
    choice, Xn = spawn.candidates(rig, two, others, others, np.delete(spacing, M))
    assert len(Xn) == 1 and np.array_equal(choice[0] >= 0, [True, True, False, False])


@pytest.mark.parametrize("agree", [True, False])
def test_a_candidate_stands_only_where_its_neighbours_carried_it(agree):
    X_last = np.array([[0.0, 0.0, 0.0]])
    nbr = np.array([[0, 1]])
    nbr_last = np.array([[[10.0, 0, 0], [0, 10.0, 0]]])
    now = np.array([[12.0, 0, 0], [2.0, 10.0, 0]])            # both neighbours moved 2 mm along x
    cand = np.array([[2.0, 0.0, 0.3]]) if agree else np.array([[0.0, 0.0, 0.3]])
    assert spawn.carried_to(X_last, nbr, nbr_last, now, cand)[0] == agree


def test_a_freckle_does_not_stand_out_from_the_skin_as_a_marker_does():
    # Skin shaded from 200 down to 60 grey levels; black dots take 80 % of its light, a freckle 25 %.
    H, W = 120, 400
    skin = np.tile(np.linspace(200.0, 60.0, W), (H, 1))
    yy, xx = np.mgrid[:H, :W]
    markers = [(40.0 + 40 * i, 40.0) for i in range(8)]
    img = skin.copy()
    for x, y in markers:
        img[np.hypot(xx - x, yy - y) <= 4] *= 0.2
    img[np.hypot(xx - 200.5, yy - 90) <= 4] *= 0.75          # the freckle, among markers as dark as any
    img[np.hypot(xx - 330.0, yy - 90) <= 4] *= 0.2           # a marker on the shaded side
    img = img.astype(np.uint8)
    share = spawn.dot_contrast(img, np.array(markers), np.full(len(markers), 8.0))
    assert np.all(share > 0.7)
    ref_xy, ref_major = [np.array(markers)], [np.full(len(markers), 8.0)]
    cand = [np.array([[200.5, 90.0], [330.0, 90.0]])]
    keep = spawn.stands_out([lambda: img], np.array([[0], [1]]), cand, [np.array([8.0, 8.0])], ref_xy, ref_major)
    assert keep.tolist() == [False, True]


def test_a_cancelled_run_keeps_the_points_it_made_and_a_live_display_sees_the_known_points_only(quiet):
    from carapost.core.commands import UndoStack
    from carapost.core.progress import Progress

    sc = without_point(quiet)
    pr = sc.project
    known = {q.id for q in pr.face_points()}
    d0 = pr.digest()
    seen_ids = set()
    prog = Progress(listener=lambda frame, payload: seen_ids.update(payload["ids"].tolist()))
    prog._callback = lambda done, total, msg: prog.cancel() if done >= 10 else None
    cmd = track(pr, 0, 1, progress=prog)
    assert cmd.cancelled and cmd.report["frames"] == 10 and cmd.report["new_points"] == 1
    # Published while tracking: the points the project holds (face and brim), not the one made meanwhile.
    assert known <= seen_ids <= set(pr.points)
    stack = UndoStack(pr)
    stack.push(cmd)
    q = next(q for q in pr.face_points() if q.id not in known)
    # Made on frame 2 and kept to the last frame done; a cancelled run is not tracked back.
    assert np.array_equal(np.flatnonzero(q.status == ST_RECONSTRUCTED), np.arange(2, 11))
    stack.undo()
    assert pr.digest() == d0


@pytest.mark.parametrize("level,made", [(30, True), (135, False)])
def test_with_images_a_match_as_faint_as_a_freckle_makes_no_point(quiet, level, made):
    """Through the tracker: marker M's blobs score 0.99 and have a marker's size, but where the images show it
    grey level 135 on skin of ~160 (the markers 30), it does not stand out as a marker does."""
    import cv2

    sc = without_point(quiet)
    cache = {}

    def images(s, f):
        if (s, f) not in cache:
            img = test_tracking.render(sc, s, f)
            x, y = sc.cameras[f][s].project(sc.face[f, M][None])[0]
            if sc.face_det[f, s, M] >= 0:
                cv2.circle(img, (int(round(x * 16)), int(round(y * 16))), 16 * 4, level, -1, cv2.LINE_AA, 4)
            cache[(s, f)] = img
        return cache[(s, f)]

    cmd, new, _ = run(sc, end_frame=12, images=images)
    assert len(new) == int(made)


def test_a_new_point_is_tracked_back_while_another_point_is_lost_on_the_frame_it_was_made(quiet):
    # The tracking back starts from the frame the new point was made on (11); a point lost there (its marker
    # hidden in every camera on frames 8-14) has no position to take its neighbours from.  Measured: the run
    # stopped with "data must be finite" (scipy's tree of the points' positions) before elastic.neighbours
    # left such points out.
    sc = without_point(quiet, sure_from=10)
    pid, other = next((p, m) for p, m in identify(sc, 0).items() if m != M)
    hide(sc, other, range(8, 15), keep={})
    cmd, new, _ = run(sc)
    assert len(new) == 1
    q = new[0]
    assert np.array_equal(np.flatnonzero(q.status == ST_RECONSTRUCTED), np.arange(1, sc.project.frame_count))
    assert np.max(np.linalg.norm(q.pos[1:] - sc.face[1:, M], axis=1)) < 0.2
    assert sc.project.points[pid].status[11] == ST_NONE


def test_points_without_a_position_have_no_neighbours_and_are_no_ones():
    X = np.random.default_rng(0).normal(0.0, 10.0, (12, 3))
    X[[3, 7]] = np.nan
    nb = elastic.neighbours(X, k=4, mutual=2)
    assert np.all(nb[[3, 7]] == -1)
    assert not np.isin(nb, [3, 7]).any()
    keep = np.array([i for i in range(12) if i not in (3, 7)])
    sub = elastic.neighbours(X[keep], k=4, mutual=2)
    np.testing.assert_array_equal(nb[keep], np.where(sub >= 0, keep[np.maximum(sub, 0)], -1))
