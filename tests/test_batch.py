"""`carapost batch`: takes in parallel on local processes and on a Dask cluster, resumable, failures isolated."""
import json
import os
import re

import numpy as np
import pytest

from carapost.api.batch import find_takes, is_up_to_date, load_pipeline, parse_pipeline, plan_batch
from carapost.cli import main
from carapost.core.errors import CaraError
from carapost.io.c3d import read_c3d
from carapost.io.cara import load_project
from support import SMALL_TAKE_SET, copy_take, write_small_take

#: The whole pipeline of `carapost process`, as a pipeline file; inputs beside each take.
FULL = {"set": SMALL_TAKE_SET,
        "steps": [{"import_xcp": "calibration.xcp"}, {"set_brim": "brim.svg"}, "detect_blobs",
                  {"initialize": "seeds.json"}, "track", "interpolate_gaps"],
        "outputs": {"cara": "{take}.cara", "c3d": "{take}.c3d"}}
#: Blobs on one frame only: for the tests of the batch's mechanics rather than of the processing.
BLOBS = {"steps": [{"detect_blobs": {"start": 0, "end": 0}}], "outputs": {"cara": "{take}_b.cara"}}


@pytest.fixture(scope="module")
def rendered(tmp_path_factory):
    return write_small_take(tmp_path_factory.mktemp("small_take"))


def make_batch(root, rendered, names, pipeline):
    for name in names:
        copy_take(rendered, root / name, name)
    pfile = root / "pipeline.json"
    pfile.write_text(json.dumps(pipeline))
    return pfile


def run_cli(capsys, *argv):
    rc = main(["batch", *map(str, argv)])
    return rc, capsys.readouterr().err


def test_local_batch_writes_every_take_then_skips_them(tmp_path, rendered, capsys):
    names = ["TakeA", "TakeB", "TakeC"]
    pfile = make_batch(tmp_path, rendered, names, FULL)
    rc, err = run_cli(capsys, tmp_path, "--pipeline", pfile, "--workers", 2)
    assert rc == 0, err
    assert "3 done, 0 up to date, 0 failed" in err
    stamps, pids = {}, set()
    for name in names:
        cara, c3d = tmp_path / name / f"{name}.cara", tmp_path / name / f"{name}.c3d"
        project = load_project(cara)
        faces = [p for p in project.face_points() if np.any(p.status[1:] != 0)]
        assert len(faces) >= 20                          # initialised and tracked past the seeds' frame
        assert read_c3d(c3d).positions.shape[:2] == (4, len(project.points))
        manifest = json.loads((tmp_path / name / f"{name}.batch.json").read_text())
        assert manifest["status"] == "ok" and manifest["steps"][2] == "detect_blobs"
        pids.add(manifest["pid"])
        stamps[name] = (cara.stat().st_mtime_ns, c3d.stat().st_mtime_ns)
    assert not list(tmp_path.rglob("*.tmp*"))          # outputs were renamed into place
    assert len(pids) == 2 and os.getpid() not in pids  # two worker processes shared the takes

    rc, err = run_cli(capsys, tmp_path, "--pipeline", pfile, "--workers", 2)
    assert rc == 0 and "0 to run, 3 up to date" in err
    for name in names:
        assert stamps[name] == ((tmp_path / name / f"{name}.cara").stat().st_mtime_ns,
                                (tmp_path / name / f"{name}.c3d").stat().st_mtime_ns)

    # A newer input (new seeds for TakeB) or a changed pipeline makes a take due again.
    seeds = tmp_path / "TakeB" / "seeds.json"
    os.utime(seeds, ns=(seeds.stat().st_atime_ns, stamps["TakeB"][0] + 10**9))

    def due(overrides=None):
        return [j.take for j in plan_batch(find_takes([tmp_path]), load_pipeline(pfile), overrides)
                if not is_up_to_date(j)]

    assert due() == ["TakeB"]
    assert due({"tracking.patch_match_threshold": 0.8}) == names


