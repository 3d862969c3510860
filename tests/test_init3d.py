"""Initialize 3D from seeds on synthetic takes (35 and 150 markers) and the headless pipeline."""
import numpy as np
import pytest

from carapost.core.calib.init3d import initialize_3d
from carapost.core.calib.synthetic import make_scene
from carapost.core.commands import UndoStack
from carapost.core.errors import CaraError
from carapost.core.pipeline import process_to_init3d
from support import remove_marker_detection


def evaluate(sc, pr, frame=0):
    """(fraction of 2+-view markers initialised, mismatched points, 3D RMS mm, camera centre error mm)."""
    F = sc.face_det[frame]
    inv = [{int(d): m for m, d in enumerate(F[s]) if d >= 0} for s in range(4)]
    vis2 = np.flatnonzero((F >= 0).sum(0) >= 2)
    got, mism, err = set(), 0, []
    for p in pr.face_points():
        ms = {inv[s].get(int(p.det[frame, s]), -1) for s in range(4) if p.src[frame, s] == 1}
        if len(ms) != 1 or -1 in ms:
            mism += 1
            continue
        m = ms.pop()
        got.add(m)
        err.append(np.linalg.norm(p.pos[frame] - sc.face[frame, m]))
    ce = max(np.linalg.norm(a.position - b.position) for a, b in zip(pr.rig.cameras_at(frame), sc.cameras[frame]))
    return len(got & set(vis2)) / len(vis2), mism, float(np.sqrt(np.mean(np.square(err)))), ce


@pytest.mark.parametrize("markers,depth,seed", [(35, 60.0, 0), (150, 16.0, 0), (150, 16.0, 3)])
def test_pipeline_initialises_face(markers, depth, seed):
    sc = make_scene(markers, seed=seed)
    pr = sc.project
    pr.properties.set("initialize_3d.max_allowed_depth", depth)
    stack = UndoStack(pr)
    d0 = pr.digest()
    lines = []
    cmds = process_to_init3d(pr, sc.seeds(n_face=8, n_brim=5, seed=seed), log=lines.append, stack=stack)
    assert len(cmds) == 5 and len(lines) == 5
    frac, mism, rms, ce = evaluate(sc, pr)
    assert frac >= 0.97 and mism == 0 and rms <= 0.08 and ce <= 0.3, (frac, mism, rms, ce)
    while stack.can_undo():
        stack.undo()
    assert pr.digest() == d0


def test_initialize_needs_seeds():
    sc = make_scene(35, seed=2)
    with pytest.raises(CaraError, match="seed points"):
        initialize_3d(sc.project, 0)
    sc.project.rig = None
    with pytest.raises(CaraError, match="intrinsics"):
        initialize_3d(sc.project, 0)


def test_rendered_sample_lips_are_not_cross_matched(tmp_path):
    """On a rendered sample take the lip markers sit one above the other, on the same epipolar lines.

    A wrong upper/lower lip match lands near the points grown so far while the right one is
    still beyond Max Allowed Depth; it used to be accepted as "unambiguous" (the right one was
    not yet a candidate), leaving 4-5 mismatched points on seed 0.
    """
    import json

    from carapost.core.blob_ops import detect_blobs_range
    from carapost.core.points import FACE, SRC_DETECTION, ST_NONE
    from carapost.io.brim_svg import read_brim_svg
    from carapost.io.imports import import_xcp
    from carapost.io.take import project_from_input
    from carapost.sample import write_sample

    write_sample(tmp_path, markers=35, frames=1, seed=0, workers=1)
    truth = np.load(tmp_path / "truth.npz")
    pr = project_from_input(str(tmp_path / "Sample_0.pico"), None)
    import_xcp(pr, tmp_path / "calibration.xcp", lambda s: None).do(pr)
    detect_blobs_range(pr, 0, 0, workers=1).do(pr)
    seeds = json.loads((tmp_path / "seeds.json").read_text())
    process_to_init3d(pr, seeds, read_brim_svg(tmp_path / "brim.svg"), log=lambda s: None)
    uv, vis = truth["uv"][0], truth["visible"][0]
    owner = []
    for s in range(4):
        rec = pr.detections[s].frame(0)
        d = np.linalg.norm(np.column_stack([rec["x"], rec["y"]])[:, None] - uv[s][None], axis=2)
        d = np.where(vis[s][None], d, np.inf)
        owner.append(np.where(d.min(1) < 1.5, d.argmin(1), -1))
    markers_of = [{int(owner[s][q.det[0, s]]) for s in range(4) if q.src[0, s] == SRC_DETECTION}
                  for q in pr.points.values() if q.kind == FACE and q.status[0] != ST_NONE]
    crossed = [m for m in markers_of if len(m - {-1}) > 1]
    assert not crossed
    lips = {i for i, lab in enumerate(truth["labels"]) if str(lab).startswith("Lip_")}
    assert lips <= set().union(*markers_of)
    for s in range(4):
        assert np.linalg.norm(np.asarray(pr.rig.camera(s, 0).position) - truth["cam_t"][0, s]) < 0.3


