"""Solve Calibration Brim, seeds.json and per-frame camera solves on a synthetic take."""
import numpy as np
import pytest

from carapost.core.calib.brim_solve import solve_calibration_brim, solve_frame_cameras
from carapost.core.calib.pointinfo import distance_between_points, format_point_information, point_information
from carapost.core.calib.seeds import apply_seeds
from carapost.core.calib.synthetic import make_scene
from carapost.core.errors import CaraError


def _centre_err(project, scene, frame=0):
    return max(np.linalg.norm(a.position - b.position)
               for a, b in zip(project.rig.cameras_at(frame), scene.cameras[frame]))


def test_brim_solve_matches_every_marker_and_undoes():
    sc = make_scene(35, frames=2, seed=4)
    pr = sc.project
    d0 = pr.digest()
    seeds = sc.seeds(n_brim=4)
    c1 = apply_seeds(pr, seeds, parts=("brim",))
    assert pr.digest() == d0                     # building a command changes nothing
    c1.do(pr)
    c2 = solve_calibration_brim(pr, 0)
    c2.do(pr)
    sol = c2.solution
    assert np.all(sol.det == sc.brim_det[0].T)  # every visible marker, no mismatch
    assert sol.rms < 0.15
    assert _centre_err(pr, sc) < 0.3
    # The calibration pose now agrees with the solved frame.
    assert np.allclose(pr.rig.cameras[0].position, pr.rig.cameras_at(0)[0].position)
    # Another frame: cameras solved from its brim detections (brim points attached there).
    pts = {p.brim_index: p for p in pr.points.values() if p.kind == "brim"}
    for m in range(4):
        for s in range(4):
            d = sc.brim_det[1, s, m]
            rec = pr.detections[s].frame(1)[d]
            p = pts[m]
            p.src[1, s], p.det[1, s], p.uv[1, s] = 1, d, (rec["x"], rec["y"])
    c3 = solve_frame_cameras(pr, 1)
    c3.do(pr)
    assert _centre_err(pr, sc, 1) < 0.3
    for c in (c3,):
        c.undo(pr)
    for m in range(4):
        pts[m].src[1] = 0
        pts[m].det[1] = -1
        pts[m].uv[1] = np.nan
    c2.undo(pr)
    c1.undo(pr)
    assert pr.digest() == d0


def test_brim_failures_leave_project_unchanged():
    sc = make_scene(35, seed=5)
    pr = sc.project
    seeds = sc.seeds(n_brim=3)
    apply_seeds(pr, seeds, parts=("brim",)).do(pr)
    d0 = pr.digest()
    with pytest.raises(CaraError, match="4 or more brim markers"):
        solve_calibration_brim(pr, 0)
    assert pr.digest() == d0
    # A brim that does not fit: markers scrambled.
    sc = make_scene(35, seed=6)
    pr = sc.project
    apply_seeds(pr, sc.seeds(n_brim=6), parts=("brim",)).do(pr)
    pr.brim.markers = pr.brim.markers[::-1].copy() * 1.7
    d0 = pr.digest()
    with pytest.raises(CaraError, match="does not fit.*RMS"):
        solve_calibration_brim(pr, 0)
    assert pr.digest() == d0
    pr.rig = None
    with pytest.raises(CaraError, match="intrinsics"):
        solve_calibration_brim(pr, 0)


def test_seed_far_from_detections_is_named():
    sc = make_scene(35, seed=7)
    pr = sc.project
    seeds = sc.seeds()
    seeds["face"][2]["uv"]["1"] = [3.0, 3.0]
    seeds["face"][2]["label"] = "Nose_Tip"
    d0 = pr.digest()
    with pytest.raises(CaraError, match=r"face\[2\] \(Nose_Tip\).*channel 1"):
        apply_seeds(pr, seeds)
    assert pr.digest() == d0


def test_face_seeds_are_labelled_and_point_information():
    sc = make_scene(35, seed=8)
    pr = sc.project
    seeds = sc.seeds()
    for part in ("brim", "face"):
        cmd = apply_seeds(pr, seeds, parts=(part,))
        cmd.do(pr)
        if part == "brim":
            solve_calibration_brim(pr, 0).do(pr)
    a = pr.point_by_label("Seed_0")
    b = pr.point_by_label("Seed_1")
    assert a is not None and a.status[0] == 1
    info = point_information(pr, a.id, 0)
    assert info["sensors"][0]["major"] > 0 and set(info["caddy_distance"]) == {"0-1", "2-3"}
    assert 100 < info["all_cameras_distance"] < 250
    assert "Seed_0" in format_point_information(info)
    d = distance_between_points(pr, a.id, b.id, 0)
    assert d["units"] == "mm" and d["distance"] > 0


def test_a_seed_for_a_brim_marker_the_brim_lacks_names_it_and_changes_nothing():
    # Seeds written for another brim (``carapost sample``'s own brim.svg has 20 markers, the default v2.0
    # 19): the message says which seed, how many markers the brim has, and what to check.
    sc = make_scene(35, seed=4)
    pr = sc.project
    seeds = sc.seeds(n_brim=4)
    n = len(pr.brim)
    seeds["brim"][2]["index"] = n
    d0 = pr.digest()
    with pytest.raises(CaraError, match=rf"seed brim\[2\] \(brim marker {n}\): the calibration brim has {n} markers "
                                        rf"\(0-{n - 1}\); is it the brim the take was captured with\?"):
        apply_seeds(pr, seeds, parts=("brim",))
    assert pr.digest() == d0
    pr.brim = None
    with pytest.raises(CaraError, match=r"seed brim\[0\] .*: no calibration brim is set"):
        apply_seeds(pr, seeds, parts=("brim",))