def test_a_corrupt_take_fails_alone_and_is_named(tmp_path, rendered, capsys):
    pfile = make_batch(tmp_path, rendered, ["Good1", "Bad", "Good2"], BLOBS)
    bad = tmp_path / "Bad" / "Bad_0.pico"
    bad.write_bytes(bad.read_bytes()[:100])
    rc, err = run_cli(capsys, tmp_path, "--pipeline", pfile, "--workers", 2)
    assert rc == 1
    failures = [ln for ln in err.splitlines() if ln.startswith("carapost: batch: failed:")]
    assert failures == [f"carapost: batch: failed: {bad}: open: not a .pico file: only 100 bytes"]
    for name in ("Good1", "Good2"):
        project = load_project(tmp_path / name / f"{name}_b.cara")
        assert sum(len(d.frame(0)) for d in project.detections) > 100
    assert not (tmp_path / "Bad" / "Bad_b.cara").exists()
    manifest = json.loads((tmp_path / "Bad" / "Bad.batch.json").read_text())
    assert manifest["status"] == "failed" and "CaraError" in manifest["traceback"]

    # Fixed, the failed take alone runs again.
    copy_take(rendered, tmp_path / "Bad", "Bad")
    rc, err = run_cli(capsys, tmp_path, "--pipeline", pfile)
    assert rc == 0 and "1 to run, 2 up to date" in err


def test_the_same_batch_on_a_dask_cluster(tmp_path, rendered, capsys, monkeypatch):
    distributed = pytest.importorskip("distributed")  # a dependency (pyproject.toml): never skips in make test
    names = ["TakeA", "TakeB", "TakeC"]
    pfile = make_batch(tmp_path, rendered, names, BLOBS)
    monkeypatch.setenv("OPENBLAS_NUM_THREADS", "1")     # the workers inherit it
    with distributed.LocalCluster(n_workers=2, processes=True, threads_per_worker=1, host="127.0.0.1",
                                  dashboard_address=None, worker_dashboard_address=None) as cluster:
        address = cluster.scheduler_address
        assert address.startswith("tcp://127.0.0.1:")
        rc, err = run_cli(capsys, tmp_path, "--pipeline", pfile, "--scheduler", address)
        hosts = {json.loads((tmp_path / n / f"{n}.batch.json").read_text())["pid"] for n in names}
    assert rc == 0, err
    assert "3 done" in err
    assert os.getpid() not in hosts                     # ran in the cluster's worker processes
    for name in names:
        assert load_project(tmp_path / name / f"{name}_b.cara").detections[0].total() > 0


def test_unreachable_scheduler_is_a_bad_argument(tmp_path, rendered, capsys):
    import socket

    with socket.socket() as s:                          # a free port nobody listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    pfile = make_batch(tmp_path, rendered, ["TakeA"], BLOBS)
    rc, err = run_cli(capsys, tmp_path, "--pipeline", pfile, "--scheduler", f"tcp://127.0.0.1:{port}")
    assert rc == 2 and "cannot connect to the Dask scheduler" in err


@pytest.mark.parametrize("pipeline, message", [
    ({"steps": ["detect_blob"]}, "steps[0]: unknown step 'detect_blob'"),
    ({"steps": [{"detect_blobs": {"first": 0}}]}, "steps[0] (detect_blobs): unknown option 'first'"),
    ({"steps": ["detect_blobs"], "set": {"blob.no_such": 1}}, "set: blob.no_such"),
    ({"steps": ["detect_blobs"], "outputs": {"obj": "{take}.obj"}}, "outputs: unknown kind 'obj'"),
    ({"steps": [{"import_xcp": "missing.xcp"}]}, "steps[0]: no such file"),
    ({"steps": ["detect_blobs"], "outputs": {"cara": "all.cara"}, "output_dir": "out"},
     "would be written by take 'TakeA' and take 'TakeB'"),
    ({"steps": [{"import_xcp": "calibration.xcp"}], "outputs": {"xcp": "calibration.xcp"}},
     "is an input of take 'TakeA'"),
])
def test_a_bad_pipeline_exits_2_naming_the_file(tmp_path, rendered, capsys, pipeline, message):
    pfile = make_batch(tmp_path, rendered, ["TakeA", "TakeB"], pipeline)
    rc, err = run_cli(capsys, tmp_path, "--pipeline", pfile)
    assert rc == 2
    assert err.count("\n") == 1 and err.startswith(f"carapost: error: {pfile}: ") and message in err
    assert not list(tmp_path.rglob("*.cara"))


