"""Faint thin black dots in the shade, measured as an elliptical Gaussian on a plane (detector._thin_lines)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from carapost.core.blobs import detector
from carapost.core.blobs.gauss_kernel import fit_gaussians
from support import area_mean, supersampled_dot

pytestmark = pytest.mark.usefixtures("steps_1_to_8")


def _line_on_shade(rng, angle, depth=30.0, semi=(3.5, 0.6), size=41, noise=2.0):
    """A thin dark dot (edge-on paint) on skin whose shade slopes and curves, inverted (blobs bright) as the
    detector sees it.

    Exact area coverage (8x8 supersampling), blur 0.8 px, ``noise`` grey levels. Returns the image and the true
    centre.
    """
    xx, yy, dot, c = supersampled_dot(rng, size, angle, semi)
    skin = 40.0 + 2.5 * (yy - c[1]) + 0.01 * ((xx - c[0]) ** 2 + (yy - c[1]) ** 2)   # the chin's underside
    img = cv2.GaussianBlur(area_mean(skin - depth * dot), (0, 0), 0.8) + rng.normal(0, noise, (size, size))
    return 255 - np.clip(np.rint(img), 0, 255).astype(np.uint8), c


def _fit(img, start, half=8):
    out = np.empty((1, 8))
    fit_gaussians(img, np.array([start[0]]), np.array([start[1]]), np.array([half]), out)
    cov = np.array([[out[0, 2], out[0, 4]], [out[0, 4], out[0, 3]]])
    w, v = np.linalg.eigh(cov)
    return out[0], np.sqrt(w), v[:, 1]


@pytest.mark.parametrize("angle", [0.0, 35.0, 90.0, 140.0])
def test_the_gaussian_fit_finds_a_thin_line_of_any_direction(angle):
    rng = np.random.default_rng(int(angle))
    direction = [np.cos(np.deg2rad(angle)), np.sin(np.deg2rad(angle))]
    # Without noise: the line's centre (to a tenth of a pixel: the grey levels' rounding, the shade's curve), its
    # direction, about a pixel across (a 1.2 px stroke blurred by 0.8 px: 0.9-1.0).
    img, c = _line_on_shade(rng, angle, noise=0.0)
    out, sd, major = _fit(img, c + [0.6, -0.5])
    assert out[7] == 1.0 and out[5] > 10
    assert np.hypot(out[0] - c[0], out[1] - c[1]) < 0.1
    assert abs(major @ direction) > 0.99 and sd[0] < 1.1 and sd[1] > 1.5 * sd[0]


def test_the_gaussian_fit_is_the_least_squares_optimum():
    from scipy.optimize import least_squares

    rng = np.random.default_rng(5)
    for angle in (10.0, 60.0, 125.0):
        img, c = _line_on_shade(rng, angle)
        start = c + rng.uniform(-0.8, 0.8, 2)            # where a round measurement might have put it
        out, _, _ = _fit(img, start)
        assert out[7] == 1.0
        x0, y0 = int(round(start[0])) - 8, int(round(start[1])) - 8
        win = img[y0:y0 + 17, x0:x0 + 17].astype(float)
        yy, xx = np.mgrid[y0:y0 + 17, x0:x0 + 17].astype(float)

        def residuals(p):
            cx, cy, a, b, cc, amp, b0, bx, by = p
            dx, dy = xx - cx, yy - cy
            g = np.exp(-0.5 * (a * dx * dx + 2 * b * dx * dy + cc * dy * dy))
            return (b0 + bx * dx + by * dy + amp * g - win).ravel()

        best = least_squares(residuals, [*start, 0.44, 0.0, 0.44, 10.0, np.median(win), 0.0, 0.0], method="lm")
        assert np.hypot(out[0] - best.x[0], out[1] - best.x[1]) < 0.01


def test_the_gaussian_fit_clips_its_window_at_the_border_and_finds_no_blob_in_noise():
    rng = np.random.default_rng(3)
    img, c = _line_on_shade(rng, 20.0, noise=0.0)
    cut = np.ascontiguousarray(img[:, 14:])              # the window reaches 1-2 px past the left border
    out, sd, _ = _fit(cut, c - [14.0, 0.0])
    assert out[7] == 1.0 and np.hypot(out[0] + 14 - c[0], out[1] - c[1]) < 0.06 and sd[0] < 1.0
    flat = np.clip(100 + rng.normal(0, 2.0, (40, 40)), 0, 255).astype(np.uint8)
    out, _, _ = _fit(flat, (20.0, 20.0))
    # Noise has no bright Gaussian standing out of it: no fit, or one of no height.
    assert out[7] == 0.0 or out[5] < 6.0


@pytest.fixture(scope="module")
def chin_frames():
    from carapost.core.blobs.synth import sample_frames

    # Frame 40 of the benchmark's seed-1 take (bench_blobs.takes), cameras 0, 2 and 3: the chin's underside in shade.
    return sample_frames(False, seed=1, frames=3, step=40, cameras=(0, 2, 3))[3:6]


# (camera's index in chin_frames, marker): thin dots 6-7 px long and ~1 px across, 10-15 grey levels darker than the
# shade they lie in, measured 4.4-7.8 px across and 0.9-1.4 px off by step 3 and step 5 until session 35.  Since then
# three of them are found from their candidate's own edge first (the black fits stage 2 scores under 0.98 and those
# grown 1.3 times their candidate are looked at again: docs/blobs-history.md, "Session 35"), as lines 0.07-0.58 px
# off, and step 6 measures the fourth.
_THIN = [(0, "Chin_L_4"), (1, "Jaw_L_3"), (2, "Chin_R_4"), (2, "Cheek_L_11")]
_STEP6 = [(2, "Chin_R_4")]


def _nearest(rec, centre):
    d = np.hypot(rec["x"] - centre[0], rec["y"] - centre[1])
    j = int(np.argmin(d))
    return d[j], rec[j]


def test_faint_thin_dots_in_the_shade_are_measured_as_lines(chin_frames, monkeypatch):
    new = [detector.detect(s.image) for s in chin_frames]
    monkeypatch.setattr(detector, "THIN_FILL", -1.0)      # the measurement without it
    old = [detector.detect(s.image) for s in chin_frames]
    for cam, name in _THIN:
        s = chin_frames[cam]
        centre = s.centres[s.names.index(name)]
        d_new, r_new = _nearest(new[cam], centre)
        d_old, r_old = _nearest(old[cam], centre)
        assert d_new < 0.6 and r_new["minor"] < 3.5, name
        if (cam, name) in _STEP6:
            assert d_old > 0.85 and r_old["minor"] > 4.4 and d_new < 0.3, name
    # Nothing else moves: the same detections, the rest to the byte.
    for a, b in zip(new, old):
        assert len(a) == len(b)
        same = (a["x"] == b["x"]) & (a["y"] == b["y"])
        assert (~same).sum() <= 4
