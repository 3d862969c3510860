"""Load ROM, Initialize from ROM [Brim Only] and the ROM Tools (issue 7, item 3).

The ROM is a synthetic take whose project is built from its truth; the second
take is the same face and brim filmed with every camera moved (the helmet put
on again) and holds only detections, as after importing its .pico files.
"""
from __future__ import annotations

import logging

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from carapost.api import CaraProcess
from carapost.core import rom_ops
from carapost.core.errors import CaraError
from carapost.core.points import BRIM, FACE
from carapost.core.project import Project
from carapost.io.cara import load_project, save_project
from rom_support import bare, rom_project, score, take

FRAME = 3


@pytest.fixture(scope="module")
def rom_file(tmp_path_factory):
    path = tmp_path_factory.mktemp("rom") / "ROM.cara"
    save_project(rom_project(take(), 0), path)
    return path


def second_take(move):
    scene = take(rig_move=move, motion_seed=77)
    return scene, CaraProcess.from_project(bare(scene))


def rom_ids(p: CaraProcess, kind=FACE) -> dict:
    """ROM point ids by label (face) or brim index (brim)."""
    rom = rom_ops.loaded_rom(p.project).rom
    return {(q.label if kind == FACE else q.brim_index): q.id for q in rom.points.values() if q.kind == kind}


def test_initialize_from_rom_labels_the_moved_take_and_undoes_exactly(rom_file):
    scene, p = second_take((5.0, 3.0))
    p.load_rom(rom_file)
    before = p.project.digest()
    report = p.initialize_from_rom(FRAME)
    got = score(p.project, scene, FRAME)
    assert got["fraction"] >= 0.98 and got["wrong"] == 0, got
    assert report["points"] == got["correct"] and report["labelled"] == got["correct"]
    # Everything came from the ROM: brim, cameras (close to the true moved ones), labels, sticks.
    pr = p.project
    assert pr.brim is not None and pr.rig is not None
    assert sum(q.kind == BRIM for q in pr.points.values()) == report["brim_markers"] >= 15
    for cam, true in zip(pr.rig.cameras_at(FRAME), scene.cameras[FRAME]):
        assert np.linalg.norm(cam.position - true.position) < 0.5
    assert set(f"M{m:02d}" for m in range(35)) <= set(pr.labels)
    assert len(pr.sticks) == 10
    rom = rom_ops.loaded_rom(pr).rom
    assert {(rom.points[s.a].label, rom.points[s.b].label) for s in rom.sticks} == \
        {(pr.points[s.a].label, pr.points[s.b].label) for s in pr.sticks}
    assert p.document.stack.names()[-1] == "Initialize from ROM"
    p.undo()
    assert pr.digest() == before
    p.redo()
    assert score(pr, scene, FRAME)["correct"] == got["correct"]


def test_brim_only_sets_brim_and_cameras_but_no_face_points(rom_file):
    scene, p = second_take((5.0, 3.0))
    p.load_rom(rom_file)
    report = p.initialize_from_rom(FRAME, brim_only=True)
    pr = p.project
    assert not list(pr.face_points())
    assert report["brim_markers"] >= 15 and report["points"] == 0
    for cam, true in zip(pr.rig.cameras_at(FRAME), scene.cameras[FRAME]):
        assert np.linalg.norm(cam.position - true.position) < 1.0
    assert p.document.stack.names()[-1] == "Initialize from ROM [Brim Only]"


def test_moved_twice_as_far_needs_a_camera_solve_from_four_correspondences(rom_file):
    scene, p = second_take((10.0, 6.0))
    p.load_rom(rom_file)
    try:
        p.initialize_from_rom(FRAME)
        assert score(p.project, scene, FRAME)["fraction"] < 0.98
        p.undo()
    except CaraError as e:
        assert "ROM Brim Point Tracking Distance" in str(e)
    # Four brim markers spread over channel 0, clicked in the take.
    brim = rom_ids(p, BRIM)
    seen = [b for b in sorted(brim) if scene.brim_det[FRAME, 0, b] >= 0]
    for b in [seen[i] for i in np.linspace(0, len(seen) - 1, 4).round().astype(int)]:
        p.add_rom_correspondence(brim[b], 0, int(scene.brim_det[FRAME, 0, b]), FRAME)
    assert len(rom_ops.loaded_rom(p.project).correspondences) == 4
    p.solve_rom_camera()
    got_report = p.initialize_from_rom(FRAME)
    got = score(p.project, scene, FRAME)
    assert got["fraction"] >= 0.98 and got["wrong"] == 0, (got, got_report)