def test_takes_from_files_folders_and_wildcards(tmp_path, rendered, capsys):
    for name in ("ROM_1", "ROM_2", "Speech"):
        copy_take(rendered, tmp_path / "jobs" / name, name, extra=())
    one = tmp_path / "jobs" / "Speech" / "Speech_2.pico"
    assert [(t.name, len(t.files)) for t in find_takes([one])] == [("Speech", 4)]
    assert sorted(t.name for t in find_takes([tmp_path / "jobs"])) == ["ROM_1", "ROM_2", "Speech"]
    assert sorted(t.name for t in find_takes([str(tmp_path / "jobs" / "*" / "ROM*.pico")])) == ["ROM_1", "ROM_2"]
    assert len(find_takes([tmp_path / "jobs", one])) == 3           # each take once
    with pytest.raises(CaraError, match="no such file or folder"):
        find_takes([tmp_path / "nope.pico"])
    with pytest.raises(CaraError, match="no .pico file matches"):
        find_takes([str(tmp_path / "jobs" / "X*.pico")])


def test_inputs_resolve_beside_the_take_then_beside_the_pipeline(tmp_path, rendered):
    copy_take(rendered, tmp_path / "takes" / "T1", "T1", extra=("seeds.json",))
    copy_take(rendered, tmp_path / "takes" / "T2", "T2", extra=("seeds.json",))
    (tmp_path / "calibration.xcp").write_bytes((rendered / "calibration.xcp").read_bytes())
    pipe = parse_pipeline({"steps": [{"import_xcp": "calibration.xcp"}, {"set_brim": "v2.0"},
                                     {"initialize": "{take_dir}/seeds.json"}],
                           "outputs": {"cara": "{take}.cara", "c3d": "c3d/{take}.c3d"}, "output_dir": "out"},
                          tmp_path / "p.json")
    jobs = plan_batch(find_takes([tmp_path / "takes"]), pipe, {"blob.black_threshold": 0.2})
    j = jobs[1]
    assert j.steps[0]["path"] == str(tmp_path / "calibration.xcp")
    assert j.steps[1]["brim"] == "v2.0"
    assert j.steps[2]["seeds"] == str(tmp_path / "takes" / "T2" / "seeds.json")
    assert j.outputs == {"cara": str(tmp_path / "out" / "T2.cara"), "c3d": str(tmp_path / "out" / "c3d" / "T2.c3d")}
    assert j.manifest == str(tmp_path / "out" / "T2.batch.json")
    assert j.properties == {"blob.black_threshold": 0.2}
    assert str(tmp_path / "takes" / "T2" / "seeds.json") in j.inputs and len(j.inputs) == 6
    assert re.fullmatch(r"[0-9a-f]{16}", j.fingerprint)


def test_relative_takes_write_beside_the_take_whatever_the_pipeline_folder(tmp_path, rendered, monkeypatch):
    copy_take(rendered, tmp_path / "takes" / "T1", "T1", extra=())
    (tmp_path / "pipelines").mkdir()
    (tmp_path / "pipelines" / "blobs.json").write_text(json.dumps(BLOBS))
    monkeypatch.chdir(tmp_path / "takes")
    job, = plan_batch(find_takes(["T1"]), load_pipeline("../pipelines/blobs.json"))
    assert job.outputs == {"cara": str(tmp_path / "takes" / "T1" / "T1_b.cara")}
    assert job.input == str(tmp_path / "takes" / "T1" / "T1_0.pico")


def test_progress_is_a_bar_on_a_terminal_and_lines_otherwise():
    import io

    from carapost.api.batch import TakeResult
    from carapost.batch_cli import ProgressBar

    results = [TakeResult("A", "/d/A_0.pico", "skipped"), TakeResult("B", "/d/B_0.pico", "ok", seconds=2.5),
               TakeResult("C", "/d/C_0.pico", "failed", "open: not a .pico file: only 7 bytes")]
    plain, tty = io.StringIO(), io.StringIO()
    for stream, is_tty in ((plain, False), (tty, True)):
        bar = ProgressBar(stream, tty=is_tty)
        bar.start(2, 3)
        for i, r in enumerate(results, 1):
            bar.update(r, i, 3)
        bar.finish()
    assert plain.getvalue().splitlines() == [
        "batch: 3 takes, 2 to run, 1 up to date", "[1/3] up to date A", "[2/3] done B (2.5 s)",
        "[3/3] FAILED /d/C_0.pico: open: not a .pico file: only 7 bytes"]
    assert "\x1b" not in plain.getvalue() and "\r" not in plain.getvalue()
    shown = tty.getvalue()
    assert "up to date A" not in shown                       # counted on the first line instead
    assert "[####################..........] 2/3 takes" in shown
    assert "[##############################] 3/3 takes, 1 failed" in shown
