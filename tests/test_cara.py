"""The .cara project file: round trip, lazy load, atomic save, bad files."""
import os
import struct
from pathlib import Path

import numpy as np
import pytest

from carapost.core.brim import Brim
from carapost.core.document import Document
from carapost.core.edits import ClearPointRange
from carapost.core.errors import CaraError
from carapost.core.project import MediaRef, Stick
from carapost.io import cara
from support import REPO, make_project


def _full_project():
    p = make_project(frames=40, points=5, with_rig=True)
    p.brim = Brim("v2.0", np.arange(12.0).reshape(4, 3), svg="<svg/>")
    p.sticks = [Stick(0, 1, (255, 0, 0))]
    p.properties.set("tracking.patch_match_threshold", 0.65)
    p.active_range = (5, 30)
    p.view_range = (2, 35)
    p.channel_selection = [1, 3]
    p.sensors[2].rotation = 3
    p.sensors[1].image_offset = 2
    p.points[0].keyframes[(4, 1)] = (8.0, 8.0, 20.0, 20.0)
    p.rig.set_pose(1, 7, p.rig.camera(1, 7).with_pose(np.eye(3), np.array([1.0, 2.0, 3.0])))
    return p


def test_round_trip_keeps_everything(tmp_path):
    p = _full_project()
    path = tmp_path / "take.cara"
    cara.save_project(p, path)
    q = cara.load_project(path)
    assert q.digest() == p.digest()
    assert np.allclose(q.rig.camera(1, 9).position, [1, 2, 3])
    assert q.points[0].keyframes == {(4, 1): (8.0, 8.0, 20.0, 20.0)}


def test_loaded_arrays_are_memory_mapped_and_edits_stay_private(tmp_path):
    p = _full_project()
    path = tmp_path / "take.cara"
    cara.save_project(p, path)
    before = path.read_bytes()
    q = cara.load_project(path)
    pt = next(iter(q.points.values()))
    assert isinstance(pt.pos.base, np.memmap) or isinstance(pt.pos, np.memmap) or pt.pos.base is not None
    doc = Document(q)
    doc.run(ClearPointRange([pt.id], 0, q.frame_count - 1))
    assert path.read_bytes() == before  # copy-on-write: the file is not touched by edits
    cara.save_project(q, path)  # saving over the file it is mapped from
    r = cara.load_project(path)
    assert r.digest() == q.digest()
    assert not r.points[pt.id].present().any()


def test_detection_overlay_consolidates_on_save(tmp_path):
    from carapost.core.detections import make_detections

    p = make_project(frames=30)
    path = tmp_path / "a.cara"
    cara.save_project(p, path)
    q = cara.load_project(path)
    q.detections[2].set_frame(7, make_detections([1.5, 2.5], [3.5, 4.5]))
    cara.save_project(q, tmp_path / "b.cara")
    r = cara.load_project(tmp_path / "b.cara")
    assert r.digest() == q.digest()
    assert list(r.detections[2].frame(7)["x"]) == [1.5, 2.5]
    assert r.detections[2].detected[7]


def test_crash_mid_save_leaves_old_file_intact(tmp_path, monkeypatch):
    p = _full_project()
    path = tmp_path / "take.cara"
    cara.save_project(p, path)
    good = path.read_bytes()
    real_put = cara._ArrayWriter.put
    calls = {"n": 0}

    def dying_put(self, arr):
        calls["n"] += 1
        if calls["n"] == 5:
            raise KeyboardInterrupt("power cut")
        return real_put(self, arr)

    monkeypatch.setattr(cara._ArrayWriter, "put", dying_put)
    p.points[0].label = "changed"
    with pytest.raises(KeyboardInterrupt):
        cara.save_project(p, path)
    assert path.read_bytes() == good
    assert [x.name for x in tmp_path.iterdir()] == ["take.cara"]  # no temporary file left behind


