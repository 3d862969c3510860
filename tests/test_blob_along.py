"""Elongated dots placed along their major axis by their profile (detector._along_profiles, profile_kernel)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from carapost.core.blobs import detector
from carapost.core.blobs.profile_kernel import CORE_MIN, CORE_SHARE, STEP_ACROSS, STEP_ALONG, fit_profiles
from support import area_mean, supersampled_dot

pytestmark = pytest.mark.usefixtures("steps_1_to_8")


def _white_line(rng, angle, semi=(4.0, 0.8), height=40.0, size=41, noise=0.0, slope=3.0):
    """A white dot seen obliquely on skin whose light rises along the dot's axis, as a camera sees it.

    Exact area coverage, blur 0.8 px, ``noise`` grey levels; the skin rises ``slope`` grey levels a pixel along the
    axis and curves a little.  Returns the image, the true centre and the axis' direction.
    """
    xx, yy, dot, c = supersampled_dot(rng, size, angle, semi)
    u = np.array([np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))])
    t = (xx - c[0]) * u[0] + (yy - c[1]) * u[1]
    skin = 90.0 + slope * t + 0.02 * ((xx - c[0]) ** 2 + (yy - c[1]) ** 2)
    img = cv2.GaussianBlur(area_mean(skin + height * dot), (0, 0), 0.8) + rng.normal(0, noise, (size, size))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), c, u


def _fit(img, centre, angle, major=8.0, minor=3.0):
    out = np.empty((1, 6))
    fit_profiles(img, np.array([centre[0]]), np.array([centre[1]]), np.array([angle]), np.array([major]),
                 np.array([minor]), out)
    return out[0]


@pytest.mark.parametrize("angle", [0.0, 35.0, 90.0, 140.0])
def test_the_profile_fit_finds_the_middle_of_a_dot_measured_off_along_its_axis(angle):
    rng = np.random.default_rng(int(angle))
    img, c, u = _white_line(rng, angle)
    start = c + 0.7 * u                     # a measurement drawn along the axis towards the lit end
    out = _fit(img, start, angle)
    assert out[5] == 1.0 and out[3] > 12      # 40 grey levels, ~20 in the band about the blurred line
    middle = start + 0.5 * (out[0] + out[1]) * u
    # To a few hundredths of a pixel (the grey levels' rounding), and the segment about as long as the dot (8 px, a
    # blurred end's middle a little inside it).
    assert np.hypot(*(middle - c)) < 0.05
    assert 6.5 < out[1] - out[0] < 8.5 and out[2] < 1.5


def _profile(img, centre, angle, major, minor):
    """The kernel's profile, sampled in numpy (bilinear, as the kernel does inside the image)."""
    u = np.array([np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))])
    v = np.array([-u[1], u[0]])
    n = 2 * int(np.floor((0.5 * major + 4.0) / STEP_ALONG)) + 1
    t = (np.arange(n) - (n - 1) / 2) * STEP_ALONG
    k = int(np.floor(max(CORE_SHARE * minor, CORE_MIN) / STEP_ACROSS + 1e-9))
    s = np.arange(-k, k + 1) * STEP_ACROSS
    tt, ss = np.meshgrid(t, s)
    mx = (centre[0] + tt * u[0] + ss * v[0]).astype(np.float32)
    my = (centre[1] + tt * u[1] + ss * v[1]).astype(np.float32)
    return t, cv2.remap(img.astype(np.float32), mx, my, cv2.INTER_LINEAR).mean(0)


def test_the_profile_fit_is_the_least_squares_optimum():
    from scipy.optimize import least_squares
    from scipy.special import ndtr

    rng = np.random.default_rng(7)
    for angle in (15.0, 70.0, 120.0):
        img, c, u = _white_line(rng, angle, noise=2.0)
        start = c + rng.uniform(-0.8, 0.8) * u
        out = _fit(img, start, angle)
        assert out[5] == 1.0
        t, p = _profile(img, start, angle, 8.0, 3.0)

        def residuals(q):
            a, t1, t2, s, b0, b1 = q
            return a * (ndtr((t - t1) / s) - ndtr((t - t2) / s)) + b0 + b1 * t - p

        best = least_squares(residuals, [p.max() - p[0], -3.2, 3.2, 1.0, p[0], 0.0], method="lm")
        assert abs(0.5 * (out[0] + out[1]) - 0.5 * (best.x[1] + best.x[2])) < 0.01


