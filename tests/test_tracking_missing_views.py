"""Tracking Parameters > Search Missing Views: a point's dot looked for again where the detections lack it."""
import copy

import cv2
import numpy as np
import pytest

from carapost.core.commands import UndoStack
from carapost.core.points import SRC_DETECTION, ST_NONE
from carapost.core.tracking import track
from carapost.core.tracking.missing_views import MEET_MM, PAIR_MEET_MM, REACH_PX, find_in_crops
from carapost.core.tracking.synthetic_take import initialise, make_take
from support import remove_marker_detection
from test_tracking import QUIET, marker_point, rendered

M = 3


@pytest.fixture(scope="module")
def quiet():
    """35 markers, 20 frames of slow head motion only, initialised on frame 0."""
    sc = make_take(35, 20, seed=4, **QUIET)
    initialise(sc, 0)
    return sc


def _undetected(quiet, frames=range(3, 15)):
    """Marker M's detections removed in every camera on ``frames`` (its dot stays in the images)."""
    sc = copy.deepcopy(quiet)
    for f in frames:
        for s in range(4):
            if sc.face_det[f, s, M] >= 0:
                remove_marker_detection(sc, f, s, M)
    return sc


def _counts(sc):
    """Every frame's detection count, per camera (20 frames)."""
    return [sc.project.detections[s].count(f) for f in range(20) for s in range(4)]


def test_dots_are_found_in_crops_where_they_are():
    """Discs at known sub-pixel centres are found within a tenth of a pixel, each for its own crop."""
    rng = np.random.default_rng(3)
    img = cv2.GaussianBlur(rng.uniform(130, 170, (240, 320)).astype(np.uint8), (0, 0), 2)
    centres = np.array([[60.3, 50.7], [150.8, 120.2], [250.45, 190.6]])
    for x, y in centres:
        cv2.circle(img, (int(round(x * 16)), int(round(y * 16))), 16 * 3, 40, -1, cv2.LINE_AA, 4)
    # Searched 2-3 px from each dot (the prediction is off), and once over bare skin.
    asked = centres + np.array([[2.0, -1.0], [-1.5, 2.0], [0.5, 2.5]])
    asked = np.vstack([asked, [[200.0, 60.0]]])
    rec, which = find_in_crops([img], asked, np.zeros(len(asked), int), white=False)
    assert sorted(which.tolist()) == [0, 1, 2]
    for k in range(3):
        got = np.array([rec["x"][which == k][0], rec["y"][which == k][0]], float)
        assert np.hypot(*(got - centres[k])) < 0.1, (k, got, centres[k])
        assert 5.0 < float(rec["major"][which == k][0]) < 8.0       # the disc's diameter, 6 px, in image px
    assert np.all(np.hypot(rec["x"] - asked[which, 0], rec["y"] - asked[which, 1]) <= REACH_PX)


def test_a_point_no_camera_detects_is_measured_from_the_dots_found(quiet):
    """Marker M undetected in every camera for 12 frames, its dot in the images: found and measured.

    Without the search, patches carry it for a few frames and then it is lost
    (test_tracking.py::test_patch_tracking_alone_stops_after_a_few_frames).
    """
    sc = _undetected(quiet)
    images = rendered(sc, lambda s, f: (M,) if 3 <= f < 15 else ())
    before = _counts(sc)
    stack = UndoStack(sc.project)
    cmd = stack.push(track(sc.project, 0, 1, end_frame=19, images=images))
    p = marker_point(sc, M)
    blobs = (p.src[3:15] == SRC_DETECTION).sum(1)
    assert np.all(blobs >= 2), blobs
    err = np.linalg.norm(p.pos[3:15] - sc.face[3:15, M], axis=1)
    assert np.all(err < 0.3), err
    # The dots found are the frame's detections now, and the samples point at them.
    for f in range(3, 15):
        for s in np.flatnonzero(p.src[f] == SRC_DETECTION):
            rec = sc.project.detections[s].frame(f)
            d = rec[p.det[f, s]]
            assert np.hypot(d["x"] - p.uv[f, s, 0], d["y"] - p.uv[f, s, 1]) < 1e-3
    after = _counts(sc)
    assert sum(after) - sum(before) >= 2 * 12
    # The log says how many (Log pane, carapost process's stderr).
    assert cmd.report["found_dots"] == sum(after) - sum(before)
    assert f"; {sum(after) - sum(before)} dots found by Search Missing Views" in cmd.summary
    stack.undo()
    assert _counts(sc) == before


def test_without_the_search_the_point_is_lost(quiet):
    """The same take with Search Missing Views off: no dot is added and the point is lost."""
    sc = _undetected(quiet)
    sc.project.properties.set("tracking.search_missing_views", False)
    images = rendered(sc, lambda s, f: (M,) if 3 <= f < 15 else ())
    before = sum(_counts(sc))
    track(sc.project, 0, 1, end_frame=19, images=images).do(sc.project)
    p = marker_point(sc, M)
    assert np.all(p.status[9:15] == ST_NONE)
    assert sum(_counts(sc)) == before


