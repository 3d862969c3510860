"""The neighbours' links both ways and the depth averaged with the neighbours' prediction (issue 7)."""
import numpy as np

from carapost.core.tracking import elastic
from carapost.core.tracking.engine import DEPTH_PX, fuse_depth


def test_links_both_ways_add_the_points_that_count_a_point_among_their_nearest():
    """A lower lip's six nearest are lips; the chin below counts the lip among its own and is added."""
    lips = np.array([[x, 0.0, 0.0] for x in (-15, -10, -5, 0, 5, 10, 15)])      # a row of seven, 5 mm apart
    chin = np.array([[0.0, -16.0, 0.0]])                                        # 16 mm below the middle one
    X = np.concatenate([lips, chin])
    plain = elastic.neighbours(X)
    links = elastic.neighbours(X, mutual=2)
    assert plain.shape == (8, 6) and links.shape == (8, 8)
    np.testing.assert_array_equal(links[:, :6], plain)
    assert 7 not in plain[3] and 3 in plain[7]          # the chin counts the middle lip, not the reverse
    assert links[3, 6] == 7                              # ... so the middle lip hears the chin too
    for i in range(8):
        extra = [j for j in links[i, 6:] if j >= 0]
        for j in extra:                                  # every added link is one made the other way
            assert i in plain[j] and j not in plain[i]
        d = [np.linalg.norm(X[j] - X[i]) for j in extra]
        assert d == sorted(d)                            # nearest first
    assert np.all(elastic.neighbours(X[:1], mutual=2) == -1)


def test_fuse_depth_weighs_the_measured_point_against_the_prediction():
    """A close pair's loose depth moves towards the prediction; what its views fix hardly moves."""
    k = DEPTH_PX                                         # lengths in units of a pixel's worth of depth
    pred = np.zeros((3, 3))
    X = np.array([[1.5, 0.0, 2.0], [1.5, 0.0, 2.0], [1.5, 0.0, 45.0]]) * k
    close = np.diag([100.0, 100.0, 1.0])                 # per px²: depth (z) 10x looser than across
    wide = np.diag([100.0, 100.0, 100.0])
    info = np.stack([close, wide, close])
    rows = np.ones(3, bool)
    sd = k                                               # the prediction as certain as the close pair's depth
    out = fuse_depth(X, info, pred, sd, rows)
    np.testing.assert_allclose(out[0, 2], k)                            # depth: halfway
    np.testing.assert_allclose(out[0, :2], [1.5 * k * 100 / 101, 0.0])  # across: hardly moved
    np.testing.assert_allclose(out[1, 2], 2 * k * 100 / 101)            # a wide view's depth hardly moves
    np.testing.assert_array_equal(out[2], X[2])                        # far off: a mismatch, left alone
    np.testing.assert_array_equal(fuse_depth(X, info, pred, sd, np.zeros(3, bool)), X)
    np.testing.assert_array_equal(fuse_depth(X, info, np.full((3, 3), np.nan), sd, rows), X)


def test_information_of_two_close_cameras_is_loose_along_their_rays():
    from carapost.core.camera import Camera
    from carapost.core.tracking.geometry import RigState, information
    cams = [Camera(focal_length=1000.0, position=np.array([x, 0.0, -150.0])) for x in (-10.0, 10.0, 120.0)]
    rig = RigState(cams)
    X = np.zeros((2, 3))
    valid = np.array([[True, True, False], [True, False, True]])
    info = information(rig, X, valid)
    depth = np.array([0.0, 0.0, 1.0])
    close, wide = (float(depth @ np.linalg.inv(i) @ depth) for i in info)
    across = float(np.array([0.0, 1.0, 0.0]) @ np.linalg.inv(info[0]) @ np.array([0.0, 1.0, 0.0]))
    assert close > 20 * across                           # ~(150 / 10)² along the rays
    assert close > 10 * wide


def test_a_low_scoring_blob_counts_less_in_triangulation():
    """Blob centres of low classifier score land farther from their dots: they weigh less."""
    from carapost.core.camera import Camera
    from carapost.core.points import SRC_DETECTION, SRC_PATCH
    from carapost.core.tracking.engine import PATCH_WEIGHT, blob_weight, confidence
    from carapost.core.tracking.geometry import RigState, triangulate
    w = blob_weight(np.array([1.0, 0.9995, 0.999, 0.99, 0.9, 0.5, np.nan]))
    np.testing.assert_allclose(w[[0, 1, 2, 6]], 1.0)
    assert 1.0 > w[3] > w[4] > w[5] > 0.1
    src = np.array([[SRC_DETECTION, SRC_PATCH]])
    np.testing.assert_allclose(confidence(src, np.array([[0.9, 0.9]])), [[w[4], PATCH_WEIGHT]])
    np.testing.assert_allclose(confidence(src), [[1.0, PATCH_WEIGHT]])

    cams = [Camera(focal_length=1000.0, position=np.array([x, 0.0, -150.0])) for x in (-60.0, 0.0, 60.0)]
    rig = RigState(cams)
    X = np.array([[1.0, 2.0, 3.0]])
    uv = rig.project(X)
    uv[0, 2] += (1.5, 0.0)                               # the third camera's blob 1.5 px off
    valid = np.ones((1, 3), bool)
    blobs = np.full((1, 3), SRC_DETECTION)
    even = triangulate(rig, uv, valid, confidence(blobs, np.array([[1.0, 1.0, 1.0]])))
    weighed = triangulate(rig, uv, valid, confidence(blobs, np.array([[1.0, 1.0, 0.7]])))
    assert np.linalg.norm(weighed - X) < 0.5 * np.linalg.norm(even - X)