def test_face_alignment_from_correspondences_recovers_a_shifted_face(tmp_path):
    rom_scene = take()
    rom = rom_project(rom_scene, 0)
    # The actor's face sits differently in the brim: 17 mm and 8 degrees away in the ROM.
    c = rom_scene.face[0].mean(axis=0)
    Rm = Rotation.from_rotvec(np.radians(8.0) * np.array([0.958, 0.287, 0.0])).as_matrix()
    for q in rom.points.values():
        if q.kind == FACE:
            q.pos[0] = (q.pos[0] - c) @ Rm.T + c + np.array([14.0, -9.0, 4.0])
    save_project(rom, tmp_path / "shifted.cara")
    scene, p = second_take((2.0, 1.0))
    p.load_rom(tmp_path / "shifted.cara")
    p.initialize_from_rom(FRAME)
    assert score(p.project, scene, FRAME)["fraction"] < 0.5
    p.undo()
    ids = rom_ids(p)
    for ch in (0, 2):
        seen = [m for m in range(35) if scene.face_det[FRAME, ch, m] >= 0]
        for m in [seen[i] for i in np.linspace(0, len(seen) - 1, 4).round().astype(int)]:
            p.add_rom_correspondence(ids[f"M{m:02d}"], ch, int(scene.face_det[FRAME, ch, m]), FRAME)
    p.solve_rom_face_alignment(FRAME)
    p.initialize_from_rom(FRAME)
    got = score(p.project, scene, FRAME)
    assert got["fraction"] >= 0.98 and got["wrong"] == 0, got


def test_no_rom_loaded_is_a_clear_error():
    scene, p = second_take((0.0, 0.0))
    before = p.project.digest()
    with pytest.raises(CaraError, match="no ROM is loaded.*Load ROM"):
        p.initialize_from_rom(FRAME)
    for call in (p.clear_rom_correspondences, p.solve_rom_camera):
        with pytest.raises(CaraError, match="no ROM is loaded"):
            call()
    assert p.project.digest() == before and len(p.document.stack) == 0


def test_load_rom_rejects_bad_files(tmp_path, rom_file):
    _scene, p = second_take((0.0, 0.0))
    bad = tmp_path / "notes.txt"
    bad.write_text("x")
    with pytest.raises(CaraError, match="notes.txt"):
        p.load_rom(bad)
    with pytest.raises(CaraError, match="missing.cara"):
        p.load_rom(tmp_path / "missing.cara")
    save_project(Project(5, 3), tmp_path / "three.cara")
    with pytest.raises(CaraError, match="3 channels, this take 4"):
        p.load_rom(tmp_path / "three.cara")
    assert not p.project.rom_path and len(p.document.stack) == 0


def test_rom_path_is_saved_and_the_rom_reloads(tmp_path, rom_file):
    scene, p = second_take((5.0, 3.0))
    p.load_rom(rom_file)
    p.save(tmp_path / "take.cara")
    reopened = load_project(tmp_path / "take.cara")
    assert reopened.rom_path == str(rom_file)
    assert not reopened.points            # the ROM's points are not copied into the take
    q = CaraProcess.from_project(reopened)
    q.initialize_from_rom(FRAME)
    assert score(q.project, scene, FRAME)["fraction"] >= 0.98


def test_rom_tools_state_is_saved_with_the_project(tmp_path, rom_file):
    """Correspondences and the solved ROM camera come back after save and reopen."""
    scene, p = second_take((10.0, 6.0))
    p.load_rom(rom_file)
    brim = rom_ids(p, BRIM)
    seen = [b for b in sorted(brim) if scene.brim_det[FRAME, 0, b] >= 0]
    for b in [seen[i] for i in np.linspace(0, len(seen) - 1, 4).round().astype(int)]:
        p.add_rom_correspondence(brim[b], 0, int(scene.brim_det[FRAME, 0, b]), FRAME)
    p.solve_rom_camera()
    before = rom_ops.loaded_rom(p.project)
    p.save(tmp_path / "take.cara")
    after = rom_ops.loaded_rom(load_project(tmp_path / "take.cara"))
    assert after.correspondences == before.correspondences
    assert np.allclose(after.rig_T, before.rig_T) and not np.allclose(after.rig_T, np.eye(4))
    q = CaraProcess.from_project(load_project(tmp_path / "take.cara"))
    q.initialize_from_rom(FRAME)
    assert score(q.project, scene, FRAME)["fraction"] >= 0.98


