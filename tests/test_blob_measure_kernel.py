"""The compiled blob-detection kernels compute what the numpy implementations they replaced computed.

References (test-only): ``tests/blob_measure_reference.py`` (the centre and ellipse
measurement, vectorised numpy, float32 as shipped or float64) and
``tests/blob_features_reference.py`` (noise estimate, DoG maxima, stage-1 features,
greedy suppression).
"""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from blob_features_reference import (candidates_reference, features_reference, fit_features_reference, greedy_nms_reference,
                                     maxima_reference, noise_sigma_reference, subpixel_reference)
from blob_measure_reference import extract, measure_reference
from carapost.core.blobs import candidate_kernel as ck
from carapost.core.blobs import centre
from carapost.core.blobs import detector as det
from carapost.core.blobs import features as fe
from carapost.core.blobs.detector import _dedupe, _suppress, as_grey_u8, find_candidates
from carapost.core.blobs.synth import disc_image, render, sample_frames


@pytest.fixture(scope="module")
def frames():
    """One sample-take frame per colour (camera 0, seed 0) and one cluttered synthetic frame per colour."""
    out = []
    for white in (False, True):
        out.append((white, sample_frames(white, seed=0, frames=1)[0].image))
        rng = np.random.default_rng([11, int(white)])
        out.append((white, render(rng, 360, 640, markers=40, white=white, radius=(2.0, 12.0), noise=(1.0, 4.0),
                                  confusers=8).image))
    return out


def _windows(white, image):
    """Every candidate's window (not only the ones stage 1 passes: they include the degenerate ones)."""
    cand, bright = find_candidates(as_grey_u8(image), white, 4.0, 50.0)
    hp = centre.WINDOWS[-1]
    pad = cv2.copyMakeBorder(bright, hp, hp, hp, hp, cv2.BORDER_REPLICATE)
    h, w = bright.shape
    ix = np.clip(np.rint(cand.x).astype(np.int64), 0, w - 1) + hp
    iy = np.clip(np.rint(cand.y).astype(np.int64), 0, h - 1) + hp
    r = np.maximum(cand.radius, 1.0)
    return pad, ix, iy, r, centre.window_for(r), cand.noise


def _compare(ref, new, centre_tol, extra_tol, only=None):
    """``new`` (the kernel's) against ``ref`` (numpy float64) on the windows ``only`` (bool; all by default).

    The kernel sums in float32 (relative errors ~1e-6 of each sum): geometry to ``centre_tol`` px, the
    stage-2 measurements to ``extra_tol`` relative or absolute (``core_std`` of a saturated core is a
    difference of two near-equal float32 sums: ~1e-4 where numpy's is 0).
    """
    x, y, major, minor, angle, ok, extra = new
    sel = np.ones(len(x), bool) if only is None else only
    np.testing.assert_array_equal(ok[sel], ref[5][sel])
    for a, b in ((x, ref[0]), (y, ref[1]), (major, ref[2]), (minor, ref[3])):
        np.testing.assert_allclose(a[sel], b[sel], rtol=0, atol=centre_tol)
    dang = np.abs(angle[sel] - ref[4][sel]) % 180.0
    # The angle of a near-round blob is ill-defined: compared where the axes differ by a tenth.
    round_ = (ref[2][sel] - ref[3][sel]) < 0.1 * ref[2][sel]
    assert np.where(round_, 0.0, np.minimum(dang, 180.0 - dang)).max(initial=0) < 100 * centre_tol
    np.testing.assert_allclose(extra[sel], ref[6][sel], rtol=extra_tol, atol=extra_tol)


