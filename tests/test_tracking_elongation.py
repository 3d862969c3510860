"""Oblique dots' views weighted less along their major axis in triangulation (issue 7)."""
import numpy as np

from carapost.core.camera import Camera
from carapost.core.detections import DET_DTYPE
from carapost.core.tracking import engine
from carapost.core.tracking.geometry import RigState, held_out_errors, triangulate


def _rig():
    """Four cameras 150 mm in front of the origin, spread as on a head rig."""
    pos = [(-60.0, 20.0), (-20.0, -20.0), (20.0, -20.0), (60.0, 20.0)]
    return RigState([Camera(focal_length=1000.0, position=np.array([x, y, -150.0])) for x, y in pos])


def test_a_view_off_along_its_major_axis_counts_less_there():
    """One view 1.5 px off along its dot's major axis: weighted k along it, the point moves ~k as far."""
    rig = _rig()
    X0 = np.array([[1.0, 2.0, 3.0]])
    uv = rig.project(X0)[0][None].copy()                         # (1, S, 2): exact views
    t = np.radians(35.0)
    along = np.array([np.cos(t), np.sin(t)])
    uv[0, 1] += 1.5 * along
    valid = np.ones((1, 4), bool)
    plain = triangulate(rig, uv, valid)
    el = np.zeros((1, 4, 3))
    el[..., 2] = 1.0
    np.testing.assert_array_equal(triangulate(rig, uv, valid, elong=el), plain)      # k = 1: round, the same
    el[0, 1] = [np.cos(t), np.sin(t), 0.2]
    tilted = triangulate(rig, uv, valid, elong=el)
    e_plain, e_tilted = (float(np.linalg.norm(x[0] - X0[0])) for x in (plain, tilted))
    assert e_plain > 0.05
    assert e_tilted < 0.35 * e_plain
    el[0, 1] = [-np.sin(t), np.cos(t), 0.2]                      # told the error is across: no help
    across = triangulate(rig, uv, valid, elong=el)
    assert float(np.linalg.norm(across[0] - X0[0])) > 0.9 * e_plain
    err, _ = held_out_errors(rig, uv, valid, elong=el)
    err0, _ = held_out_errors(rig, uv, valid)
    assert err.shape == err0.shape == (1, 4) and np.all(err >= 0)


def test_elongation_of_detections_follows_their_axes():
    rec = np.zeros(3, DET_DTYPE)
    rec["major"], rec["minor"], rec["angle"] = [10.0, 10.0, 10.0], [9.0, 7.0, 4.0], [0.0, 30.0, -60.0]
    el = engine.elongation(rec)
    np.testing.assert_allclose(el[:, 2], [1.0, 1.0, 1.0 / (1.0 + engine.ELONG_SLOPE * 0.3 ** 2)])
    np.testing.assert_allclose(el[1, :2], [np.cos(np.radians(30.0)), np.sin(np.radians(30.0))])
    np.testing.assert_allclose(el[2, :2], [0.5, -np.sqrt(3) / 2])