def test_truncated_file_is_refused(tmp_path):
    path = tmp_path / "take.cara"
    cara.save_project(_full_project(), path)
    data = path.read_bytes()
    for cut in (10, 100, len(data) // 2, len(data) - 1):
        bad = tmp_path / f"cut{cut}.cara"
        bad.write_bytes(data[:cut])
        with pytest.raises(CaraError, match=f"cut{cut}.cara") as e:
            cara.load_project(bad)
        assert "truncated" in str(e.value) or "not a carapost project" in str(e.value)


def test_corrupt_manifest_is_refused(tmp_path):
    path = tmp_path / "take.cara"
    cara.save_project(_full_project(), path)
    data = bytearray(path.read_bytes())
    joff = struct.unpack_from("<Q", data, 16)[0]
    data[joff + 20] ^= 0xFF
    path.write_bytes(bytes(data))
    with pytest.raises(CaraError, match="corrupt"):
        cara.load_project(path)


def test_newer_version_is_refused_with_a_clear_message(tmp_path):
    path = tmp_path / "future.cara"
    cara.save_project(make_project(frames=5), path)
    data = bytearray(path.read_bytes())
    struct.pack_into("<I", data, 8, cara.FORMAT_VERSION + 1)
    path.write_bytes(bytes(data))
    with pytest.raises(CaraError, match="newer carapost"):
        cara.load_project(path)


def test_missing_and_wrong_files(tmp_path):
    with pytest.raises(CaraError, match="no such file"):
        cara.load_project(tmp_path / "nope.cara")
    txt = tmp_path / "x.cara"
    txt.write_text("hello")
    with pytest.raises(CaraError, match="not a carapost project"):
        cara.load_project(txt)


def test_unwritable_folder(tmp_path):
    p = make_project(frames=5)
    with pytest.raises(CaraError, match="does not exist"):
        cara.save_project(p, tmp_path / "no" / "such" / "dir" / "a.cara")
    locked = tmp_path / "locked"
    locked.mkdir()
    existing = locked / "a.cara"
    cara.save_project(p, existing)
    before = existing.read_bytes()
    os.chmod(locked, 0o500)
    try:
        if os.access(locked, os.W_OK):  # root ignores permissions: use a folder no one can create files in
            target = Path("/proc/1/a.cara")
        else:
            target = existing
        with pytest.raises(CaraError, match="a.cara"):
            cara.save_project(p, target)
    finally:
        os.chmod(locked, 0o700)
    assert existing.read_bytes() == before


def test_media_found_again_after_the_folder_moves(tmp_path):
    take = tmp_path / "job"
    take.mkdir()
    media = take / "Example_0.pico"
    media.write_bytes(b"x")
    p = make_project(frames=5)
    p.sensors[0].media = MediaRef(str(media), kind="pico")
    p.sensors[1].media = MediaRef(str(tmp_path / "elsewhere" / "gone_1.pico"), kind="pico")
    cara.save_project(p, take / "take.cara")
    moved = tmp_path / "moved"
    take.rename(moved)
    q = cara.load_project(moved / "take.cara")
    assert q.sensors[0].media.path == str(moved / "Example_0.pico")
    assert not q.sensors[0].media.missing
    assert q.sensors[1].media.missing
    assert cara.missing_media(q) == [1]


def test_golden_files_of_every_format_version_load():
    goldens = sorted((REPO / "tests" / "data").glob("golden_v*.cara"))
    assert goldens, "tests/data must keep a golden file of each format version"
    versions = set()
    for g in goldens:
        v, _ = cara.read_header(g)
        versions.add(v)
        p = cara.load_project(g)
        assert p.frame_count == 40 and p.sensor_count == 4
        assert [x.label for x in p.points.values()][:3] == ["M0", "", "M2"]
        assert p.properties.tracking.patch_match_threshold == 0.65
        assert p.brim.name == "v2.0" and p.rig is not None
    assert versions == set(range(1, cara.FORMAT_VERSION + 1))


def test_import_labels_from_cara(tmp_path):
    from carapost.core.labels import merge_labels

    p = make_project(frames=5)
    cara.save_project(p, tmp_path / "rom.cara")
    labels = cara.read_labels(tmp_path / "rom.cara")
    assert labels[:3] == ["M0", "M2", "M4"]
    assert merge_labels(["M0"], labels)[:3] == ["M0", "M0 - Copy", "M2"]