def test_a_view_pulled_off_its_dot_is_left_out():
    """Leave-one-out: one view 1 px off (a detection pulled by a shadow beside the dot) is detached;
    views within blob noise, and 2-view points, are kept."""
    from carapost.core.calib.init3d import odd_views_out

    sc = make_scene(35, seed=2)
    cams = sc.cameras[0]
    rng = np.random.default_rng(0)
    X = sc.face[0][:20]
    uv = np.stack([c.project(X) for c in cams], axis=1) + rng.normal(0, 0.05, (20, 4, 2))
    uv[5, 2] += (0.8, -0.6)                 # 1 px off in camera 2
    uv[9, 0] += (1.0, 0.0)                  # 1 px off, but the point has only 2 views
    uv[9, 1:3] = np.nan
    bad = odd_views_out(cams, uv)
    assert bad[5, 2] and bad.sum() == 1, np.argwhere(bad)


def test_growth_goes_on_past_sparse_markers_with_the_other_caddys_support():
    """Markers sparser than Max Allowed Depth (an eye socket or a nostril on a 100-marker face with the
    dense set's 16 mm) stall the growth; matches the other caddy confirms carry it on, and none is wrong."""
    sc = make_scene(35, seed=0)
    pr = sc.project
    pr.properties.set("initialize_3d.max_allowed_depth", 12.0)
    process_to_init3d(pr, sc.seeds(n_face=8, n_brim=5, seed=0), log=lambda s: None, stack=UndoStack(pr))
    frac, mism, rms, _ce = evaluate(sc, pr)
    assert frac >= 0.97 and mism == 0 and rms <= 0.08, (frac, mism, rms)


def _seen_by_all():
    """A 35-marker scene (seed 1): the scene, its project, frame 0's marker detections, cameras, and the last
    marker every camera sees."""
    sc = make_scene(35, seed=1)
    F = sc.face_det[0]
    return sc, sc.project, F, sc.cameras[0], max(m for m in range(35) if (F[:, m] >= 0).all())


def test_a_caddy_match_pulled_along_its_epipolar_line_is_made_again_across_the_caddies():
    """A nose tip's blob merged with the nostrils' shadow in one camera of a caddy, and not found at all in
    a camera of the other: the caddy's pair still matches (the error runs along its epipolar line) and
    the point lands millimetres deep, where the other caddy sees nothing.  It is made again from the
    good detection and the other caddy's."""
    from carapost.core.camera import epipolar_line

    sc, pr, F, cams, m = _seen_by_all()
    (a, b), (c, _d) = pr.caddies()
    ra = pr.detections[a].frame(0)
    line = np.asarray(epipolar_line(cams[a], cams[b], np.array([ra["x"][F[a, m]], ra["y"][F[a, m]]])), float)
    along = np.array([line[1], -line[0]]) / np.hypot(line[0], line[1])
    rb = pr.detections[b].frame(0).copy()
    rb["x"][F[b, m]] += 6.0 * along[0]           # camera b's blob slides 6 px along camera a's epipolar line
    rb["y"][F[b, m]] += 6.0 * along[1]
    pr.detections[b].set_frame(0, rb)
    rc = pr.detections[c].frame(0).copy()
    rc["x"][F[c, m]] += 400.0                    # and camera c does not find the dot
    pr.detections[c].set_frame(0, rc)
    process_to_init3d(pr, sc.seeds(n_face=8, n_brim=5, seed=1), log=lambda s: None, stack=UndoStack(pr))
    dist = [np.linalg.norm(q.pos[0] - sc.face[0, m]) for q in pr.face_points() if q.status[0]]
    assert min(dist) < 0.3, min(dist)



