"""The neighbours' prediction of a point lost while the jaw turns (issue 7, session 12).

A point's prediction is its neighbours' positions plus the offsets recorded
while it was last seen.  A jaw opening is a turn about the hinge, so an offset
from a chin marker to a lower lip, recorded with the mouth closed, points the
wrong way once the jaw has turned: the lip was predicted millimetres off (17 mm
for the white 35-marker take's Lip_Lower_C).  Each stale offset is now turned by
its neighbour's neighbourhood's rotation since it was recorded, and on a sparse
set a lower lip also hears the chin markers that count it among their nearest.
"""
import numpy as np

from carapost.core.tracking import elastic


def rotation(axis, deg):
    """Rotation matrix about the unit vector ``axis`` by ``deg`` degrees (Rodrigues)."""
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    t = np.radians(deg)
    return np.eye(3) + np.sin(t) * K + (1 - np.cos(t)) * K @ K


def face():
    """A mouth: a lower lip, six upper-lip and nose markers above it, and six chin markers below it (mm).

    The lower lip's six nearest markers are the upper ones, while the three upper chin
    markers count the lower lip among their six nearest.
    """
    lip = np.array([[0.0, 0, 2]])
    upper = np.array([[-7.0, -3, 0], [-3.5, -4, 1], [0, -4.5, 1.5], [3.5, -4, 1], [7, -3, 0], [0, -9, 2]])
    chin = np.array([[-8.0, 10, 0], [0, 10, 1], [8, 10, 0], [-6, 20, -2], [0, 21, -1], [6, 20, -2]])
    return np.concatenate([lip, upper, chin])


HINGE = np.array([0.0, -20.0, -80.0])     # the jaw turns about an axis 80 mm behind the mouth
AXIS = np.array([1.0, 0.0, 0.0])
JAW = [0, 7, 8, 9, 10, 11, 12]           # the lower lip and the chin move with the jaw


def opened(X, deg):
    """``X`` with the jaw markers turned ``deg`` degrees about the hinge."""
    Y = X.copy()
    Y[JAW] = (Y[JAW] - HINGE) @ rotation(AXIS, deg).T + HINGE
    return Y


def test_mutual_neighbours_link_the_lower_lip_to_the_chin():
    X = face()
    plain = elastic.neighbours(X)
    both = elastic.neighbours(X, mutual=2)
    assert set(plain[0]) == set(range(1, 7))                      # six nearest: the upper markers
    assert all(0 in plain[j] for j in (7, 8, 9))                  # but the chin counts the lip
    assert both.shape == (len(X), 8)
    assert list(both[:, :6].ravel()) == list(plain.ravel())       # the nearest six come first, unchanged
    assert 8 in both[0, 6:] and set(both[0, 6:]) < {7, 8, 9}      # the nearest chin marker, and one more
    # No point is listed twice, and padding stays -1 where nothing links back.
    for row in both:
        used = row[row >= 0]
        assert len(set(used)) == len(used)


def test_a_neighbourhood_rotation_is_recovered_and_held_within_its_step():
    X = face()
    nb = elastic.neighbours(X, mutual=2)
    # Weights as the offsets' steadiness gives them: a jaw marker hears the jaw, the rest the rest.
    jaw = np.isin(np.arange(len(X)), JAW)
    w = np.where(jaw[:, None] == jaw[np.maximum(nb, 0)], 1.0, 1e-9)
    R = np.tile(np.eye(3), (len(X), 1, 1))
    seen = np.ones(len(X), bool)
    for deg in (4.0, 8.0, 12.0):                                  # 4 degrees a frame
        R = elastic.local_rotations(X, opened(X, deg), seen, nb, w, R)
    turned = rotation(AXIS, 12.0)
    assert np.allclose(R[8], turned, atol=1e-9)                   # a chin marker: its neighbourhood turned
    assert np.allclose(R[3], np.eye(3), atol=1e-9)                # an upper-lip marker's did not
    # A jump beyond ROTATION_STEP_DEG in one frame is a wrong neighbour, not the face: the last is kept.
    again = elastic.local_rotations(X, opened(X, 12.0 + 2 * elastic.ROTATION_STEP_DEG), seen, nb, w, R)
    assert np.array_equal(again[8], R[8])
    # Too few measured neighbours: the last is kept too.
    few = seen.copy()
    few[nb[8][1:]] = False
    kept = elastic.local_rotations(X, opened(X, 16.0), few, nb, w, R)
    assert np.array_equal(kept[8], R[8])


def test_only_stale_offsets_are_turned():
    X = face()
    nb = elastic.neighbours(X, mutual=2)
    off = np.random.default_rng(0).normal(size=nb.shape + (3,))
    R_at = np.tile(np.eye(3), nb.shape + (1, 1))
    R_now = np.tile(rotation(AXIS, 20.0), (len(X), 1, 1))
    fresh = np.zeros(nb.shape, bool)
    fresh[3] = True
    out = elastic.rotated_offsets(off, nb, R_now, R_at, fresh)
    assert np.array_equal(out[3], off[3])
    k = nb[5] >= 0
    assert np.allclose(out[5][k], off[5][k] @ rotation(AXIS, 20.0).T)
    assert np.array_equal(out[5][~k], off[5][~k])


def test_a_lower_lip_lost_while_the_jaw_opens_follows_the_chin():
    """Seen while the jaw turns 4 degrees, lost for 8 degrees more (its chin 14 mm lower): within a millimetre."""
    X = face()
    nb = elastic.neighbours(X, mutual=elastic.MUTUAL)
    off = np.full(nb.shape + (3,), np.nan)
    motion = np.zeros(nb.shape + (2,))
    R = np.tile(np.eye(3), (len(X), 1, 1))
    R_at = np.tile(np.eye(3), nb.shape + (1, 1))
    seen = np.ones(len(X), bool)
    elastic.update_offsets(off, nb, X, seen, motion)
    fresh = np.ones(nb.shape, bool)
    for deg in range(1, 13):
        Xf = opened(X, float(deg))
        if deg > 4:
            seen[0] = False                                       # the lip is lost from 5 degrees on
        elastic.update_offsets(off, nb, Xf, seen, motion)
        w = elastic.weights(motion)
        R = elastic.local_rotations(X, Xf, seen, nb, w, R)
        fresh = seen[:, None] & seen[np.maximum(nb, 0)] & (nb >= 0)
        R_at[fresh] = R[np.maximum(nb, 0)][fresh]
    now = opened(X, 12.0)
    turned = elastic.rotated_offsets(off, nb, R, R_at, fresh)
    pred, _ = elastic.predict(now, seen, nb, turned, weight=w)
    shifted, _ = elastic.predict(now, seen, nb, off, weight=w)
    nearest, _ = elastic.predict(now, seen, nb[:, :6], off[:, :6], weight=w[:, :6])
    err = [np.linalg.norm(p[0] - now[0]) for p in (nearest, shifted, pred)]
    assert np.linalg.norm(now[0] - X[0]) > 12.0                  # the lip moved that far
    assert err[0] > 3.0                                           # the six nearest: held by the upper lip
    assert err[1] > 1.0                                           # the chin's offsets, not turned
    assert err[2] < 0.1