def test_running_twice_adds_a_second_set_and_says_so(rom_file, caplog):
    scene, p = second_take((5.0, 3.0))
    p.load_rom(rom_file)
    first = p.initialize_from_rom(FRAME)["points"]
    with caplog.at_level(logging.WARNING, logger="carapost"):
        second = p.initialize_from_rom(FRAME)
    assert "second, independent set" in caplog.text
    assert len(list(p.project.face_points())) == first + second["points"]
    # Labels name one point each: the second set is unlabelled.
    labels = [q.label for q in p.project.face_points() if q.label]
    assert len(labels) == len(set(labels)) == first and second["labelled"] == 0


def test_correspondences_are_undoable_and_checked(rom_file):
    scene, p = second_take((0.0, 0.0))
    p.load_rom(rom_file)
    ids = rom_ids(p)
    p.add_rom_correspondence(ids["M00"], 1, int(scene.face_det[FRAME, 1, 0]), FRAME)
    p.add_rom_correspondence(ids["M00"], 1, 2, FRAME)     # the same ROM point and channel: replaced
    corr = rom_ops.loaded_rom(p.project).correspondences
    assert [(k.rom_point, k.sensor, k.detection) for k in corr] == [(ids["M00"], 1, 2)]
    with pytest.raises(CaraError, match="4 or more correspondences"):
        p.solve_rom_camera()
    with pytest.raises(CaraError, match="3 or more face point correspondences"):
        p.solve_rom_face_alignment(FRAME)
    with pytest.raises(CaraError, match="select one detection"):
        p.document.run(rom_ops.add_2d_to_rom_correspondence(p.project, ids["M01"], []))
    with pytest.raises(CaraError, match="no point 9999"):
        p.add_rom_correspondence(9999, 0, 0, FRAME)
    p.clear_rom_correspondences()
    assert rom_ops.loaded_rom(p.project).correspondences == ()
    p.undo()
    assert len(rom_ops.loaded_rom(p.project).correspondences) == 1
    p.undo()
    p.undo()
    assert rom_ops.loaded_rom(p.project).correspondences == ()


def test_rom_frame_index_outside_the_rom(rom_file):
    _scene, p = second_take((0.0, 0.0))
    p.load_rom(rom_file)
    p.set_property("initialize_from_rom.rom_frame_index", 50)
    with pytest.raises(CaraError, match="ROM Frame Index 50 is outside the ROM take"):
        p.initialize_from_rom(FRAME)


def test_rom_projections_follow_the_camera_solve(rom_file):
    scene, p = second_take((10.0, 6.0))
    p.load_rom(rom_file)
    ids = rom_ids(p)
    proj = rom_ops.rom_projections(p.project)
    row = {int(i): k for k, i in enumerate(proj["ids"])}
    true = [scene.cameras[FRAME][0].project(scene.face[FRAME, m][None])[0] for m in range(35)]
    err0 = np.nanmedian([np.linalg.norm(proj["uv"][row[ids[f"M{m:02d}"]], 0] - true[m]) for m in range(35)])
    assert err0 > 20
    brim = rom_ids(p, BRIM)
    seen = [b for b in sorted(brim) if scene.brim_det[FRAME, 0, b] >= 0]
    for b in [seen[i] for i in np.linspace(0, len(seen) - 1, 5).round().astype(int)]:
        p.add_rom_correspondence(brim[b], 0, int(scene.brim_det[FRAME, 0, b]), FRAME)
    p.solve_rom_camera(0)
    proj = rom_ops.rom_projections(p.project)
    err1 = np.nanmedian([np.linalg.norm(proj["uv"][row[ids[f"M{m:02d}"]], 0] - true[m]) for m in range(35)])
    assert err1 < 3
