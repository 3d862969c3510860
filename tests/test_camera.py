"""Camera model: radial correction and its inverse, projection, triangulation, epipolar geometry."""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from carapost.core.camera import (
    Camera,
    centroid,
    epipolar_line,
    fundamental_matrix,
    matrix_to_quaternion,
    quaternion_to_matrix,
    reprojection_errors,
    symmetric_epipolar_distance,
    triangulate,
    triangulate_many,
)


def look_at(centre, target=(0.0, 0.0, 0.0), up=(0.0, -1.0, 0.0)):
    """World-to-camera rotation of a camera at ``centre`` looking at ``target`` (y down in the image)."""
    z = np.asarray(target, float) - np.asarray(centre, float)
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return np.stack([x, y, z])


def helmet_rig():
    """Four head-mounted cameras ~140 mm from a face at the origin, both radial models,
    realistic wide-angle coefficients (10-20 % correction at the sensor corners)."""
    centres = [(-70, -60, -120), (70, -60, -120), (-60, 50, -115), (60, 50, -115)]
    cams = []
    for i, c in enumerate(centres):
        if i % 2 == 0:
            model, dist = "VICON_RADIAL", np.array([2.4e-7, -6.0e-14])
        else:
            model, dist = "VICON_RADIAL2", np.array([641.7, 358.2, 3.1e-7, -1.5e-13, 4.0e-20])
        cams.append(Camera(name=f"HMC{i}", device_id=str(100 + i), sensor_size=(1280, 720),
                           focal_length=950.0 + 15 * i, principal_point=np.array([640.0 + 2 * i, 360.0 - 1.5 * i]),
                           aspect=1.0 + 0.002 * i, skew=0.1 * i, distortion_model=model, distortion=dist,
                           rotation=look_at(c), position=np.array(c, float)))
    return cams


def face_points(n, seed=0):
    rng = np.random.default_rng(seed)
    return rng.uniform(-35, 35, (n, 3)) * np.array([1.0, 1.2, 0.5])


@pytest.fixture
def rig():
    return helmet_rig()


# --------------------------------------------------------------------------- quaternions

def test_quaternion_known_rotation():
    s = np.sqrt(0.5)
    R = quaternion_to_matrix([0.0, 0.0, s, s])  # +90 degrees about z
    np.testing.assert_allclose(R, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-15)
    np.testing.assert_allclose(matrix_to_quaternion(R), [0, 0, s, s], atol=1e-15)