@pytest.mark.parametrize("passes", [3, 2])
def test_measure_equals_the_numpy_mathematics_on_every_blob(frames, passes):
    """Against the same mathematics in numpy float64, on every candidate whose contrast is over 10 noise.

    The kernel's per-pixel sums are float32 (1.7x faster than float64; docs/blobs-history.md, "Session 30"),
    its solves float64.  On the sample takes' frames every such window agrees: centres to 2e-4 px
    (measured 1.3e-4).  On the cluttered frames a few windows hold two blobs or a blob and a confuser,
    whose systems are ill-conditioned, and a ring pixel at the edge of the plane's ring flips with a
    centre 1e-5 px away: there 99 % agree to 5e-3 px and all to 0.05 px (measured 2.2e-3 and 0.026),
    and ``ok`` on 99 %.  Windows of noise with one or two gradient lines (degenerate systems, decided by the
    rounding as they were by the float32 numpy version) are not compared.
    """
    n = 0
    cluttered = []
    for i, (white, image) in enumerate(frames):
        pad, ix, iy, r, win, noise = _windows(white, image)
        new = centre.measure_at(pad, ix, iy, win, r, noise, passes)
        for hw in np.unique(win):
            k = np.flatnonzero(win == hw)
            ref = measure_reference(extract(pad, ix[k], iy[k], hw), r[k], noise, passes, dtype=np.float64)
            blob = ref[6][:, 0] > 10 * noise
            mine = tuple(v[k] for v in new)
            if i % 2 == 0:                  # a sample take's frame (the fixture's order)
                _compare(ref, mine, 2e-4, 1e-3, blob)
                n += int(blob.sum())
            else:
                both = blob & ref[5] & mine[5]
                cluttered.append((int(blob.sum()), int((mine[5] != ref[5])[blob].sum()),
                                  np.hypot(mine[0] - ref[0], mine[1] - ref[1])[both]))
    assert n > 800
    total, flipped = sum(c[0] for c in cluttered), sum(c[1] for c in cluttered)
    d = np.concatenate([c[2] for c in cluttered])
    assert total > 300 and flipped <= 0.01 * total
    assert np.percentile(d, 99) < 5e-3 and d.max() < 0.05


def test_measure_matches_the_float32_version_on_real_blobs(frames):
    """The shipped numpy version summed float32: on blobs (contrast > 10 noise) centres agree to 1e-4 px.

    Its float32 sums of ~1000 products of 1e2-1e4 carry relative errors of ~1e-6;
    measured: at most 4e-5 px.  (On windows of pure noise with one or two
    gradient lines it decided the lines' degenerate systems by its rounding,
    so those are not compared.)
    """
    white, image = frames[0]
    pad, ix, iy, r, win, noise = _windows(white, image)
    new = centre.measure_at(pad, ix, iy, win, r, noise, 3)
    compared = 0
    for hw in np.unique(win):
        k = np.flatnonzero(win == hw)
        ref = measure_reference(extract(pad, ix[k], iy[k], hw), r[k], noise, 3)
        # A blob at the window's centre (by the float64 mathematics: where the answer wanders off to a
        # neighbour at the window's edge, both float32 versions are decided by their rounding).
        blob = measure_reference(extract(pad, ix[k], iy[k], hw), r[k], noise, 3, dtype=np.float64)[6][:, 0] > 10 * noise
        good = ref[5] & new[5][k] & blob
        d = np.hypot(ref[0] - new[0][k], ref[1] - new[1][k])[good]
        assert d.max(initial=0) < 1e-4
        compared += int(good.sum())
    assert compared > 100


def test_measure_on_isolated_discs_and_the_patch_interface():
    rng = np.random.default_rng(3)
    patches, truth = [], []
    for radius in (1.5, 3.0, 6.0):
        for _ in range(8):
            img, c = disc_image(rng, 21, radius, 1.0, 80.0, 60.0, 2.0, dark=False)
            patches.append(img[:, :].astype(np.float32))
            truth.append((c[0] - 10, c[1] - 10))
    P = np.stack(patches)
    r0 = np.repeat([1.5, 3.0, 6.0], 8)
    new = centre.measure(P, r0, 2.0)
    _compare(measure_reference(P, r0, 2.0, dtype=np.float64), new, 2e-4, 1e-3)
    assert new[5].all()
    err = np.hypot(new[0] - np.array(truth)[:, 0], new[1] - np.array(truth)[:, 1])
    assert np.median(err) < 0.1


def test_measure_refuses_windows_outside_the_image():
    img = np.zeros((40, 40), np.uint8)
    with pytest.raises(ValueError, match="outside"):
        centre.measure_at(img, np.array([3]), np.array([20]), np.array([5]), np.array([2.0]), 1.0)
    with pytest.raises(ValueError, match="5 px"):
        centre.measure_at(img, np.array([20]), np.array([20]), np.array([1]), np.array([2.0]), 1.0)
    assert all(len(v) == 0 for v in centre.measure_at(img, np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), 1.0))


