"""The perspective offset of a round dot's image, and the brim solves that take it off (session 24)."""
import numpy as np
import pytest

from carapost.core.brim import Brim, brim_image_offsets
from carapost.core.calib.brim_solve import solve_calibration_brim
from carapost.core.calib.seeds import apply_seeds
from carapost.core.calib.synthetic import make_scene
from carapost.core.camera import Camera
from carapost.core.disc_image import disc_image_offsets, outline_moments, plane_axes
from carapost.core.tracking import track
from carapost.core.tracking.geometry import RigState
from carapost.core.tracking.synthetic_take import initialise, make_take
from carapost.io.brim_svg import brim_to_svg, read_brim_svg


def _tilted(deg):
    th = np.radians(deg)
    return np.array([0.0, np.sin(th), -np.cos(th)])


def test_offset_of_a_tilted_disc_matches_the_closed_form_and_a_fine_outline():
    cam = Camera(focal_length=1400.0, principal_point=np.array([640.0, 360.0]))
    X = np.array([[0.0, 0.0, 120.0], [10.0, -5.0, 90.0]])
    fine = disc_image_offsets(cam.project, X, 1.75, _tilted(50), n=1024)
    off = disc_image_offsets(cam.project, X, 1.75, _tilted(50))
    assert np.allclose(off, fine, rtol=3e-3, atol=1e-5)
    # On the axis: a**2 sin(2 theta) / (2 f), towards the nearer side (here -y), nothing across it.
    a = 1400 * 1.75 / 120
    assert fine[0, 1] == pytest.approx(-a * a * np.sin(np.radians(100)) / 2800, rel=0.01)
    assert abs(fine[0, 0]) < 1e-9
    # Seen square-on, or of no size, a dot's image is centred on its centre's.
    assert np.allclose(disc_image_offsets(cam.project, X[:1], 1.75, (0, 0, 1)), 0, atol=1e-9)
    assert np.all(disc_image_offsets(cam.project, X, [0.0, 0.0], _tilted(50)) == 0)


def test_outline_moments_give_the_ellipse_of_an_affine_view():
    # Far away the image is the ellipse of semi-axes f r / Z and f r cos / Z, still a**2 sin(2 theta) / 2f off.
    cam = Camera(focal_length=1000.0, principal_point=np.array([640.0, 360.0]))
    X = np.array([[0.0, 0.0, 5000.0]])
    e0, e1 = plane_axes(_tilted(60))
    c, cov = outline_moments(cam.project, X, [50.0], e0, e1, n=256, second=True)
    semi = 2 * np.sqrt(np.linalg.eigvalsh(cov[0]))[::-1]
    assert semi == pytest.approx([10.0, 5.0], rel=2e-3)
    assert np.allclose(c[0], [640.0, 360.0 - 100 * np.sin(np.radians(120)) / 2000], atol=2e-4)


def test_offsets_under_a_rig_are_each_cameras():
    sc = make_scene(20, frames=1, seed=3)
    rig = RigState(sc.cameras[0])
    X = sc.brim.markers
    both = disc_image_offsets(rig.project, X, 2.0)
    assert both.shape == (len(X), 4, 2)
    for s, cam in enumerate(sc.cameras[0]):
        # The rig projects to corrected pixels: each camera's offsets in those.
        one = disc_image_offsets(lambda P, cam=cam: cam.correct(cam.project(P)), X, 2.0)
        assert np.abs(both[:, s] - one).max() < 1e-4
        # In raw pixels the wide lens's distortion stretches them by up to a sixth at the image's edges.
        raw = disc_image_offsets(cam.project, X, 2.0)
        assert np.abs(raw - one).max() < 0.2 * np.abs(raw).max()
    assert np.abs(both).max() > 0.05


def test_the_brim_svg_gives_its_dots_radii(tmp_path):
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 100 100"><g transform="scale(2)">'
           '<circle cx="1" cy="1" r="1.5"/><circle cx="10" cy="1" r="1.5"/><circle cx="1" cy="10" r="1"/></g>'
           '<circle cx="40" cy="40" r="3"/></svg>')
    (tmp_path / "b.svg").write_text(svg)
    b = read_brim_svg(tmp_path / "b.svg")
    assert b.radius.tolist() == [3.0, 3.0, 2.0, 3.0]
    again = Brim.from_json(b.to_json())
    assert again.radius.tolist() == b.radius.tolist()
    # A project written before radii were kept: none known, so no offsets.
    old = {k: v for k, v in b.to_json().items() if k != "radius"}
    assert np.all(Brim.from_json(old).radius == 0)
    (tmp_path / "c.svg").write_text(brim_to_svg(b))
    assert read_brim_svg(tmp_path / "c.svg").radius.tolist() == b.radius.tolist()
    with pytest.raises(ValueError):
        Brim("x", np.zeros((3, 3)), radius=[1.0, 2.0])


def _centre_err(cameras, truth):
    return max(np.linalg.norm(a.position - b.position) for a, b in zip(cameras, truth))


def test_solve_calibration_brim_takes_the_offsets_off():
    errs = {}
    for known in (True, False):
        sc = make_scene(35, frames=1, seed=4, noise=0.01, brim_radius=3.0)
        pr = sc.project
        if not known:
            pr.brim = Brim("synthetic", sc.brim.markers)
        apply_seeds(pr, sc.seeds(n_brim=4), parts=("brim",)).do(pr)
        cmd = solve_calibration_brim(pr, 0)
        errs[known] = _centre_err(cmd.solution.cameras, sc.cameras[0])
        # The reported error is of the detections less their offsets: with the offsets known, the noise.
        if known:
            assert cmd.solution.rms < 0.03
            off = brim_image_offsets(cmd.solution.cameras, pr.brim)
            assert np.abs(off).max() > 0.2
    assert errs[True] < 0.5 * errs[False]
    assert errs[True] < 0.05


def test_tracking_solves_each_frames_cameras_without_the_offsets():
    errs = {}
    for known in (True, False):
        sc = make_take(35, 8, seed=4, noise=0.01, brim_radius=3.0, jaw_mm=0.0, blinks=0, occlusion_rate=0.0,
                       hidden_markers=0, slips=0)
        if not known:
            sc.project.brim = Brim("synthetic", sc.brim.markers)
        initialise(sc, 0)
        track(sc.project, 0, 1).do(sc.project)
        errs[known] = np.mean([_centre_err(sc.project.rig.cameras_at(f), sc.cameras[f]) for f in range(1, 8)])
    assert errs[True] < 0.5 * errs[False]