def test_a_good_caddy_pair_is_not_made_again_with_a_blob_that_puts_it_off_the_face():
    """A cheek dot that only one caddy finds (grazing in the other) is a good pair that the other caddy does
    not see.  A free blob of the other caddy on its epipolar line (a nostril's, on the sample's 156-marker
    white take) matched it unambiguously and the point was made again from that, millimetres under the
    cheek.  A pair is made again only where that brings it nearer the surface of the points around it."""
    from carapost.core.calib.init3d import _surface_distance

    sc, pr, F, cams, m = _seen_by_all()
    (a, b), (c, d) = pr.caddies()
    for s in (c, d):                             # the other caddy does not find the dot
        r = pr.detections[s].frame(0).copy()
        r["x"][F[s, m]] += 400.0
        pr.detections[s].set_frame(0, r)
    # A blob in camera c where camera a's ray runs 8 mm under the marker.
    X = sc.face[0, m]
    ray = (X - cams[a].position) / np.linalg.norm(X - cams[a].position)
    fake = cams[c].project((X + 8.0 * ray)[None])[0]
    r = pr.detections[c].frame(0)
    extra = r[:1].copy()
    extra["x"], extra["y"] = fake
    pr.detections[c].set_frame(0, np.concatenate([r, extra]))
    others = np.delete(sc.face[0], m, axis=0)
    assert _surface_distance(X + 8.0 * ray, others) > _surface_distance(X, others) + 2.0
    process_to_init3d(pr, sc.seeds(n_face=8, n_brim=5, seed=1), log=lambda s: None, stack=UndoStack(pr))
    near = [q for q in pr.face_points() if q.status[0] and np.linalg.norm(q.pos[0] - X) < 0.3]
    assert len(near) == 1 and near[0].det[0, a] == F[a, m] and near[0].det[0, b] == F[b, m]
    assert not any(q.status[0] and q.det[0, c] == len(r) for q in pr.face_points())


# ---------------------------------------------------------------- blobs that are not a marker's centre


def _seed_markers(sc, seeds):
    """Markers the seed clicks were made on."""
    out = set()
    for s_ in seeds["face"]:
        cam, (x, y) = next(iter(s_["uv"].items()))
        rec = sc.project.detections[int(cam)].frame(0)
        i = int(np.argmin(np.hypot(rec["x"] - x, rec["y"] - y)))
        out.add(int(np.flatnonzero(sc.face_det[0, int(cam)] == i)[0]))
    return out


def _set_blob(sc, s, m, uv=None, major=None):
    """Move marker ``m``'s detection in camera ``s`` to ``uv`` and/or give it another major axis (px)."""
    table = sc.project.detections[s]
    rec = table.frame(0).copy()
    i = sc.face_det[0, s, m]
    if uv is not None:
        rec["x"][i], rec["y"][i] = uv
    if major is not None:
        rec["major"][i] = major
    table.set_frame(0, rec)


def _initialise(sc, depth=None, seed=0):
    pr = sc.project
    if depth is not None:
        pr.properties.set("initialize_3d.max_allowed_depth", depth)
    process_to_init3d(pr, sc.seeds(n_face=8, n_brim=5, seed=seed), log=lambda s: None, stack=UndoStack(pr))
    return pr


def _point_of(sc, pr, m):
    """The face point holding any of marker ``m``'s detections: (its views, its 3D error mm), or None."""
    for q in pr.face_points():
        views = [s for s in range(4) if q.src[0, s] == 1 and q.det[0, s] == sc.face_det[0, s, m] >= 0]
        if views and q.status[0]:
            return [s for s in range(4) if q.src[0, s] == 1], float(np.linalg.norm(q.pos[0] - sc.face[0, m]))
    return None