def test_candidates_features_and_noise_equal_the_numpy_versions(frames):
    checked = 0
    work = fe.Workspace()
    for white, image in frames:
        img = as_grey_u8(image)
        assert fe.noise_sigma(img) == noise_sigma_reference(img)
        bright = img if white else cv2.bitwise_not(img)
        for level, lvl in fe.pyramid(bright, 4).items():
            padded = cv2.copyMakeBorder(lvl, 5, 5, 5, 5, cv2.BORDER_REPLICATE).astype(np.float32)
            np.testing.assert_array_equal(fe.padded_level(lvl, 5), padded)
            np.testing.assert_array_equal(fe.padded_level(lvl, 5, work, level), padded)
            for floor in (0.6, 3.0):
                got, want = fe.candidates(padded, floor), candidates_reference(padded, floor)
                for a, b in zip(got, want):
                    np.testing.assert_array_equal(a, b)
                # The same in a workspace's arrays.
                for a, b in zip(fe.candidates(padded, floor, work, level), got):
                    np.testing.assert_array_equal(a, b)
            ys, xs, v, g, _, _ = got
            F = fe.features(padded, g, ys, xs, v, level, 2.0)
            # float64 input makes the numpy version's sums exact enough to compare closely.
            F64 = features_reference(padded.astype(np.float64), g.astype(np.float64), ys, xs, v.astype(np.float64),
                                     level, 2.0)
            np.testing.assert_allclose(F, F64.astype(np.float32), rtol=2e-6, atol=2e-6)
            checked += len(ys)
    assert checked > 2000


def test_dog_peaks_of_a_plateau_keep_every_pixel():
    # A plateau above the floor is all maxima: far more than the kernel's first allocation.
    g = np.full((60, 80), 5.0, np.float32)
    s = np.zeros_like(g)
    s[30, 40] = 1.0                                     # one dip: its 8 neighbours stay maxima
    ys, xs, v, ox, oy = ck.dog_peaks(g, s, np.float32(0.6), 5)
    want = maxima_reference(g - s, np.float32(0.6), 5)
    np.testing.assert_array_equal(ys, want[0])
    np.testing.assert_array_equal(xs, want[1])
    assert len(ys) == 50 * 70 - 1 > 1024
    np.testing.assert_array_equal(v, (g - s)[ys, xs])
    for a, b in zip((ox, oy), subpixel_reference(g - s, ys, xs)):
        np.testing.assert_array_equal(a, b)
    assert [len(a) for a in ck.dog_peaks(g[:10], s[:10], np.float32(0.6), 5)] == [0] * 5


@pytest.mark.parametrize("width", [11, 12, 13, 17, 18, 21, 26, 29])
def test_dog_peaks_on_rows_of_every_length(width):
    # The search reads its row mask 8 pixels at a time: rows whose searched part is not a multiple of 8 long,
    # maxima in the last pixels searched and ties must come out as the numpy version's.
    rng = np.random.default_rng(width)
    g = rng.normal(0.0, 1.0, (23, width)).astype(np.float32)
    s = rng.normal(0.0, 0.3, (23, width)).astype(np.float32)
    g[6:9, width - 6:width - 3] = 3.0                   # a plateau: ties
    for border in (2, 3, 5):
        gb = g.copy()
        gb[15, width - border - 1] = 10.0               # a maximum in the last column searched
        ys, xs, v, ox, oy = ck.dog_peaks(gb, s, np.float32(0.2), border)
        want = maxima_reference(gb - s, np.float32(0.2), border)
        np.testing.assert_array_equal(ys, want[0])
        np.testing.assert_array_equal(xs, want[1])
        assert (15, width - border - 1) in zip(ys.tolist(), xs.tolist())
        np.testing.assert_array_equal(v, (gb - s)[ys, xs])
        for a, b in zip((ox, oy), subpixel_reference(gb - s, ys, xs)):
            np.testing.assert_array_equal(a, b)


def test_workspace_arrays_follow_the_image_size():
    work = fe.Workspace()
    a = work.image("x", (4, 5))
    assert work.image("x", (4, 5)) is a
    b = work.image("x", (6, 5))
    assert b.shape == (6, 5) and b.dtype == np.float32
    assert work.image("x", (6, 5), np.uint8).dtype == np.uint8
    # find_candidates on images of two sizes in one thread: each as with nothing reused.
    for shape in ((200, 300), (120, 160), (200, 300)):
        img = render(np.random.default_rng(shape[0]), *shape, markers=10, white=False, radius=(2.0, 6.0),
                     noise=(1.0, 2.0), confusers=2).image
        reused, _ = find_candidates(img, False, 4.0, 50.0)
        saved, fe._local.workspace = fe.workspace(), fe.Workspace()
        try:
            fresh, _ = find_candidates(img, False, 4.0, 50.0)
        finally:
            fe._local.workspace = saved
        assert len(reused.x) > 5
        np.testing.assert_array_equal(reused.feats, fresh.feats)
        np.testing.assert_array_equal(reused.x, fresh.x)