def test_a_dot_one_camera_shows_is_not_enough(quiet):
    """Marker M undetected everywhere and drawn in one camera only: one view cannot make the point whole."""
    sc = _undetected(quiet)
    s1 = next(s for s in range(4) if quiet.face_det[5, s, M] >= 0)
    images = rendered(sc, lambda s, f: (M,) if s == s1 and 3 <= f < 15 else ())
    before = _counts(sc)
    track(sc.project, 0, 1, end_frame=19, images=images).do(sc.project)
    p = marker_point(sc, M)
    assert not np.any((p.src[9:15] == SRC_DETECTION).sum(1) >= 2)
    assert _counts(sc) == before


@pytest.mark.parametrize("offset,cameras,taken", [(1.8, 4, False), (1.0, 2, False), (0.3, 2, True)])
def test_dots_are_taken_only_where_their_views_meet_near_the_prediction(quiet, offset, cameras, taken):
    """Marker M's dot drawn ``offset`` mm from it on the face, in up to ``cameras`` of the cameras that see it.

    Views of one 3-D place meet, so only the distance from the prediction turns them down: :data:`MEET_MM`
    for three or more views, :data:`PAIR_MEET_MM` for two.  (1.8 mm lies 4-5 px from the prediction's
    projection, within the search's reach.  No patch tracking: a patch would follow the marker's look onto
    the drawn dot on the first frames, before any search.)
    """
    assert PAIR_MEET_MM < 1.0 < MEET_MM < 1.8
    sc = _undetected(quiet)
    sc.project.properties.set("tracking.patch_match_threshold", 1.0)
    normal = np.mean([c.position for c in sc.cameras[0]], axis=0) - sc.face[0, M]
    side = np.cross(normal, [0.0, 0.0, 1.0])
    side *= offset / np.linalg.norm(side)
    drawn = [s for s in range(4) if np.all(quiet.face_det[3:15, s, M] >= 0)][:cameras]
    assert len(drawn) >= 2

    def images(s, f, base=rendered(sc)):
        img = base(s, f).copy()
        if 3 <= f < 15 and s in drawn:
            x, y = sc.cameras[f][s].project((sc.face[f, M] + side)[None])[0]
            cv2.circle(img, (int(round(x * 16)), int(round(y * 16))), 16 * 4, 30, -1, cv2.LINE_AA, 4)
        return img
    before = _counts(sc)
    track(sc.project, 0, 1, end_frame=19, images=images).do(sc.project)
    p = marker_point(sc, M)
    blobs = (p.src[3:15] == SRC_DETECTION).sum(1)
    after = _counts(sc)
    if taken:
        assert np.all(blobs >= 2)
        err = np.linalg.norm(p.pos[3:15] - sc.face[3:15, M], axis=1)
        assert np.all(err < offset + 0.3), err
        assert sum(after) > sum(before)
    else:
        assert not np.any(blobs >= 2)
        assert after == before


@pytest.mark.parametrize("learned", [True, False])
def test_the_found_dots_follow_the_learned_centre_property(quiet, monkeypatch, learned):
    """Blob Parameters > Learned Centre Correction reaches the search: its dots are measured as the detections were."""
    import carapost.core.tracking.missing_views as mv

    asked = []
    real = mv.find_in_crops

    def spy(images, uv, src, white, learned_centres=True):
        asked.append(learned_centres)
        return real(images, uv, src, white, learned_centres)
    monkeypatch.setattr(mv, "find_in_crops", spy)
    sc = _undetected(quiet)
    sc.project.properties.set("blob.learned_centres", learned)
    track(sc.project, 0, 1, end_frame=8, images=rendered(sc, lambda s, f: (M,) if 3 <= f < 15 else ())).do(sc.project)
    assert asked and set(asked) == {learned}
    p = marker_point(sc, M)
    assert np.all((p.src[3:9] == SRC_DETECTION).sum(1) >= 2)


def test_a_cancelled_run_keeps_the_dots_of_the_frames_done_and_undoes_them(quiet):
    """Cancelled on frame 8: the dots found on frames 3-8 are in the one undoable step, none after, and undo
    gives the project back as it was (its digest)."""
    from carapost.core.progress import Progress

    sc = _undetected(quiet)
    pr = sc.project
    stack = UndoStack(pr)
    d0 = pr.digest()
    before = [[pr.detections[s].count(f) for f in range(20)] for s in range(4)]
    prog = Progress()
    prog._callback = lambda done, total, msg: prog.cancel() if done >= 8 else None
    cmd = track(pr, 0, 1, end_frame=19, images=rendered(sc, lambda s, f: (M,) if 3 <= f < 15 else ()), progress=prog)
    assert pr.digest() == d0 and cmd.cancelled and cmd.report["frames"] == 8
    stack.push(cmd)
    added = [[pr.detections[s].count(f) - before[s][f] for f in range(20)] for s in range(4)]
    per_frame = np.sum(added, axis=0)
    assert np.all(per_frame[3:9] >= 2) and not np.any(per_frame[9:])
    assert cmd.report["found_dots"] == int(per_frame.sum())
    stack.undo()
    assert pr.digest() == d0
    assert [[pr.detections[s].count(f) for f in range(20)] for s in range(4)] == before