def _free_marker(sc):
    """A marker seen by every camera that no seed of :func:`_initialise` is clicked on."""
    taken = _seed_markers(sc, sc.seeds(n_face=8, n_brim=5, seed=0))
    return next(m for m in np.flatnonzero(np.all(sc.face_det[0] >= 0, axis=0)) if m not in taken)


def _pull(sc, m, cams, offset, major):
    """Marker ``m``'s blobs in ``cams``: where a point ``offset`` (mm) from it projects, ``major`` px long
    (blobs merged with something beside the dot, pulled the same way)."""
    wrong = sc.face[0, m] + np.asarray(offset, float)
    for s in cams:
        _set_blob(sc, s, m, uv=sc.cameras[0][s].project(wrong[None])[0], major=major)


def test_blobs_merged_with_a_shadow_in_both_caddies_give_way_to_the_clean_views():
    """A nose tip's dot merged with the nostrils' shadow in one camera of each caddy: two blobs 3.5 times a
    marker's size, 6 px off, that agree with each other (2 mm off in 3D).  They used to pull the point
    off and the clean views were detached instead; the merged blobs are left out, the point is made from
    the clean views."""
    sc = make_scene(35, seed=2)
    m = _free_marker(sc)
    _pull(sc, m, (0, 2), (0.0, 2.0, 0.0), 30.0)
    views, err = _point_of(sc, _initialise(sc), m)
    assert views == [1, 3] and err < 0.1, (views, err)


def test_a_two_view_point_on_two_enlarged_blobs_is_not_made():
    """A faint brow dot merged with the brow hair in the only two cameras that find it: both blobs half again
    as large as a marker, both pulled.  Nothing checks two views against each other, so the point is
    not made (it was, 0.6 mm off)."""
    sc = make_scene(35, seed=2)
    m = _free_marker(sc)
    for s in (1, 3):
        remove_marker_detection(sc, 0, s, m)
    _pull(sc, m, (0, 2), (0.0, 0.0, 0.6), 15.0)
    assert _point_of(sc, _initialise(sc), m) is None
    # The same pair with blobs of a marker's size is a marker seen by one camera of each caddy: it is made.
    sc = make_scene(35, seed=2)
    for s in (1, 3):
        remove_marker_detection(sc, 0, s, m)
    views, err = _point_of(sc, _initialise(sc), m)
    assert views == [0, 2] and err < 0.1, (views, err)


def test_markers_seen_by_one_camera_of_each_caddy_are_made_across_the_caddies():
    """No caddy sees these markers whole (a brow dot lost in the hair of the other two views): they are
    matched between one camera of each caddy, accurately and without a mismatch."""
    sc = make_scene(35, seed=0)
    taken = _seed_markers(sc, sc.seeds(n_face=8, n_brim=5, seed=0))
    both = [m for m in np.flatnonzero(np.all(sc.face_det[0] >= 0, axis=0)) if m not in taken]
    pairs = {both[0]: (0, 2), both[3]: (1, 3), both[6]: (0, 3), both[9]: (1, 2)}
    for m, keep in pairs.items():
        for s in set(range(4)) - set(keep):
            remove_marker_detection(sc, 0, s, m)
    pr = _initialise(sc)
    for m, keep in pairs.items():
        got = _point_of(sc, pr, m)
        assert got is not None and got[0] == sorted(keep) and got[1] < 0.1, (m, got)
    assert evaluate(sc, pr)[1] == 0


def test_a_cross_caddy_match_reaches_past_max_allowed_depth_when_it_has_no_rival():
    """A nose tip farther from every other marker than Max Allowed Depth (a 100-marker face with the dense
    set's 16 mm), seen by one camera of each caddy: made once growth within the depth has stopped,
    its two detections being each other's only candidates."""
    from scipy.spatial import cKDTree

    sc = make_scene(35, seed=0)
    taken = _seed_markers(sc, sc.seeds(n_face=8, n_brim=5, seed=0))
    gap = cKDTree(sc.face[0]).query(sc.face[0], k=2)[0][:, 1]
    m = next(m for m in np.argsort(-gap) if m not in taken and np.all(sc.face_det[0, :, m] >= 0))
    depth = 0.8 * gap[m]
    for s in (0, 2):
        remove_marker_detection(sc, 0, s, m)
    views, err = _point_of(sc, _initialise(sc, depth=depth), m)
    assert views == [1, 3] and err < 0.1, (views, err)