def test_noise_estimate_of_tiny_and_flat_images():
    assert fe.noise_sigma(np.zeros((3, 1), np.uint8)) == noise_sigma_reference(np.zeros((3, 1), np.uint8)) == 1.0
    flat = np.full((20, 20), 7, np.uint8)
    assert fe.noise_sigma(flat) == noise_sigma_reference(flat) == 0.5


def test_suppression_equals_the_pairwise_version():
    rng = np.random.default_rng(5)
    for n in (0, 1, 2, 50, 400):
        x, y = rng.uniform(0, 60, n), rng.uniform(0, 40, n)
        rad = rng.uniform(0.5, 6, n)
        score = np.round(rng.uniform(0, 1, n), 1)          # ties: the stable order decides

        def near(i, j, d):
            return d < np.minimum(rad[i], rad[j]) + 1.0
        near.reach = float(rad.max()) + 1.0 if n else 1.0
        np.testing.assert_array_equal(_suppress(x, y, rad, score),
                                      greedy_nms_reference(np.stack([x, y], 1), score, near))
        r2 = np.maximum(2.0, 0.5 * rad)

        def same(i, j, d):
            return d < np.maximum(r2[i], r2[j])
        same.reach = float(r2.max()) if n else 1.0
        np.testing.assert_array_equal(_dedupe(x, y, rad, score), greedy_nms_reference(np.stack([x, y], 1), score, same))


def test_detections_equal_those_of_the_numpy_paths(frames, monkeypatch):
    """The whole detector with the kernels and with every numpy version: the same detections."""
    def measure_at_ref(img, ix, iy, win, r, noise, passes):
        out = [np.zeros(len(ix)) for _ in range(5)] + [np.zeros(len(ix), bool), np.zeros((len(ix), 9))]
        for hw in np.unique(win):
            k = np.flatnonzero(win == hw)
            for i, v in enumerate(measure_reference(extract(img, ix[k], iy[k], hw), r[k], noise, passes)):
                out[i][k] = v
        return tuple(out)

    def fit_round_ref(img, cx, cy, rr, todo, noise, passes, windows, border, c, out, ok, extra, again):
        # fit_candidates' numpy glue before it was compiled (measure_kernel.fit_round), on a padded copy.
        h, w = img.shape
        hp = centre.WINDOWS[-1]
        pad = cv2.copyMakeBorder(img, hp, hp, hp, hp, cv2.BORDER_REPLICATE)
        ix = np.clip(np.rint(cx[todo]).astype(np.int64), 0, w - 1)
        iy = np.clip(np.rint(cy[todo]).astype(np.int64), 0, h - 1)
        res = measure_at_ref(pad, ix + hp, iy + hp, centre.window_for(rr[todo]), rr[todo], noise, passes)
        out[0][todo], out[1][todo] = ix + res[0], iy + res[1]
        for i in (2, 3, 4):
            out[i][todo] = res[i]
        ok[todo] = res[5]
        extra[todo] = res[6]

    new = [det.detect(image, white=white) for white, image in frames]
    monkeypatch.setattr(det, "fit_round", fit_round_ref)
    monkeypatch.setattr(fe, "features", features_reference)
    monkeypatch.setattr(fe, "candidates", candidates_reference)
    monkeypatch.setattr(fe, "noise_sigma", noise_sigma_reference)
    monkeypatch.setattr(det, "_fit_features", fit_features_reference)
    old = [det.detect(image, white=white) for white, image in frames]
    assert sum(len(r) for r in new) > 200
    for a, b in zip(new, old):
        assert len(a) == len(b)
        np.testing.assert_allclose(a["x"], b["x"], atol=1e-3)
        np.testing.assert_allclose(a["y"], b["y"], atol=1e-3)
        # Stored as float16: paths 1e-6 apart may round to neighbouring float16 values (2**-10 apart, relative).
        np.testing.assert_allclose(a["major"], b["major"], rtol=2.0 ** -10, atol=1e-3)
        np.testing.assert_allclose(a["score"], b["score"], atol=1e-4)


