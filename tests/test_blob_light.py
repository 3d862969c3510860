"""Step 8: black dots' centres taken back from the light's slope across them (docs/blobs.md)."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from carapost.core.blobs import detector
from carapost.core.blobs.light_kernel import light_slopes
from support import area_mean, supersampled_dot

pytestmark = pytest.mark.usefixtures("steps_1_to_8")


def _slopes(img, x, y, major, minor, angle):
    out = np.full((len(x), 2), np.nan)
    light_slopes(img, *(np.asarray(v, float) for v in (x, y, major, minor, angle)), out)
    return out


def test_the_light_slope_is_the_skin_plane_over_its_level_whatever_the_dot():
    yy, xx = np.mgrid[0:60, 0:80].astype(float)
    img = 100.0 + 2.0 * (xx - 40) - 1.0 * (yy - 30)
    img[27:34, 37:44] = 5.0                        # the dot (and its edge) is left out of the plane
    out = _slopes(img.astype(np.float32), [40.0, 2.0, 40.0], [30.0, 2.0, 30.0], [6.0, 6.0, 6.0], [6.0, 6.0, 6.0],
                  [0.0, 0.0, 0.0])
    np.testing.assert_allclose(out[0], [0.02, -0.01], atol=1e-9)
    # At the image's corner only the pixels inside it count, and the level is the plane's there.
    np.testing.assert_allclose(out[1], np.array([2.0, -1.0]) / (100.0 + 2.0 * (2 - 40) - (2 - 30)), atol=1e-9)
    # Too dark to be lit skin: no slope.
    out = _slopes(np.full((40, 40), 3.0, np.float32), [20.0], [20.0], [6.0], [6.0], [0.0])
    np.testing.assert_array_equal(out, 0.0)


def _lit_dot(rng, semi, angle, slope, skin=150.0, paint=10.0, size=61, blur=0.8, noise=0.0):
    """A black elliptical dot under light that rises ``slope`` (a share of its level a px) along its major axis."""
    xx, yy, mask, centre = supersampled_dot(rng, size, angle, semi)
    t = np.deg2rad(angle)
    light = 1.0 + slope * ((xx - centre[0]) * np.cos(t) + (yy - centre[1]) * np.sin(t))
    img = cv2.GaussianBlur(area_mean(light * np.where(mask, paint, skin)), (0, 0), blur)
    img = img + rng.normal(0.0, noise, img.shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), centre


def _pull(rng, semi, slope, n=12):
    """Mean offset of the detected centre from the true one towards the light, px, over ``n`` dots."""
    out = []
    for _ in range(n):
        angle = rng.uniform(0, 180)
        img, c = _lit_dot(rng, semi, angle, slope)
        r = detector.detect(img)
        j = np.argmin(np.hypot(r["x"] - c[0], r["y"] - c[1]))
        t = np.deg2rad(angle)
        out.append((r["x"][j] - c[0]) * np.cos(t) + (r["y"][j] - c[1]) * np.sin(t))
    return float(np.mean(out))


@pytest.mark.parametrize("semi", [(3.5, 2.0), (3.0, 3.0), (2.5, 1.0)])
def test_a_black_dot_is_no_longer_pulled_towards_the_light(semi, monkeypatch):
    # 3 % of the light's level a px along the dot: without step 8 the centre is 0.03-0.10 px towards the light
    # (a^2/4 * 0.03: 0.05-0.09); with it 0.01-0.03 px either way.
    monkeypatch.setattr(detector, "LIGHT_UPTO", 0.0)
    before = _pull(np.random.default_rng(4), semi, 0.03)
    monkeypatch.undo()
    after = _pull(np.random.default_rng(4), semi, 0.03)
    assert before > 0.025
    assert abs(after) < 0.4 * before


def test_without_a_light_slope_and_for_white_dots_the_centres_do_not_move(monkeypatch):
    rng = np.random.default_rng(5)
    flat = [_lit_dot(rng, (3.0, 2.0), a, 0.0, noise=1.0)[0] for a in (10.0, 70.0, 130.0)]
    lit = [255 - _lit_dot(rng, (3.0, 2.0), a, 0.03)[0] for a in (10.0, 70.0)]
    got = [detector.detect(im) for im in flat] + [detector.detect(im, white=True) for im in lit]
    monkeypatch.setattr(detector, "LIGHT_UPTO", 0.0)
    want = [detector.detect(im) for im in flat] + [detector.detect(im, white=True) for im in lit]
    for g, w in zip(got, want):
        assert len(g) == len(w) and len(g)
    # Flat light: only the noise's slope, a few thousandths of a px at most.
    for g, w in zip(got[:3], want[:3]):
        assert np.max(np.hypot(g["x"] - w["x"], g["y"] - w["y"])) < 0.01
    for g, w in zip(got[3:], want[3:]):
        assert g.tobytes() == w.tobytes()