def test_quaternion_matrix_round_trip():
    rng = np.random.default_rng(1)
    q = rng.normal(size=(200, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    R = quaternion_to_matrix(q)
    # Independent reference: scipy uses the same (x, y, z, w) convention.
    np.testing.assert_allclose(R, Rotation.from_quat(q).as_matrix(), atol=1e-14)
    np.testing.assert_allclose(R @ R.transpose(0, 2, 1), np.broadcast_to(np.eye(3), R.shape), atol=1e-14)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-14)
    q2 = matrix_to_quaternion(R)
    assert np.all(q2[:, 3] >= 0)
    np.testing.assert_allclose(q2, q * np.sign(q[:, 3:4]), atol=1e-14)
    np.testing.assert_allclose(quaternion_to_matrix(q2), R, atol=1e-14)
    # Non-unit quaternions are normalised.
    np.testing.assert_allclose(quaternion_to_matrix(3.0 * q[0]), R[0], atol=1e-14)


def test_quaternion_rejects_bad_input():
    with pytest.raises(ValueError):
        quaternion_to_matrix([0, 0, 1])
    with pytest.raises(ValueError):
        quaternion_to_matrix([0, 0, 0, 0])


def test_camera_from_quaternion_and_back(rig):
    cam = rig[1]
    c2 = Camera.from_quaternion(cam.quaternion(), cam.position, focal_length=cam.focal_length)
    np.testing.assert_allclose(c2.rotation, cam.rotation, atol=1e-15)
    assert c2.quaternion()[3] >= 0


# --------------------------------------------------------------------------- distortion

def test_correct_hand_computed():
    # VICON_RADIAL about the principal point with aspect 2: dp = (100, 2 * 50).
    cam = Camera(principal_point=np.array([600.0, 400.0]), aspect=2.0,
                 distortion_model="VICON_RADIAL", distortion=np.array([1e-6, 1e-12]))
    r2 = 100.0 ** 2 + 100.0 ** 2
    s = 1 + 1e-6 * r2 + 1e-12 * r2 ** 2
    np.testing.assert_allclose(cam.correct([700.0, 450.0]), [600 + 100 * s, 400 + 100 * s / 2], rtol=1e-15)
    # VICON_RADIAL2 about its own centre, with the r^6 term.
    cam2 = Camera(principal_point=np.array([600.0, 400.0]), distortion_model="VICON_RADIAL2",
                  distortion=np.array([610.0, 390.0, 1e-7, 2e-13, 3e-19]))
    r2 = 90.0 ** 2 + 60.0 ** 2
    s = 1 + 1e-7 * r2 + 2e-13 * r2 ** 2 + 3e-19 * r2 ** 3
    np.testing.assert_allclose(cam2.correct([700.0, 450.0]), [610 + 90 * s, 390 + 60 * s], rtol=1e-15)


@pytest.mark.parametrize("index", [0, 1])
def test_distort_inverts_correct_over_sensor(rig, index):
    cam = rig[index]
    assert cam.distortion_model == ("VICON_RADIAL" if index == 0 else "VICON_RADIAL2")
    xs, ys = np.meshgrid(np.linspace(0, 1279, 41), np.linspace(0, 719, 23))
    raw = np.stack([xs.ravel(), ys.ravel()], axis=1)
    corrected = cam.correct(raw)
    # The correction is substantial at the corners (realistic wide-angle lens) ...
    assert np.max(np.linalg.norm(corrected - raw, axis=1)) > 50
    back = cam.distort(corrected)
    # ... and the inverse recovers the raw pixels (converged to ~1e-9 px).
    assert np.max(np.abs(back - raw)) < 1e-6
    assert np.max(np.abs(back - raw)) < 1e-8
    # The other direction too, and the (2,) form.
    np.testing.assert_allclose(cam.correct(cam.distort(raw)), raw, atol=1e-6)
    np.testing.assert_allclose(cam.distort(cam.correct(raw[5])), raw[5], atol=1e-6)
    assert cam.correct(raw[5]).shape == (2,)


def test_distort_beyond_fold_is_nan():
    # Strong negative r^4 term: rho * s(rho) peaks and folds back; past the peak
    # no raw pixel maps there.
    cam = Camera(distortion_model="VICON_RADIAL", distortion=np.array([0.0, -1e-12]))
    out = cam.distort(np.array([[640.0 + 100.0, 360.0], [640.0 + 5000.0, 360.0]]))
    assert np.all(np.isfinite(out[0])) and np.all(np.isnan(out[1]))
    assert np.all(np.isnan(cam.distort([np.nan, 1.0])))


def test_correct_jacobian_matches_finite_differences(rig):
    for cam in rig[:2]:
        p = np.array([[100.0, 650.0], [900.0, 200.0]])
        J = cam.correct_jacobian(p)
        h = 1e-4
        for j in range(2):
            dp = np.zeros(2)
            dp[j] = h
            fd = (cam.correct(p + dp) - cam.correct(p - dp)) / (2 * h)
            np.testing.assert_allclose(J[:, :, j], fd, rtol=1e-7, atol=1e-9)


# --------------------------------------------------------------------------- projection

def test_projection_hand_computed():
    # Identity rotation, camera 100 mm behind the origin, aspect 2, skew 1.
    cam = Camera(focal_length=1000.0, principal_point=np.array([640.0, 360.0]), aspect=2.0, skew=1.0,
                 position=np.array([0.0, 0.0, -100.0]))
    np.testing.assert_allclose(cam.K, [[1000, 1, 640], [0, 500, 360], [0, 0, 1]])
    np.testing.assert_allclose(cam.P, [[1000, 1, 640, 64000], [0, 500, 360, 36000], [0, 0, 1, 100]])
    # X = (10, 5, 0) is (10, 5, 100) in the camera: u = 1000*0.1 + 1*0.05 + 640, v = 500*0.05 + 360.
    np.testing.assert_allclose(cam.project_corrected([10.0, 5.0, 0.0]), [740.05, 385.0], rtol=1e-14)
    np.testing.assert_allclose(cam.project([10.0, 5.0, 0.0]), [740.05, 385.0], rtol=1e-14)  # no distortion
    assert cam.depth([10.0, 5.0, 0.0]) == pytest.approx(100.0)
    np.testing.assert_allclose(cam.to_camera([10.0, 5.0, 0.0]), [10, 5, 100])


def test_projection_matches_projection_matrix(rig):
    X = face_points(50)
    Xh = np.hstack([X, np.ones((50, 1))])
    for cam in rig:
        # P built here from the specification, independently of Camera.P.
        R = cam.rotation
        f, a, k = cam.focal_length, cam.aspect, cam.skew
        K = np.array([[f, k, cam.principal_point[0]], [0, f / a, cam.principal_point[1]], [0, 0, 1]])
        P = K @ np.hstack([R, (-R @ cam.position)[:, None]])
        np.testing.assert_allclose(cam.P, P, rtol=1e-13)
        h = Xh @ P.T
        expected = h[:, :2] / h[:, 2:]
        np.testing.assert_allclose(cam.project_corrected(X), expected, rtol=1e-12)
        raw = cam.project(X)
        # The raw pixel is the one whose correction is the corrected projection.
        np.testing.assert_allclose(cam.correct(raw), expected, atol=1e-6)
        assert np.all(cam.depth(X) > 0)
        # Every face point is inside the sensor.
        assert np.all((raw >= 0) & (raw < np.array(cam.sensor_size)))


def test_points_behind_camera_do_not_project(rig):
    cam = rig[0]
    behind = cam.position - 50 * cam.rotation[2]
    assert cam.depth(behind) < 0
    assert np.all(np.isnan(cam.project(behind)))
    assert np.all(np.isnan(cam.project_corrected(behind[None])))


def test_ray_passes_through_point(rig):
    X = face_points(20, seed=3)
    for cam in rig:
        origin, d = cam.ray(cam.project(X))
        np.testing.assert_allclose(origin, cam.position)
        np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0, atol=1e-14)
        v = X - origin
        along = np.sum(v * d, axis=1)
        assert np.all(along > 0)  # towards the scene
        np.testing.assert_allclose(np.linalg.norm(v - along[:, None] * d, axis=1), 0.0, atol=1e-6)