def test_the_compiled_stage2_features_are_numpys_to_the_bit(frames, monkeypatch):
    """``measure_kernel.fit_features`` gives numpy's float32 features, NaN rows included (merged blobs)."""
    seen = []

    def record(cand, sel, logit1, x, y, major, minor, extra, rescued):
        F = fit_features_reference(cand, sel, logit1, x, y, major, minor, extra, rescued)
        seen.append((cand, sel, logit1, x.copy(), y.copy(), major.copy(), minor.copy(), extra.copy(),
                     np.asarray(rescued).copy(), F))
        return F

    monkeypatch.setattr(det, "_fit_features", record)
    for white, image in frames:
        det.detect(image, white=white)
    monkeypatch.undo()
    # Every feature clipped at both ends, NaN measurements, and the rescue flag flipped.
    cand, sel, logit1, x, y, major, minor, extra, rescued, _ = seen[0]
    rng = np.random.default_rng(5)
    case = (cand, sel, logit1 * 50, x, y, major * rng.uniform(0, 300, len(x)), minor,
            extra * rng.uniform(0, 40, extra.shape), ~rescued.astype(bool))
    case[7][::7] = np.nan
    seen.append(case + (fit_features_reference(*case),))
    rows = nan_rows = 0
    for cand, sel, logit1, x, y, major, minor, extra, rescued, F in seen:
        assert det._fit_features(cand, sel, logit1, x, y, major, minor, extra, rescued).tobytes() == F.tobytes()
        rows += len(F)
        nan_rows += int(np.isnan(extra).any(1).sum())
    assert rows > 500 and nan_rows > 10


def test_the_compiled_profile_radius_is_numpys_to_the_bit(frames):
    """``candidate_kernel.profile_radius`` (the candidates' radii) is ``features.profile_radius`` times 2^level."""
    rng = np.random.default_rng(2)
    F = rng.normal(0.4, 0.4, (20000, len(fe.FEATURE_NAMES))).astype(np.float32)
    F[::97, 2] = np.nan
    F[::89, 1] = np.nan
    level = rng.integers(1, 5, len(F)).astype(np.int8)
    cases = [(F, level)]
    for white, image in frames:
        cand, _ = find_candidates(as_grey_u8(image), white, 4.0, 50.0)
        cases.append((cand.feats, cand.level))
        assert cand.radius.tobytes() == (fe.profile_radius(cand.feats) * 2.0 ** cand.level).tobytes()
    for F, level in cases:
        out = np.empty(len(F))
        ck.profile_radius(F, level, out)
        assert out.tobytes() == (fe.profile_radius(F) * 2.0 ** level).tobytes()


def test_apart_finds_the_maxima_with_no_other_within_the_distance():
    rng = np.random.default_rng(4)
    width = 60
    for trial in range(20):
        # Maxima on a 40 x 60 level with offsets of up to half a pixel, a few on one pixel of the other list,
        # and the second list out of row-major order now and then (the strongest picked out of too many).
        n, n2 = int(rng.integers(0, 80)), int(rng.integers(0, 120))
        ys2, xs2 = rng.integers(5, 35, n2), rng.integers(5, 55, n2)
        ys, xs = rng.integers(5, 35, n), rng.integers(5, 55, n)
        if n and n2:
            k = min(n, n2) // 3
            ys[:k], xs[:k] = ys2[:k] + rng.integers(-1, 2, k), xs2[:k] + rng.integers(-1, 2, k)
        ox, oy = (rng.uniform(-0.5, 0.5, n).astype(np.float32) for _ in range(2))
        ox2, oy2 = (rng.uniform(-0.5, 0.5, n2).astype(np.float32) for _ in range(2))
        if trial % 2 == 0:
            order = np.lexsort((xs2, ys2))
            ys2, xs2, ox2, oy2 = ys2[order], xs2[order], ox2[order], oy2[order]
        for r in (0.3, 0.5, 1.0):
            got = ck.apart(ys, xs, ox, oy, ys2, xs2, ox2, oy2, width, r)
            d = np.hypot((ys + oy.astype(np.float64))[:, None] - (ys2 + oy2.astype(np.float64))[None],
                         (xs + ox.astype(np.float64))[:, None] - (xs2 + ox2.astype(np.float64))[None])
            want = (d > r).all(1) if n2 else np.ones(n, bool)
            np.testing.assert_array_equal(got, want)
