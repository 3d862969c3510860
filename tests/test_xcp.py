"""XCP calibration files: reading, lossless writing, keyframes, bad input."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from lxml import etree

from carapost.core.camera import Camera, quaternion_to_matrix
from carapost.core.errors import CaraError
from carapost.io import atomic as atomic_mod
from carapost.io import xcp as xcp_mod
from carapost.io.xcp import read_xcp, write_xcp, xcp_from_cameras

DATA = Path(__file__).parent / "data" / "xcp"
SHARED_XCP = Path(__file__).parents[1] / ".." / "shared" / "data" / "xcp"
REAL = "opencap-core_testCalibration.xcp"


def real_file() -> Path:
    p = SHARED_XCP / REAL
    if not p.exists():
        pytest.skip("../shared is absent (clone elsewhere)")
    return p


def assert_same_tree(a, b):
    """Every element of ``a`` is in ``b`` at the same place with the same attribute strings."""
    assert a.tag == b.tag
    assert dict(a.attrib) == dict(b.attrib), f"<{a.tag}> line {a.sourceline}"
    ca, cb = list(a), list(b)
    assert [c.tag for c in ca] == [c.tag for c in cb]
    for x, y in zip(ca, cb):
        assert_same_tree(x, y)


def parse(path):
    return etree.parse(str(path)).getroot()


# --------------------------------------------------------------------------- the real Nexus file

def test_real_file_loads():
    x = read_xcp(real_file())
    assert len(x.cameras) == 25
    assert x.attrs["VERSION"] == "2.0"
    kinds = [c.attrs["DISPLAY_TYPE"] for c in x.cameras]
    assert (kinds.count("Vantage 16"), kinds.count("Vantage 5"), kinds.count("Vue")) == (8, 12, 5)
    for xc in x.cameras:
        assert len(xc.keyframes) == 1 and xc.keyframes[0].frame == 0
        cam = xc.at(0)
        assert cam.distortion_model == "VICON_RADIAL2" and cam.distortion.shape == (5,)
        assert cam.skew == 0.0 and cam.aspect == 1.0
        assert cam.device_id == xc.attrs["DEVICEID"] and cam.label == cam.device_id
        assert cam.sensor_size in [(4096, 4096), (2432, 2048), (1920, 1080)]
        # Every camera looks at the capture volume: the world origin is in front of it.
        assert cam.depth(np.zeros(3)) > 0
        # FOCAL_LENGTH in pixels: a plausible field of view for these lenses.
        fov = 2 * np.degrees(np.arctan(cam.sensor_size[0] / 2 / cam.focal_length))
        assert 20 < fov < 110
        np.testing.assert_allclose(cam.rotation @ cam.rotation.T, np.eye(3), atol=1e-14)
    first = x.cameras[0].camera
    assert first.device_id == "2109510"
    assert first.focal_length == 3962.33469727722
    np.testing.assert_array_equal(first.position, [-6368.08349199808, 559.614191749742, 2909.94688255975])
    np.testing.assert_array_equal(first.distortion, [2076.158482997856, 2043.3487558785741, 4.2617029255275423e-09,
                                                     -6.2363780472315727e-16, 4.8336137711293014e-23])


def _fold_radius(cam):
    """First raw radius where r s(r) stops increasing (inf if never within 5000 px)."""
    cx, cy, k1, k2, k3 = cam.distortion
    r = np.linspace(0, 5000, 200001)
    r2 = r * r
    fp = 1 + 3 * k1 * r2 + 5 * k2 * r2 ** 2 + 7 * k3 * r2 ** 3
    return r[np.argmax(fp <= 0)] if np.any(fp <= 0) else np.inf


def test_real_file_distortion_inverts():
    x = read_xcp(real_file())
    folded = seen = 0
    for xc in x.cameras:
        cam = xc.camera
        w, h = cam.sensor_size
        xs, ys = np.meshgrid(np.linspace(0, w - 1, 33), np.linspace(0, h - 1, 33))
        raw = np.stack([xs.ravel(), ys.ravel()], axis=1)
        corrected = cam.correct(raw)
        # Within the radius where the polynomial is monotonic the inverse is exact.
        # Three of these cameras' 3-term polynomials fold back in the extreme
        # sensor corners (outside the wand-waved area): there two raw radii share a
        # corrected one, and distort gives the inner one.
        fold = _fold_radius(cam)
        r_raw = np.hypot(raw[:, 0] - cam.distortion[0], raw[:, 1] - cam.distortion[1])
        folded += bool(fold < r_raw.max())
        inside = r_raw < 0.999 * fold
        assert inside.mean() > 0.95
        assert np.max(np.abs(cam.distort(corrected[inside]) - raw[inside])) < 1e-6
        back = cam.distort(corrected)
        ok = np.all(np.isfinite(back), axis=1)
        assert np.all(ok[inside])
        np.testing.assert_allclose(cam.correct(back[ok]), corrected[ok], atol=1e-6)
        # The origin, when it projects into the sensor, gives a raw pixel that
        # corrects back onto P's projection.
        uv_c = cam.project_corrected(np.zeros(3))
        if np.all((uv_c >= 0) & (uv_c < np.array([w, h]))):
            seen += 1
            np.testing.assert_allclose(cam.correct(cam.project(np.zeros(3))), uv_c, atol=1e-6)
    assert folded == 3
    assert seen >= 20


def test_real_file_round_trip(tmp_path):
    src = real_file()
    x = read_xcp(src)
    out = tmp_path / "copy.xcp"
    write_xcp(out, x)
    # Every attribute and element, with the same strings, in the same places.
    assert_same_tree(parse(src), parse(out))
    # Untouched, the file is reproduced byte for byte.
    assert out.read_bytes() == src.read_bytes()
    y = read_xcp(out)
    assert len(y.cameras) == 25
    for a, b in zip(x.cameras, y.cameras):
        assert a.attrs == b.attrs
        assert a.keyframes[0].attrs == b.keyframes[0].attrs
        assert a.camera == b.camera  # identical floats


def test_real_file_edit_writes_only_changes(tmp_path):
    src = real_file()
    x = read_xcp(src)
    cam0 = x.cameras[0].keyframes[0].camera
    cam0.position = cam0.position + np.array([0.1, -0.2, 1.0 / 3.0])
    cam0.focal_length = cam0.focal_length * (1 + 1e-7)
    kf3 = x.cameras[3].keyframes[0]
    R = quaternion_to_matrix([0.1, 0.2, 0.3, 0.9])
    kf3.camera = kf3.camera.with_pose(R, kf3.camera.position)
    cam5 = x.cameras[5].keyframes[0].camera
    cam5.distortion = cam5.distortion * np.array([1, 1, 1.01, 1, 1])
    out = tmp_path / "edited.xcp"
    write_xcp(out, x)
    y = read_xcp(out)
    # Edited values re-read as the same floats.
    assert y.cameras[0].camera.position.tolist() == cam0.position.tolist()
    assert y.cameras[0].camera.focal_length == cam0.focal_length
    assert y.cameras[5].camera.distortion.tolist() == cam5.distortion.tolist()
    np.testing.assert_allclose(y.cameras[3].camera.rotation, R, atol=1e-15)
    assert y.cameras[3].keyframes[0].attrs["ORIENTATION"].split() == [repr(float(v)) for v in
                                                                     kf3.camera.quaternion()]
    assert y.cameras[5].keyframes[0].attrs["VICON_RADIAL2"].startswith("Vicon3Parameter ")
    # Only the edited attributes changed; everything else keeps its string.
    changed = {(0, "POSITION"), (0, "FOCAL_LENGTH"), (3, "ORIENTATION"), (5, "VICON_RADIAL2")}
    for i, (a, b) in enumerate(zip(x.cameras, y.cameras)):
        assert a.attrs == b.attrs
        ka, kb = a.keyframes[0].attrs, b.keyframes[0].attrs
        assert list(ka) == list(kb)
        for key in ka:
            if (i, key) in changed:
                assert ka[key] != kb[key]
            else:
                assert ka[key] == kb[key], (i, key)
    # The unmodelled elements (threshold grids, calibration records) survive.
    assert [e.tag for e in parse(src).iter()] == [e.tag for e in parse(out).iter()]


# --------------------------------------------------------------------------- moving cameras and other files

def test_keyframes_pick_by_frame():
    x = read_xcp(DATA / "moving_cameras.xcp")
    assert len(x.cameras) == 2
    moving, static = x.cameras
    assert [kf.frame for kf in moving.keyframes] == [0, 11, 25]
    kf0, kf1, kf2 = (kf.camera for kf in moving.keyframes)
    assert moving.at(0) is kf0 and moving.at(10) is kf0
    assert moving.at(11) is kf1 and moving.at(24) is kf1
    assert moving.at(25) is kf2 and moving.at(10_000) is kf2
    assert moving.at(-3) is kf0  # before the first keyframe: the first
    np.testing.assert_array_equal(kf1.position, [-40, 12, -119.5])
    assert static.at(0) is static.at(500)
    assert x.cameras_at(12) == [kf1, static.camera]
    # Camera-element attributes reach every keyframe; SKEW, aspect and VICON_RADIAL parsed.
    for c in (kf0, kf1, kf2):
        assert (c.name, c.device_id, c.sensor_size) == ("HMC_TopLeft", "101", (1280, 720))
        assert c.aspect == 1.001 and c.skew == 0.25
        assert c.distortion_model == "VICON_RADIAL"
        np.testing.assert_array_equal(c.distortion, [2.7e-7, -2.0e-13])
    assert static.camera.skew == 0.0  # SKEW absent
    np.testing.assert_array_equal(static.camera.distortion, [640.5, 360.25, 3.1e-07, -1.5e-13, 2.0e-20])


def test_moving_file_round_trip_and_edits(tmp_path):
    src = DATA / "moving_cameras.xcp"
    x = read_xcp(src)
    out = tmp_path / "moving.xcp"
    write_xcp(out, x)
    assert out.read_bytes() == src.read_bytes()  # comment, unknown root attribute and <Vendor> kept
    # Add a keyframe, change the pixel aspect and skew, switch the static camera's model.
    moving, static = x.cameras
    new_cam = moving.keyframes[-1].camera.with_pose(np.eye(3), np.array([-40.0, 16.0, -118.0]))
    moving.keyframes.append(xcp_mod.XcpKeyFrame(frame=40, camera=new_cam))
    for kf in moving.keyframes:
        kf.camera.skew = 0.0
    static.keyframes[0].camera = Camera(**{**vars(static.camera), "distortion_model": "VICON_RADIAL",
                                           "distortion": np.array([1e-7, 0.0])})
    write_xcp(out, x)
    y = read_xcp(out)
    assert [kf.frame for kf in y.cameras[0].keyframes] == [0, 11, 25, 40]
    assert y.cameras[0].at(41) == new_cam
    assert y.cameras[0].attrs["SKEW"] == "0" and y.cameras[0].at(0).skew == 0.0
    assert y.cameras[0].attrs["PIXEL_ASPECT_RATIO"] == "1.0010"  # unchanged string kept
    kf_attrs = y.cameras[1].keyframes[0].attrs
    assert "VICON_RADIAL2" not in kf_attrs and kf_attrs["VICON_RADIAL"] == "1e-07 0"
    assert kf_attrs["WORLD_ERROR"] == "0.4"
    tree = parse(out)
    assert tree.get("CUSTOM_ROOT") == "kept"
    assert tree.find("Camera/Vendor/Child").get("value") == "1e-3"
    # The new KeyFrame sits with its siblings, one per line.
    kfs = tree.findall("Camera/KeyFrames")[0]
    assert len(kfs) == 4 and kfs[-1].tail == "\n    " and kfs[-2].tail == "\n      "
    # Dropping a camera drops its element.
    del x.cameras[0]
    write_xcp(out, x)
    z = read_xcp(out)
    assert [c.attrs["DEVICEID"] for c in z.cameras] == ["102"]


def test_no_distortion_attribute(tmp_path):
    text = (DATA / "moving_cameras.xcp").read_text()
    text = text.replace(' VICON_RADIAL2="Vicon3Parameter 640.5 360.25 3.1e-07 -1.5e-13 2.0e-20"', "")
    src = tmp_path / "plain.xcp"
    src.write_text(text)
    x = read_xcp(src)
    cam = x.cameras[1].camera
    assert cam.distortion_model == "none" and cam.distortion.size == 0
    np.testing.assert_array_equal(cam.correct([[10.0, 20.0]]), [[10.0, 20.0]])
    # Remove the other camera's distortion too: its VICON_RADIAL goes, nothing else changes.
    for kf in x.cameras[0].keyframes:
        kf.camera.distortion_model, kf.camera.distortion = "none", np.zeros(0)
    out = tmp_path / "out.xcp"
    write_xcp(out, x)
    y = read_xcp(out)
    for a, b in zip(x.cameras[0].keyframes, y.cameras[0].keyframes):
        assert b.camera.distortion_model == "none"
        assert {k: v for k, v in a.attrs.items() if k != "VICON_RADIAL"} == b.attrs


def _helmet(n=3):
    cams = []
    for i in range(n):
        ang = np.radians(-20 + 20 * i)
        R = np.array([[np.cos(ang), 0, -np.sin(ang)], [0, 1, 0], [np.sin(ang), 0, np.cos(ang)]])
        model, dist = (("VICON_RADIAL", [2.5e-7, -1e-13]) if i % 2 == 0
                       else ("VICON_RADIAL2", [640.125, 359.875, 3e-7, -1.25e-13, 1e-20]))
        cams.append(Camera(name=f"HMC{i}", device_id=str(200 + i), focal_length=1000.0 + i / 3,
                           principal_point=np.array([640.0 + i, 360.0 - i / 7]), aspect=1.0 + i * 1e-3,
                           skew=0.5 * (i == 2), distortion_model=model, distortion=np.array(dist),
                           rotation=R, position=-R.T @ np.array([0.1 * i, 0.0, 130.0 + i])))
    return cams


def test_xcp_from_cameras_round_trip(tmp_path):
    cams = _helmet()
    moved = cams[0].with_pose(quaternion_to_matrix([0.01, 0.02, 0.0, 1.0]), cams[0].position + 1.5)
    x = xcp_from_cameras([[(0, cams[0]), (30, moved)], [(0, cams[1])], [(0, cams[2])]], name="session")
    out = tmp_path / "new.xcp"
    write_xcp(out, x)
    text = out.read_text()
    assert text.startswith('<?xml version="1.0" encoding="UTF-8" standalone="no" ?>\n<Cameras NAME="session" '
                           'VERSION="2.0">')
    y = read_xcp(out)
    assert y.attrs == {"NAME": "session", "VERSION": "2.0"}
    got = [[(kf.frame, kf.camera) for kf in c.keyframes] for c in y.cameras]
    want = [[(0, cams[0]), (30, moved)], [(0, cams[1])], [(0, cams[2])]]
    for g, w in zip(got, want):
        assert [f for f, _ in g] == [f for f, _ in w]
        for (_, a), (_, b) in zip(g, w):
            # Rotations go through a quaternion; everything else re-reads as the same floats.
            np.testing.assert_allclose(a.rotation, b.rotation, atol=2e-16)
            assert a == b.with_pose(a.rotation, b.position)
    assert y.cameras[2].attrs["SKEW"] == "0.5" and "SKEW" not in y.cameras[0].attrs
    # Written again untouched, identical.
    out2 = tmp_path / "again.xcp"
    write_xcp(out2, y)
    assert out2.read_bytes() == out.read_bytes()


# --------------------------------------------------------------------------- bad input

@pytest.mark.parametrize("name, words", [
    ("truncated.xcp", ["XML"]),
    ("wrong_root.xcp", ["<Cameras>", "KinematicModel"]),
    ("no_keyframe.xcp", ["KeyFrame", "Camera 1"]),
    ("missing_focal_length.xcp", ["FOCAL_LENGTH", "line 5"]),
    ("bad_number.xcp", ["POSITION", "not numeric"]),
    ("bad_quaternion.xcp", ["ORIENTATION", "4 numbers"]),
])
def test_malformed_files_raise_cara_error(name, words):
    path = DATA / name
    with pytest.raises(CaraError) as info:
        read_xcp(path)
    msg = str(info.value)
    assert name in msg and info.value.path == str(path)
    for w in words:
        assert w in msg


def test_missing_and_odd_paths(tmp_path):
    for p, word in [(tmp_path / "nope.xcp", "not found"), (tmp_path, "folder")]:
        with pytest.raises(CaraError) as info:
            read_xcp(p)
        assert str(p) in str(info.value) and word in str(info.value)
    empty = tmp_path / "empty.xcp"
    empty.write_bytes(b"")
    with pytest.raises(CaraError, match="empty.xcp"):
        read_xcp(empty)


def test_more_bad_attributes(tmp_path):
    base = (DATA / "moving_cameras.xcp").read_text()
    cases = [
        (base.replace('SENSOR_SIZE="1280 720" SKEW', 'SENSOR_SIZE="1280" SKEW'), "SENSOR_SIZE"),
        (base.replace('FRAME="11"', 'FRAME="30"'), "FRAME 25 does not follow FRAME 30"),
        (base.replace('ORIENTATION="0 0 0 1"', 'ORIENTATION="0 0 0 0"'), "ORIENTATION"),
        (base.replace("Vicon3Parameter", "Vicon9Parameter"), "Vicon9Parameter"),
        (base.replace('FOCAL_LENGTH="998.75"', 'FOCAL_LENGTH="nan"'), "not finite"),
        (base.replace('PIXEL_ASPECT_RATIO="1"', 'PIXEL_ASPECT_RATIO="0"'), "PIXEL_ASPECT_RATIO"),
    ]
    for i, (text, word) in enumerate(cases):
        assert text != base
        p = tmp_path / f"case{i}.xcp"
        p.write_text(text)
        with pytest.raises(CaraError) as info:
            read_xcp(p)
        assert f"case{i}.xcp" in str(info.value) and word in str(info.value), str(info.value)


# --------------------------------------------------------------------------- failed writes

def _no_temp_files(folder: Path):
    return [p.name for p in folder.iterdir() if p.name.endswith(".tmp")] == []


def test_write_to_missing_or_unwritable_folder(tmp_path):
    x = read_xcp(DATA / "moving_cameras.xcp")
    target = tmp_path / "no_such_folder" / "out.xcp"
    with pytest.raises(CaraError) as info:
        write_xcp(target, x)
    assert "out.xcp" in str(info.value) and not target.exists()
    afile = tmp_path / "plain.txt"
    afile.write_text("x")
    with pytest.raises(CaraError, match="out.xcp"):
        write_xcp(afile / "out.xcp", x)
    if hasattr(os, "geteuid") and os.geteuid() != 0:  # root ignores folder permissions
        ro = tmp_path / "ro"
        ro.mkdir()
        ro.chmod(0o500)
        try:
            with pytest.raises(CaraError, match="out.xcp"):
                write_xcp(ro / "out.xcp", x)
            assert list(ro.iterdir()) == []
        finally:
            ro.chmod(0o700)


@pytest.mark.parametrize("fail_at", ["replace", "fsync"])
def test_failed_write_leaves_old_file_and_no_partial(tmp_path, monkeypatch, fail_at):
    x = read_xcp(DATA / "moving_cameras.xcp")
    target = tmp_path / "calib.xcp"
    target.write_bytes(b"previous contents")

    def boom(*a, **k):
        raise OSError(28, "No space left on device")

    monkeypatch.setattr(atomic_mod.os, fail_at, boom)
    with pytest.raises(CaraError) as info:
        write_xcp(target, x)
    assert "calib.xcp" in str(info.value) and "No space left" in str(info.value)
    assert target.read_bytes() == b"previous contents"
    assert _no_temp_files(tmp_path) and sorted(p.name for p in tmp_path.iterdir()) == ["calib.xcp"]


def test_non_finite_camera_is_not_written(tmp_path):
    x = read_xcp(DATA / "moving_cameras.xcp")
    x.cameras[1].keyframes[0].camera.position[0] = np.nan
    target = tmp_path / "calib.xcp"
    with pytest.raises(CaraError, match="calib.xcp"):
        write_xcp(target, x)
    assert not target.exists() and list(tmp_path.iterdir()) == []