def test_with_pose_copies(rig):
    cam = rig[0]
    moved = cam.with_pose(np.eye(3), np.array([1.0, 2.0, 3.0]))
    assert moved.focal_length == cam.focal_length and moved.distortion_model == cam.distortion_model
    np.testing.assert_array_equal(moved.rotation, np.eye(3))
    moved.distortion[0] = 0.0
    assert cam.distortion[0] != 0.0
    assert cam.copy() == cam and moved != cam


def test_camera_validation():
    with pytest.raises(ValueError):
        Camera(distortion_model="VICON_RADIAL", distortion=np.zeros(5))
    with pytest.raises(ValueError):
        Camera(distortion_model="FISHEYE")
    with pytest.raises(ValueError):
        Camera(focal_length=0.0)
    np.testing.assert_array_equal(Camera(sensor_size=(1920, 1080)).principal_point, [960, 540])


# --------------------------------------------------------------------------- triangulation

@pytest.mark.parametrize("views", [(0, 1), (0, 2, 3), (0, 1, 2, 3), (1, 3)])
def test_triangulate_noiseless(rig, views):
    cams = [rig[i] for i in views]
    for X in face_points(10, seed=5):
        uv = np.stack([c.project(X) for c in cams])
        np.testing.assert_allclose(triangulate(cams, uv), X, atol=1e-6)
        np.testing.assert_allclose(triangulate(cams, uv, refine=False), X, atol=1e-6)


def test_triangulate_many_noiseless_and_agrees(rig):
    X = face_points(160, seed=7)
    uv = np.stack([c.project(X) for c in rig], axis=1)          # (N, V, 2)
    Y = triangulate_many(rig, uv)
    assert Y.shape == (160, 3)
    np.testing.assert_allclose(Y, X, atol=1e-6)
    np.testing.assert_allclose(reprojection_errors(rig, Y, uv), 0.0, atol=1e-6)
    # With detector noise the batched solver (raw error linearised at the
    # observations) and the single-point one (exact raw error) agree closely,
    # and both beat the linear solution.
    rng = np.random.default_rng(8)
    noisy = uv + rng.normal(0, 0.3, uv.shape)
    Ym = triangulate_many(rig, noisy)
    Ys = np.array([triangulate(rig, o) for o in noisy[:25]])
    np.testing.assert_allclose(Ym[:25], Ys, atol=1e-3)
    lin = triangulate_many(rig, noisy, refine=False)
    e_lin = np.nansum(reprojection_errors(rig, lin, noisy) ** 2)
    e_ref = np.nansum(reprojection_errors(rig, Ym, noisy) ** 2)
    assert e_ref <= e_lin
    assert np.sqrt(np.mean(reprojection_errors(rig, Ym, noisy) ** 2)) < 0.5


