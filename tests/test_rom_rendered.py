"""Initialize from ROM on rendered sample takes (issue 7, "Judged by", second point).

A one-frame ROM take of a 35-marker face is processed as a user would
(seeds.json, brim.svg, Initialize 3D, labelled) and saved; two more takes of
the same face with another motion are initialised from it: one with the helmet
put on again 5 mm / 3 degrees off, one with a camera moved 10 mm / 6 degrees.
Markers are scored when two or more cameras see them and their paint is not
faint (see :mod:`carapost.sample.rom_trial`).
"""
from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from carapost.io.cara import save_project
from carapost.sample import write_sample
from carapost.sample.face import EXPRESSIONS
from carapost.sample.rig import BRIM_RIG_R, BRIM_RIG_T
from carapost.sample.rom_trial import initialize, make_rom
from carapost.sample.scene import build_scene, frame_geometry, true_cameras

BASE = dict(markers=35, frames=1, seed=0)
RIG = dict(BASE, motion_seed=100, rig_move=(5.0, 3.0))
MOVED = 1
CAMERA = dict(BASE, motion_seed=100, camera_move=(MOVED, 10.0, 6.0))


@pytest.fixture(scope="module")
def takes(tmp_path_factory):
    root = tmp_path_factory.mktemp("rom_rendered")
    for name, kw in (("rom", BASE), ("rig", RIG), ("camera", CAMERA)):
        write_sample(root / name, workers=1, **kw)
    rom, info = make_rom(root / "rom", BASE)
    save_project(rom, root / "ROM.cara")
    return root, info


@pytest.fixture(scope="module")
def camera_runs(takes):
    root, _ = takes
    return (initialize(root / "ROM.cara", root / "camera", CAMERA),
            initialize(root / "ROM.cara", root / "camera", CAMERA, solve_channel=MOVED))


def _rigid(A, B):
    """Rotation and translation with B ~ A R^T + t (Kabsch)."""
    ca, cb = A.mean(axis=0), B.mean(axis=0)
    U, _, Vt = np.linalg.svd((A - ca).T @ (B - cb))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(Vt.T @ U.T))])
    R = Vt.T @ D @ U.T
    return R, cb - ca @ R.T


def test_second_take_options_move_exactly_what_they_say():
    plain = build_scene(**dict(BASE, motion_seed=100))
    helmet = build_scene(**RIG)
    knocked = build_scene(**CAMERA)
    # The same face, markers and rig; the helmet moves the face relative to brim and cameras.
    assert plain.markers.labels == helmet.markers.labels == knocked.markers.labels
    A, B = frame_geometry(plain, 0).points[:35], frame_geometry(helmet, 0).points[:35]
    R, t = _rigid(A, B)
    assert np.allclose(B, A @ R.T + t, atol=1e-9)
    assert np.degrees(Rotation.from_matrix(R).magnitude()) == pytest.approx(3.0, abs=1e-6)
    # 5 mm exactly at the neutral face's centre (the move is about it, in rig coordinates).
    c = plain.marker_basis.pose(np.zeros(len(EXPRESSIONS))).reshape(-1, 13, 3)[:, 0].mean(axis=0)
    c = (c - BRIM_RIG_T) @ BRIM_RIG_R
    assert np.linalg.norm(c @ R.T + t - c) == pytest.approx(5.0, abs=1e-6)
    for a, b in zip(true_cameras(plain, 0), true_cameras(helmet, 0)):
        assert np.allclose(a.position, b.position) and np.allclose(a.rotation, b.rotation)
    # One camera knocked: only it moves, by 10 mm and 6 degrees (to within the bar's flex, which
    # pivots about the camera centroid: the knock moves that by 2.5 mm, the flex's effect by ~1 um).
    for c, (a, b) in enumerate(zip(true_cameras(plain, 0), true_cameras(knocked, 0))):
        moved = np.linalg.norm(a.position - b.position)
        turn = np.degrees(Rotation.from_matrix(a.rotation @ b.rotation.T).magnitude())
        if c == MOVED:
            assert moved == pytest.approx(10.0, abs=0.01) and turn == pytest.approx(6.0, abs=1e-3)
        else:
            assert moved < 0.01 and turn < 1e-3
    assert np.allclose(frame_geometry(plain, 0).points, frame_geometry(knocked, 0).points)
    # The defaults are the seed's own take (the same arrays, not merely close).
    same = build_scene(**dict(BASE, motion_seed=BASE["seed"], rig_move=(0.0, 0.0), camera_move=None))
    assert np.array_equal(frame_geometry(same, 0).verts, frame_geometry(build_scene(**BASE), 0).verts)


def test_rom_is_processed_and_labelled_from_the_rendered_take(takes):
    _root, info = takes
    assert info["markers"] >= 30
    assert info["points"] >= 0.98 * info["markers"]


def test_helmet_moved_5mm_3deg_labels_98_percent_and_none_wrong(takes):
    root, _ = takes
    got = initialize(root / "ROM.cara", root / "rig", RIG)
    assert got["error"] == "" and not got["warnings"], got
    assert got["fraction"] >= 0.98 and got["wrong"] == 0, got
    assert got["camera_error_mm"] < 0.5
    assert got["report"]["labelled"] == got["report"]["points"]


def test_camera_moved_without_help_says_which_channel_and_what_to_do(camera_runs):
    bare, _ = camera_runs
    text = " ".join(bare["warnings"]) + bare["error"]
    assert f"for channel {MOVED}" in text and "Solve ROM Camera From Correspondences" in text, bare
    if not bare["error"]:
        assert bare["report"]["weak_channels"] == [MOVED]
        # Its pose cannot be trusted (the warning says so): it is not the true one.
        assert bare["camera_error_mm"] > 1.0


def test_camera_moved_10mm_6deg_after_solve_rom_camera_labels_98_percent(camera_runs):
    _, solved = camera_runs
    # Only the knocked camera moved: the others stay where the ROM had them.
    assert "stay" in solved["solve"], solved["solve"]
    assert solved["error"] == "" and not solved["warnings"], solved
    assert solved["fraction"] >= 0.98 and solved["wrong"] == 0, solved
    assert solved["camera_error_mm"] < 0.5


def test_sample_command_checks_the_second_take_options(tmp_path, capsys):
    from carapost.cli import main

    assert main(["sample", str(tmp_path / "a"), "--frames", "1", "--rig-move", "5"]) == 2
    assert "--rig-move must be MM,DEG" in capsys.readouterr().err
    assert main(["sample", str(tmp_path / "b"), "--frames", "1", "--camera-move", "7,10,6"]) == 2
    assert "no camera 7" in capsys.readouterr().err
    assert not (tmp_path / "b" / "Sample_0.pico").exists()


def test_a_single_camera_solve_is_saved_with_the_project(camera_runs, tmp_path):
    from carapost.core import rom_ops
    from carapost.io.cara import load_project

    p = camera_runs[1]["process"]
    p.save(tmp_path / "take.cara")
    before = rom_ops.loaded_rom(p.project)
    after = rom_ops.loaded_rom(load_project(tmp_path / "take.cara"))
    assert len(after.cam_T) == 4 and np.allclose(np.array(after.cam_T), np.array(before.cam_T))
    # Only the knocked camera carries a motion of its own.
    assert [not np.allclose(T, np.eye(4)) for T in after.cam_T] == [c == MOVED for c in range(4)]