def test_a_caddy_pulled_off_its_dot_gives_way_to_the_caddy_with_the_smaller_blobs():
    """A dot beside a brow merged with it in both cameras of one caddy: both blobs larger, both pulled the
    same way, so they agree with each other and leave-one-out cannot say which views are wrong.  Every
    view pair across the caddies misses its epipolar line; the caddy with the larger blobs is detached."""
    from carapost.core.camera import symmetric_epipolar_distance

    sc = make_scene(35, seed=2)
    m = _free_marker(sc)
    cams = sc.cameras[0]
    _pull(sc, m, (2, 3), 0.5 * cams[2].rotation[1], 13.0)      # down in camera 2's image
    rec = [sc.project.detections[s].frame(0)[sc.face_det[0, s, m]] for s in range(4)]
    uv = [np.array([r["x"], r["y"]], float) for r in rec]
    assert min(symmetric_epipolar_distance(cams[a], uv[a], cams[b], uv[b]) for a in (0, 1) for b in (2, 3)) > 0.6
    views, err = _point_of(sc, _initialise(sc), m)
    assert views == [0, 1] and err < 0.1, (views, err)


def test_unsupported_candidates_are_told_apart_by_their_own_epipolar_distance():
    """Two markers one above the other that only one caddy sees: neither candidate pair of a detection has
    the other caddy's support.  The penalty for that must not make 0.01 px and 3.9 px look alike."""
    from carapost.core.calib.matching import unambiguous

    ia, ib = np.array([0, 0, 1, 1]), np.array([0, 1, 0, 1])
    d = np.array([0.01, 3.95, 3.89, 0.03])
    assert unambiguous(ia, ib, d, np.full(4, 2.0)).tolist() == [True, False, False, True]
    # Between a supported pair and an unsupported one the penalty still counts: the supported pair wins
    # over one a little closer to its line, not over one much closer.
    pen = np.array([0.0, 2.0, 2.0, 0.0])
    assert unambiguous(ia, ib, np.array([0.4, 0.3, 0.3, 0.4]), pen).tolist() == [True, False, False, True]
    assert unambiguous(ia, ib, np.array([0.6, 0.05, 0.05, 0.6]), pen).tolist() == [False, False, False, False]


def test_two_markers_on_one_epipolar_line_that_only_one_caddy_sees_are_both_made():
    """Two cheek markers one above the other seen by one caddy only (150 markers seed 4): the right
    pairs lie 0.01 px from their epipolar lines, the crossed ones 4 px; with no support from the other
    caddy for any of them, both right pairs are still the clear choice."""
    from carapost.core.camera import symmetric_epipolar_distance
    from carapost.core.detections import make_detections

    sc = make_scene(35, seed=2)
    m = _free_marker(sc)
    cams = sc.cameras[0]
    X = sc.face[0, m]
    base = cams[3].position - cams[2].position
    across = np.cross(base, X - cams[2].position)
    X2 = X + 7.0 * base / np.linalg.norm(base) + 1.2 * across / np.linalg.norm(across)
    for s in (0, 1):
        remove_marker_detection(sc, 0, s, m)
    uv = {s: cams[s].project(np.array([X, X2]))[:, :] for s in (2, 3)}
    crossed = symmetric_epipolar_distance(cams[2], uv[2][0], cams[3], uv[3][1])
    assert 2.5 < crossed < 6.0 and symmetric_epipolar_distance(cams[2], uv[2][1], cams[3], uv[3][0]) > 2.5
    for s in (2, 3):
        rec = sc.project.detections[s].frame(0)
        sc.project.detections[s].set_frame(0, np.concatenate([rec, make_detections([uv[s][1, 0]], [uv[s][1, 1]],
                                                                                    [8.5], [6.0], [0.0], [1.0])]))
    pr = _initialise(sc)
    views, err = _point_of(sc, pr, m)
    assert views == [2, 3] and err < 0.3, (views, err)
    second = [q for q in pr.face_points() if q.status[0] and np.linalg.norm(q.pos[0] - X2) < 0.5]
    assert len(second) == 1


