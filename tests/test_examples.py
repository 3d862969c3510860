"""The guide's ten example scripts (examples/): each has --help, runs on a small rendered take, and says true things."""
import ast
import importlib.util
import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest

from carapost.api import CaraExport, CaraProcess, property_table
from support import REPO, SMALL_TAKE_SET, copy_take, write_small_take

EXAMPLES = REPO / "examples"
SCRIPTS = ["process_detect_blobs", "process_track", "process_batch_detect_blobs", "cara_fbx_export",
           "process_setup_ROM", "process_properties", "export_3d_simple", "export_brim", "export_general",
           "export_timecode"]
THRESHOLD = [f"--set={k}={v}" for k, v in SMALL_TAKE_SET.items()]


def run(name, *args, cwd=None):
    """Run an example script; return its stdout (a failure shows its stderr)."""
    r = subprocess.run([sys.executable, str(EXAMPLES / f"{name}.py"), *map(str, args)], capture_output=True,
                       text=True, cwd=cwd, timeout=300)
    assert r.returncode == 0, f"{name} exited {r.returncode}:\n{r.stderr}"
    return r.stdout


def load_script(name):
    spec = importlib.util.spec_from_file_location(f"example_{name}", EXAMPLES / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def take(tmp_path_factory):
    """A rendered take, its blobs, its initialised project and its tracked project."""
    folder = write_small_take(tmp_path_factory.mktemp("examples_take"))
    p = CaraProcess(folder / "Sample_0.pico")
    for k, v in SMALL_TAKE_SET.items():
        p.set_property(k, v)
    p.import_xcp(folder / "calibration.xcp")
    p.set_brim(folder / "brim.svg")
    p.detect_blobs()
    p.save(folder / "blobs.cara")
    p.initialize_from_seeds(folder / "seeds.json")
    p.save(folder / "init.cara")
    p.track(0)
    p.save(folder / "tracked.cara")
    return folder


def test_the_ten_scripts_are_there():
    assert sorted(p.stem for p in EXAMPLES.glob("*.py")) == sorted(SCRIPTS)


def test_every_script_has_help_and_a_docstring():
    procs = {name: subprocess.Popen([sys.executable, str(EXAMPLES / f"{name}.py"), "--help"], text=True,
                                    stdout=subprocess.PIPE, stderr=subprocess.PIPE) for name in SCRIPTS}
    for name, proc in procs.items():
        out, err = proc.communicate(timeout=120)
        assert proc.returncode == 0, f"{name}: {err}"
        assert out.startswith("usage: ") and "-h, --help" in out
        doc = ast.get_docstring(ast.parse((EXAMPLES / f"{name}.py").read_text()))
        assert doc and len(doc.splitlines()) >= 3 and doc.splitlines()[0] in " ".join(out.split())


def test_a_bad_input_is_one_line_and_status_2(tmp_path):
    missing = tmp_path / "missing.cara"
    r = subprocess.run([sys.executable, str(EXAMPLES / "export_brim.py"), str(missing)], capture_output=True,
                       text=True, timeout=120)
    assert r.returncode == 2 and r.stderr == f"export_brim: error: {missing}: no such file\n"


def test_process_detect_blobs_writes_take_b_cara(take, tmp_path):
    copy_take(take, tmp_path, "Example", extra=())
    out = run("process_detect_blobs", tmp_path / "Example_0.pico", *THRESHOLD, "--end", 1)
    written = tmp_path / "Example_b.cara"
    e = CaraExport(written)
    counts = [sum(len(e.detections(s, f)) for f in range(e.frame_count)) for s in range(4)]
    assert f"{sum(counts)} blobs ({', '.join(map(str, counts))} per channel) in 4 frames -> {written}" in out
    assert sum(counts) > 200 and all(len(e.detections(s, 3)) == 0 for s in range(4))   # frames 0-1 only
    assert e.properties()["blob.black_threshold"] == pytest.approx(0.1)


def test_process_batch_detect_blobs_skips_takes_that_have_blobs(take, tmp_path):
    for name in ("ROM_1", "ROM_2", "Speech"):
        copy_take(take, tmp_path / name, name, extra=())
    done = tmp_path / "ROM_1" / "ROM_1_b.cara"
    done.write_bytes((take / "blobs.cara").read_bytes())
    before = done.stat().st_mtime_ns
    out = run("process_batch_detect_blobs", str(tmp_path / "*" / "ROM*.pico"), *THRESHOLD)
    assert re.search(r"skip +ROM_1: .*ROM_1_b\.cara exists", out)
    assert re.search(r"wrote +ROM_2: ", out) and "Speech" not in out
    assert "2 takes: 1 detected, 1 skipped, 0 failed" in out
    assert done.stat().st_mtime_ns == before
    assert CaraExport(tmp_path / "ROM_2" / "ROM_2_b.cara").detections(0, 0).size > 20
    assert not (tmp_path / "Speech" / "Speech_b.cara").exists()


def test_process_track_a_cara_from_its_first_frame(take, tmp_path):
    src = tmp_path / "Example.cara"
    shutil.copy(take / "init.cara", src)
    before = CaraExport(src)
    assert all(not np.any(before.point_status(pid)[1:]) for pid in before.point_ids())   # frame 0 only
    out = run("process_track", src, "--c3d", tmp_path / "Example.c3d")
    after = CaraExport(src)
    ids = after.point_ids()
    tracked = sum(bool(np.any(after.point_status(pid))) for pid in ids)
    samples = sum(int(np.count_nonzero(after.point_status(pid))) for pid in ids)
    assert f"{tracked} of {len(ids)} face points tracked, {samples} 3D samples in 4 frames" in out
    assert sum(bool(np.all(after.point_status(pid))) for pid in ids) >= 0.8 * len(ids)   # through frame 3
    assert (tmp_path / "Example.c3d").stat().st_size > 0


def test_process_track_a_pico_initialised_from_a_rom(take, tmp_path):
    copy_take(take, tmp_path, "Speech", extra=())
    rom = take / "tracked.cara"
    out = run("process_track", tmp_path / "Speech_0.pico", "--rom", rom, *THRESHOLD)
    result = CaraExport(tmp_path / "Speech.cara")
    labels = {result.point_label(pid) for pid in result.point_ids()}
    rom_labels = {lb for lb in (CaraExport(rom).point_label(pid) for pid in CaraExport(rom).point_ids()) if lb}
    assert rom_labels and rom_labels <= labels                      # the ROM's labelled points came over
    assert re.search(r"Initialize from ROM on frame 0: \d+ points", out)
    ids = result.point_ids()
    assert sum(bool(np.all(result.point_status(pid))) for pid in ids) >= 0.8 * len(ids)
    assert len(result.point_ids("brim")) >= 15


def test_process_setup_rom_makes_a_project_ready_to_track(take, tmp_path):
    copy_take(take, tmp_path, "ROM", extra=("calibration.xcp", "brim.svg", "seeds.json", "labels.txt"))
    out = run("process_setup_ROM", tmp_path / "ROM_0.pico", "--xcp", "calibration.xcp", "--brim-svg", "brim.svg",
              "--labels", "labels.txt", "--seeds", "seeds.json", *THRESHOLD, cwd=tmp_path)
    rom = CaraExport(tmp_path / "ROM.cara")
    labels = (tmp_path / "labels.txt").read_text().split()
    assert rom.labels()[:len(labels)] == labels
    assert len(rom.brim_markers()) == 20 and rom.camera(0, 0) is not None
    faces = len(rom.point_ids())
    assert faces >= 20 and f"{faces} face points initialised on frame 0" in out
    assert f"{len(rom.labels())} labels" in out and f"wrote {tmp_path / 'ROM.cara'}" in out


def test_process_properties_lists_every_property(take):
    table = property_table()
    listed = run("process_properties")
    keys = re.findall(r"^  (\S+)\s", listed, re.M)
    assert keys == [r["key"] for r in table]
    assert f"{len(table)} properties in {len({r['group'] for r in table})} groups" in listed
    mine = run("process_properties", take / "tracked.cara", "--group", "blob")
    assert re.search(r"blob\.black_threshold +0\.1 \* +\(default 0\.4, 0\.\.1\)", mine)
    assert not re.search(r"blob\.white_threshold .*\*", mine)
    assert set(re.findall(r"^  (\S+)\s", mine, re.M)) == {r["key"] for r in table if r["group"] == "blob"}
    rows = json.loads(run("process_properties", "--json"))
    assert [(r["key"], r["value"]) for r in rows] == [(r["key"], r["default"]) for r in table]


def test_export_3d_simple_prints_the_face_points(take):
    e = CaraExport(take / "tracked.cara")
    out = run("export_3d_simple", take / "tracked.cara")
    rows = [ln.split() for ln in out.splitlines()[2:]]
    names = {e.point_label(pid) or f"Point_{pid}": pid for pid in e.point_ids()}
    expected = sum(int(np.count_nonzero(np.isfinite(e.point_3d(pid)[:, 0]))) for pid in names.values())
    assert len(rows) == expected > 0
    for f, name, *xyz in rows:
        np.testing.assert_allclose([float(v) for v in xyz], e.point_3d(names[name])[int(f)], atol=5e-4)
    one = run("export_3d_simple", take / "tracked.cara", "--label", "Nose_Tip", "--start", 2)
    assert [ln.split()[:2] for ln in one.splitlines()[2:]] == [["2", "Nose_Tip"], ["3", "Nose_Tip"]]


def test_export_brim_prints_layout_and_tracked_brim(take):
    e = CaraExport(take / "tracked.cara")
    out = run("export_brim", take / "tracked.cara")
    layout = [[float(v) for v in ln.split()[2:]] for ln in out.splitlines() if ln.startswith("marker")]
    np.testing.assert_allclose(layout, e.brim_markers(), atol=5e-4)
    brim = e.brim_3d()
    rows = [ln.split() for ln in out.splitlines() if re.match(r"^ +\d+ +\d+ ", ln)]
    assert len(rows) == sum(int(np.isfinite(v[:, 0]).sum()) for v in brim.values()) > 0
    for f, index, *xyz in rows:
        np.testing.assert_allclose([float(v) for v in xyz], brim[int(index)][int(f)], atol=5e-4)


def test_export_general_prints_point_data_and_plots_2d_tracks(take, tmp_path):
    import cv2

    e = CaraExport(take / "tracked.cara")
    png = tmp_path / "tracks.png"
    out = run("export_general", take / "tracked.cara", "-o", png, "--sensor", 1)
    img = cv2.imread(str(png))
    assert img.shape == (720, 1280, 3) and (img < 128).any()          # the size of sensor 1's images, drawn on
    rows = {int(m[0]): tuple(map(int, m[1:])) for m in re.findall(r"^ *(\d+) \S+ +(\d+) +(\d+) +(\d+) +(\d+)$",
                                                                    out, re.M)}
    assert sorted(rows) == sorted(e.point_ids())
    for pid, counts in rows.items():
        st = e.point_status(pid)
        assert counts == tuple(int(np.count_nonzero(st == c)) for c in (1, 2, 3, 0))
    drawn = sum(bool(np.isfinite(e.point_2d(pid, 1)[:, 0]).any()) for pid in e.point_ids())
    assert f"{drawn} 2D tracks drawn with" in out and drawn > 20


def test_cara_fbx_export_builds_the_builtin_export(take, tmp_path):
    from carapost.io.cara import load_project
    from carapost.io.export_fbx import project_fbx_scene

    out = tmp_path / "Example.fbx"
    printed = run("cara_fbx_export", take / "tracked.cara", "-o", out)
    e = CaraExport(take / "tracked.cara")
    n = len(e.point_ids(None))
    assert f"{n} animated Nulls, 4 frames at 60 fps -> {out}" in printed
    mine, _ = load_script("cara_fbx_export").build_scene(e)
    # The file is this scene (tests/test_fbx.py reads FbxScene files back with ufbx and assimp);
    # only the header's time stamp can differ, and it has a fixed size.
    data = out.read_bytes()
    assert data.startswith(b"Kaydara FBX Binary") and len(data) == len(mine.to_bytes())
    assert len(mine.nulls) == n + 2                                  # Face, Brim, one Null per point
    builtin = project_fbx_scene(load_project(take / "tracked.cara"))

    def nodes(scene):
        return [(nd.name, nd.parent.name if nd.parent else None,
                 None if nd.key_frames is None else nd.key_frames.tolist()) for nd in scene.nulls]

    assert nodes(mine) == nodes(builtin)
    for a, b in zip(mine.nulls, builtin.nulls):
        if a.key_xyz is not None:
            np.testing.assert_allclose(a.key_xyz, b.key_xyz, atol=1e-9)
    grouped, _ = load_script("cara_fbx_export").build_scene(e, group_by_prefix=True)
    parents = {nd.name: nd.parent.name for nd in grouped.nulls if nd.parent}
    assert parents["Nose_Tip"] == "Nose" and parents["Nose"] == "Face"


def test_export_timecode_converts_frames_numbers_and_timecode(tmp_path):
    from carapost.io.pico import write_pico

    frames = [np.full((64, 64), 40 * i, np.uint8) for i in range(5)]
    for c in range(4):
        write_pico(tmp_path / f"TC_{c}.pico", frames, frame_rate=30.0, channel=c, start_frame=1000 + 10 * c,
                   timecode="10:00:59:28")
    CaraProcess(tmp_path / "TC_0.pico").save(tmp_path / "TC.cara")
    table = run("export_timecode", tmp_path / "TC.cara").splitlines()[2:]
    assert [ln.split() for ln in table] == [[str(f), str(1000 + f), f"10:00:59:{28 + f}" if f < 2 else
                                             f"10:01:00:{f - 2:02d}"] for f in range(5)]
    assert run("export_timecode", tmp_path / "TC.cara", "--timecode", "10:01:00:01").splitlines()[2].split() == \
        ["3", "1003", "10:01:00:01"]
    assert run("export_timecode", tmp_path / "TC.cara", "--burnt-in", 1021, "--sensor", 2).splitlines()[2].split() \
        == ["1", "1021", "10:00:59:29"]
