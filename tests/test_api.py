"""The scripting API (carapost.api): PyCara's classes over a project."""
import numpy as np
import pytest

from carapost.api import CaraExport, CaraProcess, DebugServices, Pico, frame_to_timecode, timecode_to_frames
from carapost.core.errors import CaraError
from carapost.io import cara
from carapost.io.pico import write_pico
from support import make_project


def test_process_properties_undo_and_save(tmp_path):
    for ch in range(4):
        write_pico(tmp_path / f"Ex_{ch}.pico", [np.full((32, 48), 10 * k, np.uint8) for k in range(5)], channel=ch)
    p = CaraProcess(tmp_path / "Ex_0.pico")
    assert p.project.sensor_count == 4 and p.project.frame_count == 5
    p.set_property("tracking.patch_match_threshold", 0.7)
    assert p.get_property("tracking.patch_match_threshold") == 0.7
    p.undo()
    assert p.get_property("tracking.patch_match_threshold") == 0.8
    p.redo()
    p.set_brim("v2.0")
    p.save(tmp_path / "Ex.cara")
    e = CaraExport(tmp_path / "Ex.cara")
    assert e.frame_count == 5 and len(e.brim_markers()) == 19
    with pytest.raises(CaraError):
        p.set_property("tracking.patch_match_threshold", 3)


def test_export_reads_points_tracks_and_timecode(tmp_path):
    proj = make_project(frames=30, with_rig=True)
    proj.timecode_start = "10:00:00:00"
    proj.frame_rate = 30.0
    cara.save_project(proj, tmp_path / "t.cara")
    e = CaraExport(tmp_path / "t.cara")
    pid = e.point_ids()[0]
    xyz = e.point_3d(pid)
    present = proj.points[pid].status != 0
    assert np.allclose(xyz[present], proj.points[pid].pos[present]) and np.isnan(xyz[~present]).all()
    uv = e.point_2d(pid, 0)
    assert np.isnan(uv[proj.points[pid].src[:, 0] == 0]).all()
    assert e.frame_to_timecode(31) == "10:00:01:01"
    assert e.timecode_to_frame("10:00:01:01") == 31
    assert e.camera(1, 3).name == "cam1"


def test_timecode_helpers():
    assert timecode_to_frames("00:00:01:00", 60) == 60
    assert frame_to_timecode(59, "00:00:00:00", 60) == "00:00:00:59"
    with pytest.raises(CaraError):
        timecode_to_frames("12:00", 30)


def test_pico_and_debug_services(tmp_path):
    write_pico(tmp_path / "A_0.pico", [np.full((16, 16), 7 * k, np.uint8) for k in range(3)], capture_name="A")
    with Pico(tmp_path / "A_0.pico") as pc:
        assert pc.frame_count == 3 and pc.size == (16, 16)
        assert int(pc.frame(2)[0, 0]) == 14
        assert pc.frame_number(1) - pc.frame_number(0) == 1
    DebugServices.set_log_level("warning")
    assert DebugServices.get_log_level() == "warning"
    with pytest.raises(CaraError):
        DebugServices.set_log_level("loud")


def test_target_tracking_from_a_script(tmp_path):
    """CaraProcess.target_track follows a keyed marker through a rendered take; Clear Tracked Points undoes it."""
    from carapost.core import editing
    from carapost.core.points import SRC_TARGET
    from support import write_small_take

    folder = write_small_take(tmp_path)
    truth = np.load(folder / "truth.npz")
    uv = truth["uv"]                                     # (F, 4, markers + brim, 2) raw px
    F = uv.shape[0]
    m = int(np.flatnonzero(truth["visible"][:, 0].all(axis=0))[0])    # a marker seen by channel 0 throughout
    p = CaraProcess(folder / "Sample_0.pico")
    p.import_xcp(folder / "calibration.xcp")
    pid = p.document.run(editing.add_target_track(p.project, 0, 0, uv[0, 0, m])).select_after[0]
    report = p.target_track([pid], "forward_to_end", frame=0)
    q = p.project.point(pid)
    assert report["last"] == F - 1 and np.all(q.src[1:, 0] == SRC_TARGET)
    assert np.max(np.linalg.norm(q.uv[1:, 0] - uv[1:, 0, m], axis=1)) < 0.5
    p.clear_tracked_points([pid])
    assert not np.any(p.project.point(pid).src[1:, 0] == SRC_TARGET)