def test_the_two_views_of_one_caddy_do_not_outvote_a_third_view():
    """A brow dot's blobs pulled the same way in both cameras of one caddy (1 mm along camera 2's ray: camera 2
    does not see the pull, camera 3 sees it along the caddy's epipolar line) fit each other perfectly; the
    clean view of camera 0 is not detached for disagreeing with them."""
    from carapost.core.calib.init3d import odd_views_out

    sc = make_scene(35, seed=2)
    cams = sc.cameras[0]
    X = sc.face[0][:20]
    ray = X - cams[2].position
    pulled = X + ray / np.linalg.norm(ray, axis=1, keepdims=True)
    uv = np.stack([c.project(X) for c in cams], axis=1)
    uv[:, 2] = cams[2].project(pulled)
    uv[:, 3] = cams[3].project(pulled)
    uv[:, 1] = np.nan
    assert odd_views_out(cams, uv)[:, 0].all()          # judged by the pair alone, camera 0 was always out
    assert not odd_views_out(cams, uv, sc.project.caddies())[:, 0].any()


def test_of_two_views_either_of_which_explains_the_third_the_larger_blob_goes():
    """Three views, one pulled 1 px off its dot (a brow dot fused with the brow): leaving out the pulled view
    or the clean view of the same caddy leaves two views of both caddies that fit each other, so the
    reprojection errors alone pick either.  The pulled blob measures larger (mm at its depth): it goes."""
    from carapost.core.calib.init3d import odd_views_out

    sc = make_scene(35, seed=2)
    cams = sc.cameras[0]
    caddies = sc.project.caddies()
    X = sc.face[0][:20]
    uv = np.stack([c.project(X) for c in cams], axis=1)
    a, b = caddies[0]
    other = caddies[1][0]
    uv[:, caddies[1][1]] = np.nan
    # Camera a's blob pulled 1 px along its epipolar line with the other caddy's camera (the dot moved
    # along that camera's ray): that pair fits itself, and the clean view of a's caddy is as far off.
    ray = X - cams[other].position
    ray /= np.linalg.norm(ray, axis=1, keepdims=True)
    step = np.linalg.norm(cams[a].project(X + ray) - uv[:, a], axis=1)
    uv[:, a] = cams[a].project(X + ray / step[:, None])
    sizes = np.full(uv.shape[:2], 2.0)
    sizes[:, a] = 2.6
    plain = odd_views_out(cams, uv, caddies)
    by_size = odd_views_out(cams, uv, caddies, sizes)
    assert plain[:, b].sum() >= 5                  # errors alone often drop the clean view
    assert by_size[:, a].all() and not by_size[:, [b, other]].any()
    # Blobs of about one size: the errors decide, as before.
    sizes[:, a] = 2.1
    assert (odd_views_out(cams, uv, caddies, sizes) == plain).all()


def _one_caddy_points(depth_mm):
    """25 markers of a scene, each a point of caddy 1's pair only, put ``depth_mm`` off along that caddy's line
    of sight; returns the cameras, caddies, every camera's blobs (the markers' projections), the points and
    the lines of sight."""
    sc = make_scene(35, seed=2)
    cams = sc.cameras[0]
    caddies = sc.project.caddies()
    X = sc.face[0][:25]
    xy = [c.project(X) for c in cams]
    centre = np.mean([cams[s].position for s in caddies[1]], axis=0)
    sight = (X - centre) / np.linalg.norm(X - centre, axis=1, keepdims=True)
    Xoff = X + depth_mm * sight
    pts = []
    for k in range(len(X)):
        uv = np.full((4, 2), np.nan)
        det = np.full(4, -1)
        for s in caddies[1]:
            uv[s], det[s] = xy[s][k], k
        pts.append({"id": None, "det": det, "uv": uv, "X": Xoff[k]})
    return cams, caddies, xy, pts, sight


def _camera_0_views_found(cams, caddies, xy, pts):
    """Attach along depth; (right, wrong) camera-0 views of the points."""
    from carapost.core.calib.depth_attach import attach_along_depth

    blocked = [np.zeros(len(v), bool) for v in xy]
    attach_along_depth(pts, cams, xy, blocked, caddies)
    got = [d["det"][0] for d in pts]
    return sum(g == k for k, g in enumerate(got)), sum(g >= 0 and g != k for k, g in enumerate(got))