def test_the_profile_fit_near_the_border_and_in_noise():
    rng = np.random.default_rng(3)
    img, c, u = _white_line(rng, 0.0)
    cut = np.ascontiguousarray(img[:, 14:])      # the profile reaches 1-2 px past the left border
    at = c - [14.0, 0.0]
    start = at + 0.5 * u
    out = _fit(cut, start, 0.0)
    # Past the border the samples repeat the edge's (a flat run the sloped background does not follow): 0.07 px.
    assert out[5] == 1.0 and np.hypot(*(start + 0.5 * (out[0] + out[1]) * u - at)) < 0.1
    flat = np.clip(100 + rng.normal(0, 2.0, (40, 40)), 0, 255).astype(np.uint8)
    out = _fit(flat, (20.0, 20.0), 30.0)
    # Noise has no segment standing out of it: no fit, or one of no height.
    assert out[5] == 0.0 or out[3] < 6.0


@pytest.fixture(scope="module")
def white_frames():
    from carapost.core.blobs.synth import sample_frames

    # Frame 40 of the white benchmark take's seed 1 (bench_blobs.takes), its four cameras.
    return sample_frames(True, seed=1, frames=2, step=40)[4:]


def _along_errors(frames):
    """Each hit's centre error along its measured major axis (px), and its minor/major ratio."""
    along, ratio = [], []
    for s in frames:
        rec = detector.detect(s.image, white=True)
        d = np.hypot(rec["x"][:, None] - s.centres[:, 0], rec["y"][:, None] - s.centres[:, 1])
        j = d.argmin(0)
        r = rec[j[d[j, np.arange(len(s.centres))] < 1.5]]
        e = np.stack([r["x"], r["y"]], 1) - s.centres[d[j, np.arange(len(s.centres))] < 1.5]
        a = np.deg2rad(r["angle"].astype(float))
        along.append(e[:, 0] * np.cos(a) + e[:, 1] * np.sin(a))
        ratio.append(r["minor"] / r["major"])
    return np.concatenate(along), np.concatenate(ratio)


def test_oblique_white_dots_are_placed_better_along_their_axis(white_frames, monkeypatch):
    new, ratio = _along_errors(white_frames)
    monkeypatch.setattr(detector, "ALONG_UPTO", 0.0)           # the detector without the step
    old, ratio_old = _along_errors(white_frames)
    assert len(new) == len(old) and (ratio == ratio_old).all()
    # The thin ones (minor under 0.45 of major; 24 dots): 0.31 px RMS along their axis without the step, 0.12 with.
    thin = ratio < 0.45
    assert thin.sum() >= 15
    rms_new, rms_old = np.sqrt(np.mean(new[thin] ** 2)), np.sqrt(np.mean(old[thin] ** 2))
    assert rms_new < 0.6 * rms_old, (rms_new, rms_old)
    # The rest no worse.
    assert np.sqrt(np.mean(new[~thin] ** 2)) < np.sqrt(np.mean(old[~thin] ** 2)) + 0.01


def test_round_dots_are_not_moved_and_the_step_moves_only_along(white_frames, monkeypatch):
    s = white_frames[1]
    upto = detector.ALONG_UPTO
    new = detector.detect(s.image, white=True)
    monkeypatch.setattr(detector, "ALONG_UPTO", 0.0)
    old = detector.detect(s.image, white=True)
    assert len(new) == len(old)
    # The records are sorted by position: pair each with its own (a move is under a pixel, the dots far apart).
    d = np.hypot(old["x"][:, None] - new["x"], old["y"][:, None] - new["y"])
    new = new[d.argmin(1)]
    assert len(set(d.argmin(1))) == len(old)
    ratio = old["minor"] / old["major"]
    moved = (new["x"] != old["x"]) | (new["y"] != old["y"])
    assert moved.any() and not moved[ratio >= upto].any()
    # Along the major axis only.
    a = np.deg2rad(old["angle"][moved].astype(float))
    dx, dy = (new["x"] - old["x"])[moved], (new["y"] - old["y"])[moved]
    assert np.abs(-dx * np.sin(a) + dy * np.cos(a)).max() < 1e-3
    assert (new["major"] == old["major"]).all() and (new["score"] == old["score"]).all()
