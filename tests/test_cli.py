"""The command line: properties, info, and the error behaviour of CONTRACT section 2."""
import json
import subprocess
import sys

import pytest

from carapost.cli import main
from carapost.core.properties import PROPERTY_TABLE
from carapost.io import cara
from support import REPO, make_project, shared_file


def run_cli(*args):
    return subprocess.run([sys.executable, "-m", "carapost", *map(str, args)], capture_output=True, text=True,
                          cwd=REPO, timeout=120)


def test_properties_json_lists_every_property(capsys):
    assert main(["properties", "--json"]) == 0
    rows = json.loads(capsys.readouterr().out)
    assert {r["key"] for r in rows} == {p.key for p in PROPERTY_TABLE}
    row = next(r for r in rows if r["key"] == "tracking.patch_match_threshold")
    assert row["value"] == row["default"] == 0.8 and row["group_title"] == "Tracking Parameters"


def test_properties_of_a_project(tmp_path, capsys):
    p = make_project(frames=5)
    p.properties.set("blob.find_white_blobs", True)
    cara.save_project(p, tmp_path / "t.cara")
    assert main(["properties", str(tmp_path / "t.cara")]) == 0
    out = capsys.readouterr().out
    assert "[Blob Parameters]" in out
    assert "blob.find_white_blobs" in out and "(default false)" in out


def test_info_on_a_project(tmp_path, capsys):
    p = make_project(frames=12, with_rig=True)
    cara.save_project(p, tmp_path / "t.cara")
    assert main(["info", str(tmp_path / "t.cara"), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["frames"] == 12 and len(info["sensors"]) == 4 and info["format_version"] == cara.FORMAT_VERSION
    assert info["points"]["face"] == len(p.points)
    assert info["detections"] == [d.total() for d in p.detections]


def test_info_on_the_real_xcp(capsys):
    xcp = shared_file("xcp", "opencap-core_testCalibration.xcp")
    assert main(["info", str(xcp)]) == 0
    out = capsys.readouterr().out
    assert "cameras: 25" in out and "VICON_RADIAL2" in out


@pytest.mark.parametrize("make_bad,needle", [
    (lambda d: d / "missing.cara", "no such file"),
    (lambda d: (d / "bad.xcp").write_text("<Cameras><Camera") and d / "bad.xcp", "bad.xcp"),
    (lambda d: (d / "t.cara").write_bytes(b"CARAPOST" + b"\0" * 10) and d / "t.cara", "t.cara"),
    (lambda d: (d / "x.doc").write_text("x") and d / "x.doc", "unknown kind of file"),
])
def test_bad_input_exit_2_one_line(tmp_path, make_bad, needle):
    path = make_bad(tmp_path)
    r = run_cli("info", path)
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and str(path.name) in lines[0]
    assert "Traceback" not in r.stderr


def test_bad_set_value_exit_2(tmp_path):
    from carapost.core.errors import CaraError
    from carapost.core.properties import parse_set_options

    with pytest.raises(CaraError, match="tracking.patch_match_threshold"):
        parse_set_options(["tracking.patch_match_threshold=2"])


def test_python_dash_m_and_version():
    r = run_cli("--version")
    assert r.returncode == 0 and "carapost" in r.stdout


def test_info_on_the_real_facial_c3d(capsys):
    c3d = shared_file("c3d", "c3dorg_sample29_Facial-Sing.c3d")
    assert main(["info", str(c3d), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["points"] == 38 and info["frames"] == 3000 and info["rate"] == 100
    assert info["warnings"]  # the malformed LABELS record is reported, not fatal


def test_export_c3d_and_xcp(tmp_path):
    from carapost.io.c3d import read_c3d
    from carapost.io.xcp import read_xcp

    p = make_project(frames=10, with_rig=True)
    cara.save_project(p, tmp_path / "t.cara")
    assert main(["export", "c3d", str(tmp_path / "t.cara"), str(tmp_path / "t.c3d")]) == 0
    d = read_c3d(tmp_path / "t.c3d")
    assert d.positions.shape == (10, len(p.points), 3)
    assert main(["export", "xcp", str(tmp_path / "t.cara"), str(tmp_path / "t.xcp"), "--frame", "3"]) == 0
    x = read_xcp(tmp_path / "t.xcp")
    assert len(x.cameras) == 4
    import numpy as np

    assert np.allclose(x.cameras[1].at(0).position, p.rig.camera(1, 3).position)
    r = run_cli("export", "xcp", tmp_path / "t.cara", tmp_path / "u.xcp", "--frame", "99")
    assert r.returncode == 2 and "frame 99" in r.stderr


def test_process_refuses_bad_inputs_cleanly(tmp_path):
    (tmp_path / "seeds.json").write_text("{not json")
    r = run_cli("process", tmp_path / "none_0.pico", "--xcp", tmp_path / "c.xcp", "--brim", "v2.0",
                "--seeds", tmp_path / "seeds.json", "-o", tmp_path / "out.cara")
    assert r.returncode == 2 and "seeds.json" in r.stderr and "Traceback" not in r.stderr
    r = run_cli("process", tmp_path / "none_0.pico", "--xcp", tmp_path / "c.xcp", "--brim", "v2.0",
                "--seeds", tmp_path / "seeds.json", "-o", tmp_path / "no" / "out.cara")
    assert r.returncode == 2 and "does not exist" in r.stderr
    assert not (tmp_path / "out.cara").exists()