def test_triangulate_many_missing_views(rig):
    X = face_points(6, seed=9)
    uv = np.stack([c.project(X) for c in rig], axis=1)
    uv[1, [0, 1]] = np.nan          # two views left
    uv[2, [0, 1, 2]] = np.nan       # one view: no point
    uv[3] = np.nan                  # none
    uv[4, 2, 0] = np.nan            # half a pixel missing counts as missing
    Y = triangulate_many(rig, uv)
    np.testing.assert_allclose(Y[[0, 1, 4, 5]], X[[0, 1, 4, 5]], atol=1e-6)
    assert np.all(np.isnan(Y[[2, 3]]))
    # The single-point solver agrees, including NaN.
    np.testing.assert_allclose(triangulate(rig, uv[1]), X[1], atol=1e-6)
    assert np.all(np.isnan(triangulate(rig, uv[2])))
    # min_views raises the bar.
    Y3 = triangulate_many(rig, uv, min_views=3)
    assert np.all(np.isnan(Y3[[1, 2, 3]])) and np.all(np.isfinite(Y3[[0, 4, 5]]))
    errs = reprojection_errors(rig, Y, uv)
    assert errs.shape == (6, 4) and np.isnan(errs[1, 0]) and errs[1, 2] < 1e-6
    # Empty input.
    assert triangulate_many(rig, np.zeros((0, 4, 2))).shape == (0, 3)


# --------------------------------------------------------------------------- epipolar geometry

def test_fundamental_matrix_and_lines(rig):
    a, b = rig[0], rig[1]
    X = face_points(30, seed=11)
    ua, ub = a.project(X), b.project(X)
    F = fundamental_matrix(a, b)
    xa = np.hstack([a.correct(ua), np.ones((30, 1))])
    xb = np.hstack([b.correct(ub), np.ones((30, 1))])
    # Relative to the size of the terms, x_b^T F x_a vanishes.
    scale = np.abs(xb) @ np.abs(F) @ np.abs(xa).T
    assert np.max(np.abs(np.sum(xb * (xa @ F.T), axis=1)) / np.diag(scale)) < 1e-12
    lines = epipolar_line(a, b, ua)
    np.testing.assert_allclose(lines[:, 0] ** 2 + lines[:, 1] ** 2, 1.0)
    # The line passes through the true match (in b's corrected pixels).
    np.testing.assert_allclose(np.sum(lines * xb, axis=1), 0.0, atol=1e-6)
    assert epipolar_line(a, b, ua[0]).shape == (3,)


def test_symmetric_epipolar_distance(rig):
    a, b = rig[2], rig[3]
    X = face_points(40, seed=12)
    ua, ub = a.project(X), b.project(X)
    d = symmetric_epipolar_distance(a, ua, b, ub)
    assert d.shape == (40,)
    assert np.max(d) < 1e-6
    wrong = symmetric_epipolar_distance(a, ua, b, np.roll(ub, 1, axis=0))
    assert np.all(wrong > 0.1) and np.median(wrong) > 5
    # All pairs by broadcasting: the diagonal holds the true matches.
    M = symmetric_epipolar_distance(a, ua[:, None, :], b, ub[None, :, :])
    assert M.shape == (40, 40)
    np.testing.assert_allclose(np.diag(M), d, atol=1e-12)
    np.testing.assert_allclose(M[3, 7], symmetric_epipolar_distance(a, ua[3], b, ub[7]), rtol=1e-12)
    # Symmetric in the two cameras.
    np.testing.assert_allclose(symmetric_epipolar_distance(b, ub, a, np.roll(ua, -1, axis=0)),
                               np.roll(wrong, -1), rtol=1e-9)


def test_centroid(rig):
    np.testing.assert_allclose(centroid(rig), np.mean([c.position for c in rig], axis=0))