def test_a_one_caddy_point_finds_the_other_caddys_view_along_its_depth():
    """A point of one caddy's pair, 1.5 mm off along its line of sight (half-pixel errors along that pair's
    short baseline do that), projects pixels away from its blob in the other caddy's cameras: too far for the
    attach gate, but on the projection of its depth range, where that blob is the only detection."""
    from carapost.core.calib.init3d import ATTACH_GATE_PX

    cams, caddies, xy, pts, _ = _one_caddy_points(1.5)
    miss = np.linalg.norm(cams[0].project(np.array([d["X"] for d in pts])) - xy[0], axis=1)
    assert np.median(miss) > ATTACH_GATE_PX           # the plain attach gate cannot take them
    right, wrong = _camera_0_views_found(cams, caddies, xy, pts)
    assert wrong == 0 and right >= 20, (right, wrong)


def test_a_one_caddy_point_on_a_grown_blob_finds_the_other_caddys_view_along_its_depth():
    """A brow dot's blob grown into the hair in one camera of a caddy, 2.7 px off, put the pair's point
    3.9 mm deep, and the other caddy's blob lay 1.6 px beside the projection of that depth range (the
    sample's 156 black markers, seed 0, frame 299; 1.74 px since session 34, whose profile step moved that
    clean blob 0.14 px along its axis): the range reaches 5 mm and takes blobs within 2 px."""
    cams, caddies, xy, pts, sight = _one_caddy_points(4.0)
    Xoff = np.array([d["X"] for d in pts])
    # Camera 0's blobs 1.8 px beside the projection of each point's line of sight.
    a, b = cams[0].project(Xoff - sight), cams[0].project(Xoff + sight)
    across = np.stack([b[:, 1] - a[:, 1], a[:, 0] - b[:, 0]], axis=1)
    xy[0] = xy[0] + 1.8 * across / np.linalg.norm(across, axis=1, keepdims=True)
    right, wrong = _camera_0_views_found(cams, caddies, xy, pts)
    assert wrong == 0 and right >= 20, (right, wrong)


def test_the_largest_of_three_blobs_pulled_by_brow_hair_is_left_out():
    """A brow dot merged with the hair in three cameras of four (35 markers seed 1, last frame): blobs 1.2, 1.2
    and 1.7 times a marker, centres 1-1.9 px off, close enough to one another that no view is odd one
    out, and the point sat 1.1 mm off (farther than the benchmark's 1 mm, so the marker counted as not
    initialised).  The largest blob goes; the point is made from the other three views."""
    from carapost.core.calib.blob_size import pulled_views

    sc = make_scene(35, seed=0)
    m = _free_marker(sc)
    typical = np.median(np.concatenate([sc.project.detections[s].frame(0)["major"] for s in range(4)]))
    off = {0: (-1.2, 0.0), 1: (-1.07, -0.11), 2: (1.88, 0.15), 3: (0.59, 0.24)}      # px, as rendered
    size = {0: 1.24, 1: 1.22, 2: 1.69, 3: 1.0}
    for s in range(4):
        _set_blob(sc, s, m, uv=sc.cameras[0][s].project(sc.face[0, m][None])[0] + off[s], major=typical * size[s])
    views, err = _point_of(sc, _initialise(sc), m)
    assert views == [0, 1, 3] and err < 0.8, (views, err)          # all four views: 0.96 mm
    # Only where three views on both caddies are left, and only a blob clearly the largest.
    caddies = sc.project.caddies()
    ratio = np.array([[1.51, 0.93, np.nan, 2.0],        # the rest: one caddy's pair
                      [np.nan, 1.06, 0.98, 1.73],       # the rest: a pair across the caddies
                      [1.17, 1.5, 1.36, 1.28],          # not clearly the largest
                      [1.2, 1.1, 1.3, 1.4],             # not enlarged
                      [1.03, 1.66, 1.38, 1.43]])        # Brow_R_5, 156 markers, frame 0
    assert pulled_views(ratio, caddies, 1.15).tolist() == [[False] * 4] * 4 + [[False, True, False, False]]
