"""The centre from the dot's painted edge (carapost/core/blobs/edges.py), step 5 of blob detection."""
from __future__ import annotations

import cv2
import numpy as np
import pytest

from carapost.core.blobs import detect
from carapost.core.blobs.edges import refine_centres
from support import area_mean, supersampled_dot

pytestmark = pytest.mark.usefixtures("steps_1_to_8")


def _dot_beside_a_band(rng, gap=2.0, semi=(4.0, 2.5), angle=20.0, band=70.0, size=64):
    """A black elliptical dot on lit skin, a darker band (a lip line) ``gap`` px below its edge.

    Rendered with exact area coverage (8x8 supersampling), blur 0.8 px and noise 1 grey level.
    Returns the image and the true centre.
    """
    xx, yy, dot, c = supersampled_dot(rng, size, angle, semi)
    img = np.full(xx.shape, 170.0)
    img[yy > c[1] + semi[1] / np.cos(np.deg2rad(angle)) + gap] = band
    img[dot] = 15.0
    img = cv2.GaussianBlur(area_mean(img), (0, 0), 0.8) + rng.normal(0, 1.0, (size, size))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), c


def test_a_dark_band_beside_a_dot_does_not_pull_its_centre():
    # The intensity measurement alone is pulled 0.28 px (RMS) towards the band here; the edge is not.
    rng = np.random.default_rng(0)
    errs = []
    for _ in range(12):
        img, c = _dot_beside_a_band(rng)
        rec = detect(img)
        d = np.hypot(rec["x"] - c[0], rec["y"] - c[1])
        assert len(d) and d.min() < 1.0
        errs.append(d.min())
    assert np.sqrt(np.mean(np.square(errs))) < 0.12, errs


def test_refine_moves_a_wrong_centre_onto_the_edge_and_leaves_a_right_one():
    rng = np.random.default_rng(1)
    img, c = _dot_beside_a_band(rng, gap=6.0)
    bright = cv2.bitwise_not(img)
    # Started 0.6 px off (as a biased measurement would be), with the dot's true ellipse.
    x, y, used = refine_centres(bright, [c[0] + 0.6], [c[1] - 0.3], [8.0], [5.0], [20.0])
    assert used[0]
    assert np.hypot(x[0] - c[0], y[0] - c[1]) < 0.1
    # Started on the centre: the move is within the fit's own noise, so the centre stays.
    x2, y2, _ = refine_centres(bright, [c[0]], [c[1]], [8.0], [5.0], [20.0])
    assert np.hypot(x2[0] - c[0], y2[0] - c[1]) < 0.05


def test_a_centre_the_edge_moves_far_is_measured_from_the_edge_again(monkeypatch):
    """A dot measured together with the band beside it: the first ellipse is too large and 1.2-2 px off, so
    the rays cut the dot's edge obliquely and one pass leaves the centre 0.2-0.4 px off; a second pass from
    the edge's centre (``AGAIN``) takes it to ~0.1 px.  The kernel does what the numpy reference does."""
    import blob_edges_reference as reference

    one, two = [], []
    for off in ((1.2, 0.2), (1.6, -0.4), (2.0, 0.5)):
        img, c = _dot_beside_a_band(np.random.default_rng(1), gap=2.0)
        bright = cv2.bitwise_not(img)
        args = ([c[0] + off[0]], [c[1] + off[1]], [12.0], [7.0], [20.0])
        x, y, used = refine_centres(bright, *args)
        rx, ry, _ = reference.refine_centres(bright, *args)
        assert used[0] and abs(x[0] - rx[0]) < 1e-3 and abs(y[0] - ry[0]) < 1e-3
        two.append(np.hypot(x[0] - c[0], y[0] - c[1]))
        monkeypatch.setattr(reference, "AGAIN", 0.0)
        ox, oy, _ = reference.refine_centres(bright, *args)
        monkeypatch.undo()
        one.append(np.hypot(ox[0] - c[0], oy[0] - c[1]))
    assert max(two) < 0.12 and min(one) > 0.2, (one, two)


def _centre_rms(frames, white):
    """Centre RMS (px) of ``detect``'s hits on ``frames`` (SynthImage) and how many hits."""
    from carapost.core.blobs import detector
    from carapost.core.blobs.synth import match_truth

    e = []
    for s in frames:
        r = detector.detect(s.image, white=white)
        e.append(match_truth(np.stack([r["x"], r["y"]], 1), s)[2])
    e = np.concatenate(e)
    return np.sqrt((e ** 2).sum(1).mean()), len(e)


@pytest.mark.parametrize("white", [False, True])
def test_the_edge_is_trusted_sooner_on_textured_skin_and_not_on_a_flat_surround(monkeypatch, white):
    """On skin the intensity centre is pulled by the texture and shading around a dot: there (a surround
    varying more than TEXTURED times the noise) step 5 moves to the edge's centre from 2 standard errors of
    the fit instead of 8.  On sample frames that lowers the centre RMS; isolated discs on a flat background
    keep the full trust, so their centres (near the Cramér-Rao bound) do not change."""
    from carapost.core.blobs import detector
    from carapost.core.blobs.edges import TRUST
    from carapost.core.blobs.synth import disc_image, sample_frames

    frames = sample_frames(white, seed=0, frames=1)
    shipped, n1 = _centre_rms(frames, white)
    monkeypatch.setattr(detector, "_trust", lambda F: np.full(len(F), TRUST))
    before, n2 = _centre_rms(frames, white)
    monkeypatch.undo()
    assert n1 >= n2 > 400 and shipped < 0.97 * before, (shipped, before)
    rng = np.random.default_rng(3)
    for _ in range(20):
        img, _c = disc_image(rng, 48, 4.0, 1.0, 100.0, 60.0 if white else 200.0, 100.0 / 15, dark=not white)
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        cand, bright = detector.find_candidates(img, white, 4.0, 50.0)
        fitted = detector.fit_stage(cand, bright, detector.default_model(white))
        ok = np.flatnonzero(fitted.ok)
        assert (detector._trust(fitted.feats[ok]) == TRUST).all()


@pytest.mark.parametrize("white", [False, True])
def test_a_large_dot_whose_gradient_lines_miss_each_other_trusts_its_edge_sooner(monkeypatch, white):
    """Step 3's window about a large dot weighs a wide patch of skin, whose shading pulls the intensity centre
    even where the ring about the dot fits its plane: a dot longer than LARGE px whose gradient lines miss each
    other (LINES_APART) moves to its edge's centre from 2 standard errors, as a textured one does.  On generated
    large-dot frames that lowers the centre RMS; isolated large discs on a flat background, whose lines meet,
    keep the full trust."""
    from carapost.core.blobs import detector
    from carapost.core.blobs.edges import TRUST
    from carapost.core.blobs.synth import disc_image, render

    rng = np.random.default_rng([7, int(white)])
    frames = [render(rng, 720, 1280, markers=60, white=white, radius=(5.0, 24.0), noise=(1.0, 3.0), confusers=14)
              for _ in range(3)]

    shipped, n1 = _centre_rms(frames, white)
    monkeypatch.setattr(detector, "LARGE", np.inf)
    before, n2 = _centre_rms(frames, white)
    monkeypatch.undo()
    assert n1 == n2 > 120 and shipped < 0.97 * before, (shipped, before)
    for radius in (8.0, 12.0):
        for _ in range(10):
            img, c = disc_image(rng, 96, radius, 1.0, 100.0, 60.0 if white else 200.0, 100.0 / 15, dark=not white)
            img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
            cand, bright = detector.find_candidates(img, white, 4.0, 50.0)
            fitted = detector.fit_stage(cand, bright, detector.default_model(white))
            # The disc's own fit (not a fragment of its rim from a finer candidate).
            disc = np.flatnonzero(fitted.ok & (np.hypot(fitted.x - c[0], fitted.y - c[1]) < 0.5))
            assert len(disc) and (fitted.major[disc] > detector.LARGE).all()
            assert (detector._trust(fitted.feats[disc]) == TRUST).all()


def _found(frames, white):
    """Per (frame index, marker) that ``detect`` finds within 1.5 px: the detection's record and the true centre."""
    from scipy.spatial import cKDTree

    from carapost.core.blobs import detector

    out = {}
    for f, s in enumerate(frames):
        r = detector.detect(s.image, white=white)
        d, j = cKDTree(np.stack([r["x"], r["y"]], 1)).query(s.centres)
        out.update({(f, m): (r[j[m]], s.centres[m]) for m in np.flatnonzero(d <= 1.5)})
    return out


@pytest.mark.parametrize("white", [False, True])
def test_an_oblique_dots_centre_along_its_major_axis_averages_the_edge_and_the_intensity(monkeypatch, white):
    """The ends of an oblique dot's ellipse are sharp beside the blur, and shading and texture move them: along
    the major axis the edge's centre is no better than the intensity centre, and the two err independently
    enough that their average is better (across it the edge is much better, and is kept).  On the sample
    frames of seeds 1 and 2 the centre error of elongated dots (minor/major under ALONG_ROUND) along their
    major axis falls (measured: black 2 %, white 14 %), across it does not change, and round dots (the
    Cramér-Rao discs) are left as they were."""
    from carapost.core.blobs import detector
    from carapost.core.blobs.edges import ALONG_ROUND
    from carapost.core.blobs.synth import sample_frames

    refine = detector.refine_centres

    def errors(frames, along):
        """Per (frame, marker) found within 1.5 px: error along and across the major axis, minor/major."""
        monkeypatch.setattr(detector, "refine_centres", lambda *a, **kw: refine(*a, **{**kw, "along": along}))
        # Step 5 of the ellipses found from a candidate's edge (its own test, below) calls refine_centres too.
        monkeypatch.setattr(detector, "_refine_edge_ellipses", lambda bright, x, y, *a: (x, y))
        # Step 7 (the profile along the axis, its own test in test_blob_along.py) comes after and would take over.
        monkeypatch.setattr(detector, "ALONG_UPTO", 0.0)
        out = {}
        for k, (rec, truth) in _found(frames, white).items():
            e = np.array([rec["x"], rec["y"]], float) - truth
            t = np.radians(float(rec["angle"]))
            out[k] = (e[0] * np.cos(t) + e[1] * np.sin(t), -e[0] * np.sin(t) + e[1] * np.cos(t),
                      float(rec["minor"] / rec["major"]))
        monkeypatch.undo()
        return out

    frames = sample_frames(white, seed=1, frames=1) + sample_frames(white, seed=2, frames=1)
    before, after = errors(frames, False), errors(frames, True)
    keys = sorted(set(before) & set(after))
    b, a = np.array([before[k] for k in keys]), np.array([after[k] for k in keys])
    thin, round_ = b[:, 2] < ALONG_ROUND, b[:, 2] >= ALONG_ROUND
    assert len(keys) > 800 and thin.sum() > 400
    rms = lambda v: float(np.sqrt(np.mean(v ** 2)))
    assert rms(a[thin, 0]) < (0.9 if white else 0.99) * rms(b[thin, 0]), (rms(a[thin, 0]), rms(b[thin, 0]))
    assert abs(rms(a[thin, 1]) - rms(b[thin, 1])) < 1e-3, (rms(a[thin, 1]), rms(b[thin, 1]))
    assert rms(a[:, :2]) < rms(b[:, :2])
    assert np.allclose(a[round_, :2], b[round_, :2])


def test_step_5_measures_the_ellipses_found_from_a_candidates_edge_along_their_own_normals(monkeypatch):
    """An ellipse found from its candidate's edge (a dot the intensity fit drew off into what it touches) was
    where the candidate's circle of rays put it: those rays cut an elongated or off-centre dot's edge obliquely.
    Step 5 along the ellipse's own normals moves it when the move is short and a second pass confirms it.
    On the white benchmark frames (seeds 0-2) the from-edge hits' centre RMS falls by about 15 % (14.8 %, 0.401
    -> 0.342 px, on the frames drawn under perspective since session 24) and more of them improve than worsen; without the confirmation more of them end over 0.1 px worse (a dot whose step 5 ran
    onto the edge of what it touches)."""
    from carapost.core.blobs import detector
    from carapost.core.blobs.synth import sample_frames

    frames = [f for seed in (0, 1, 2) for f in sample_frames(True, seed=seed, frames=3)]

    def errors(**patch):
        """Per (frame, marker) found within 1.5 px: its distance from the truth."""
        for k, v in patch.items():
            monkeypatch.setattr(detector, k, v)
        out = {k: float(np.hypot(rec["x"] - truth[0], rec["y"] - truth[1]))
               for k, (rec, truth) in _found(frames, True).items()}
        monkeypatch.undo()
        return out

    before = errors(_refine_edge_ellipses=lambda bright, x, y, *a: (x, y))
    after, unconfirmed = errors(), errors(EDGE_CONVERGE=np.inf)
    keys = [k for k in before if k in after and k in unconfirmed
            and (abs(after[k] - before[k]) > 1e-6 or abs(unconfirmed[k] - before[k]) > 1e-6)]
    b, a, u = (np.array([e[k] for k in keys]) for e in (before, after, unconfirmed))
    assert len(keys) > 20 and len(after) >= len(before) - 1
    rms = lambda v: float(np.sqrt(np.mean(v ** 2)))
    assert rms(a) < 0.87 * rms(b), (rms(a), rms(b))
    assert np.count_nonzero(a < b - 1e-6) > 1.5 * np.count_nonzero(a > b + 1e-6)
    assert np.count_nonzero(u - b > 0.1) > np.count_nonzero(a - b > 0.1)


def test_no_clean_edge_keeps_the_first_centre():
    flat = np.full((40, 40), 90, np.uint8)
    x, y, used = refine_centres(flat, [20.3], [19.6], [8.0], [8.0], [0.0])
    assert not used[0] and (x[0], y[0]) == (20.3, 19.6)
    x, y, used = refine_centres(flat, [], [], [], [], [])
    assert len(x) == len(y) == len(used) == 0


@pytest.mark.parametrize("flat", [False, True])
def test_the_kernel_computes_what_the_numpy_reference_does(flat):
    """The compiled step equals its numpy version (tests/blob_edges_reference.py) on sample-take frames,
    with and without the flat-paint test of black dots.

    The reference samples with cv2.remap, which rounds sample positions to 1/32 px, and the kernel's
    coarse search is bilinear: a ray whose two peaks are nearly equal may take the other one.
    """
    from blob_edges_reference import refine_centres as reference

    from carapost.core.blobs.detector import _trust, find_candidates, fit_stage
    from carapost.core.blobs.model import default_model
    from carapost.core.blobs.synth import sample_frames

    diffs, textured, kinds, along, moved = [], [], [], [], []
    for s in sample_frames(False, seed=1, frames=1, markers=35):
        cand, bright = find_candidates(s.image, False, 4.0, 50.0)
        # The fits as the comments below counted them (the orphan search of session 44 adds thin edge ellipses).
        fitted = fit_stage(cand, bright, default_model(False), orphans=False)
        model = default_model(False)
        keep = np.flatnonzero(fitted.ok & (model.stage2.predict(fitted.feats) >= 0.4))
        args = (fitted.x[keep], fitted.y[keep], fitted.major[keep], fitted.minor[keep], fitted.angle[keep],
                tuple(v[keep] for v in fitted.start))
        x1, y1, _ = refine_centres(bright, *args, flat=flat)
        x2, y2, _ = reference(bright, *args, flat=flat)
        diffs.append(np.hypot(x1 - x2, y1 - y2))
        # Each blob's trust as detect() sets it (by how textured its surround is).
        trust = _trust(fitted.feats[keep])
        kinds.append(trust)
        x1, y1, _ = refine_centres(bright, *args, flat=flat, trust=trust)
        x2, y2, _ = reference(bright, *args, flat=flat, trust=trust)
        textured.append(np.hypot(x1 - x2, y1 - y2))
        x3, y3, _ = refine_centres(bright, *args, flat=flat, trust=trust, along=True)
        x4, y4, _ = reference(bright, *args, flat=flat, trust=trust, along=True)
        along.append(np.hypot(x3 - x4, y3 - y4))
        moved.append(np.hypot(x3 - x1, y3 - y1))
    d = np.concatenate(diffs)
    assert len(d) > 150
    # A few blobs of brow hair or shadow may have two near-equal edges per ray (2 of 255 on these frames with the
    # dots drawn centred on their projections, 4 of 252 drawn under perspective; 6 of 266 since session 35, whose
    # GROWN adds two ellipses found from a candidate's edge, 0.037 px each); the rest agree exactly.
    assert np.percentile(d, 97) < 1e-3 and np.count_nonzero(d > 0.01) <= 6, (np.percentile(d, 97), np.sort(d)[-7:])
    # With the lower trust of textured skin more blobs move to their edge, and the move's share rises from 0
    # to 1 between one and two noise levels of the fit (~0.02-0.04 px): the reference's sampling (1/32 px)
    # then shows in a few more centres, by hundredths of a pixel.
    d = np.concatenate(textured)
    assert len(np.unique(np.concatenate(kinds))) == 2
    # (Besides them, one of the two-edged blobs above, 0.13 px apart without the trust, is 0.19 px apart with it
    # on the frames drawn under perspective.)
    assert np.percentile(d, 95) < 1e-3 and np.count_nonzero(d > 0.06) <= 1, (np.percentile(d, 95), np.sort(d)[-3:])
    # detect()'s call: the per-blob trust and the average along elongated blobs' major axes.
    d = np.concatenate(along)
    assert np.percentile(d, 95) < 1e-3 and np.count_nonzero(d > 0.06) <= 1, (np.percentile(d, 95), np.sort(d)[-3:])
    assert np.count_nonzero(np.concatenate(moved) > 0.01) > 10


def test_a_lower_lip_dot_against_the_open_mouth_is_measured_on_its_own():
    """Frame 56 of the 120-frame sample take seed 1 (`carapost sample --seed 1 --markers 35`): the jaw is
    wide open and the lower lip's dots touch the mouth's darker shade.  Measured together with it they
    were 2.0-3.5 px off in cameras 1 and 3; their own edge, found from the candidate, puts the centre and
    right ones within a few tenths: 0.08-0.18 px with the dots drawn centred on their projections, 0.14-0.34 px
    drawn under perspective (session 24; the right one in camera 1 is 0.34 px off)."""
    from carapost.sample.render import leds_of, render_view
    from carapost.sample.scene import build_scene, frame_geometry, true_cameras

    sc = build_scene(markers=35, frames=120, seed=1)
    g = frame_geometry(sc, 56)
    cams = true_cameras(sc, 56)
    labels = list(sc.markers.labels)
    worst = 0.0
    for c in (1, 3):
        img, truth = render_view(sc, g, cams[c], c, 56, leds=leds_of(cams))
        rec = detect(img)
        for lab in ("Lip_Lower_C", "Lip_Lower_R"):
            u, v = truth.centre[labels.index(lab)]
            worst = max(worst, float(np.hypot(rec["x"] - u, rec["y"] - v).min()))
    assert worst < 0.4, worst



def _offset_of(white: bool, seed: int, camera: int, frame: int, name: str):
    """A function giving how far ``detect`` puts its nearest detection from marker ``name`` of a blob benchmark
    frame: ``sample_frames(white, seed=seed, frames=3)``'s frame ``frame`` (0, 40, 80: 0-2) in ``camera``."""
    from carapost.core.blobs.synth import sample_frames

    s = sample_frames(white, seed=seed, frames=3, cameras=(camera,))[frame]
    u, v = s.centres[s.names.index(name)]

    def off():
        rec = detect(s.image, white=white)
        return float(np.hypot(rec["x"] - u, rec["y"] - v).min())

    return off


def test_a_lip_dot_measured_with_the_band_under_it_is_looked_at_again_though_stage_2_believes_it(monkeypatch):
    """Frame 40 of the blob benchmark's held-out seed 5, camera 0: the lower lip's left dot touches the dark band
    under the lip.  Measured together with it (12.4 x 5.9 px, 1.32 px low) it holds its candidate and stage 2 scores
    it 0.94, so until session 35 (0.9 for black dots too) its candidate's own edge was never looked for; now every
    black fit stage 2 scores under 0.98 (``RESCUE_ABOVE_FLAT``) is looked at again, and the dot's own ellipse
    (12.8 x 2.95 px) puts it 0.07 px off."""
    from carapost.core.blobs import detector

    off = _offset_of(False, 5, 0, 1, "Lip_Lower_L")
    assert off() < 0.2
    monkeypatch.setattr(detector, "RESCUE_ABOVE_FLAT", 0.9)
    assert off() > 1.0


def test_a_mouth_corner_dot_grown_into_the_mouth_line_is_measured_from_its_own_edge(monkeypatch):
    """Frame 40 of the white benchmark's seed 1, camera 0: the left mouth corner's dot touches the dark line of the
    lips.  Measured from its candidate it takes in a little of the lit lip beside it (10.8 x 8.9 px, 0.62 px off,
    where the dot is 8.5 x 5.3): 1.4 times its candidate's radius, under the 1.5 that counted as grown until
    session 35, so its candidate's own edge was not looked for.  At 1.3 (``GROWN``) it is: 8.6 x 5.1 px, 0.05 px
    off."""
    from carapost.core.blobs import detector

    off = _offset_of(True, 1, 0, 1, "Mouth_Corner_L")
    assert off() < 0.15
    monkeypatch.setattr(detector, "GROWN", 1.5)
    assert off() > 0.5


def test_a_saturated_nose_tip_dot_moves_to_its_edge_centre_though_that_is_over_a_pixel_away(monkeypatch):
    """Frame 80 of the white benchmark's seed 2, camera 0: the saturated nose-tip dot on the nose's highlight.  Its
    ellipse, found from its candidate's edge, sits 1.27 px low; measured along its own normals the edge is centred
    on the dot, and a second pass from there confirms it.  Until session 35 a move over 1 px was refused
    (``EDGE_MOVE``); at 1.3 px it is taken: 0.04 px off."""
    from carapost.core.blobs import detector

    off = _offset_of(True, 2, 0, 2, "Nose_Tip")
    assert off() < 0.15
    monkeypatch.setattr(detector, "EDGE_MOVE", 1.0)
    assert off() > 1.0


def test_a_nose_tip_dot_on_the_shadow_under_the_nose_is_found_from_its_own_edge(monkeypatch):
    """Frame 2 of the 120-frame sample take seed 1 (the README's): in camera 0 the nose tip's thin dot sits
    on the upper edge of the shadow under the nose.  The intensity measurement from its candidate runs
    into the shadow and a second candidate may measure dot and shadow as one large blob; the dot's own
    edge, around its candidate, outlines it.  Cameras 1 and 3 see it clear of the shadow.  (The classifier
    retrained with jaw-open frames in session 6 scores such edge ellipses under the default threshold after
    the rescue's penalty: camera 0 is checked at 0.15, see docs/blobs.md.)  Until session 24 this was frame 0;
    with the dots drawn under perspective the other of the dot's two candidates wins the merge there and on
    frame 1, so no rescue is tried and the dot is missed in camera 0; frames 2-5 are rescued (0.23-0.43 px)."""
    from carapost.core.blobs import detector
    from carapost.sample.render import leds_of, render_view
    from carapost.sample.scene import build_scene, frame_geometry, true_cameras
    sc = build_scene(markers=35, frames=120, seed=1)
    g = frame_geometry(sc, 2)
    cams = true_cameras(sc, 2)
    k = list(sc.markers.labels).index("Nose_Tip")

    def error(c, threshold=0.4):
        img, truth = render_view(sc, g, cams[c], c, 2, leds=leds_of(cams))
        rec = detect(img, threshold=threshold)
        return float(np.hypot(rec["x"] - truth.centre[k, 0], rec["y"] - truth.centre[k, 1]).min())

    assert error(0, 0.15) < 0.5
    assert max(error(c) for c in (1, 3)) < 0.3
    # No edge search at all: neither the rescue's nor the orphan search's (its rows have the quality columns).
    monkeypatch.setattr(detector, "edge_ellipses",
                        lambda bright, x, *a, **kw: np.zeros((len(x), 10 if kw.get("quality") else 6)))
    assert error(0, 0.15) > 1.5


def _dot_under_a_hair_clump(rng, sector=90.0, size=48):
    """A black dot (semi-axes 4.5 x 4 px) touched over ``sector`` degrees by a clump of brow hair.

    The clump (grey 60 on skin 170; the dot is 20) reaches a ragged 7-10 px from the dot's centre: on
    the rays through it the hair's outer edge is steeper than the dot's own.  Returns the image and the
    dot's true centre.
    """
    ss = 8
    yy, xx = (np.mgrid[0:size * ss, 0:size * ss] + 0.5) / ss - 0.5
    cx, cy = size / 2 + rng.uniform(-0.5, 0.5), size / 2 + rng.uniform(-0.5, 0.5)
    img = np.full(xx.shape, 170.0)
    rel = (np.degrees(np.arctan2(yy - cy, xx - cx)) - rng.uniform(-180, 180) + 180) % 360 - 180
    reach = 8.5 + 1.5 * np.sin(np.deg2rad(rel) * 7 + rng.uniform(0, 6))
    img[(np.abs(rel) < sector / 2) & (np.hypot(xx - cx, yy - cy) < reach)] = 60.0
    img[((xx - cx) / 4.5) ** 2 + ((yy - cy) / 4.0) ** 2 <= 1] = 20.0
    img = img.reshape(size, ss, size, ss).mean((1, 3))
    img = cv2.GaussianBlur(img, (0, 0), 0.8) + rng.normal(0, 1.5, (size, size))
    return np.clip(np.rint(img), 0, 255).astype(np.uint8), np.array([cx, cy])


def test_an_edge_broken_by_hair_on_one_side_is_fitted_on_its_best_arc(monkeypatch):
    # The whole edge is not a clean ellipse (the rays through the clump find its outer edge); the
    # arc of 60 % of the rays that most edge points agree with is the dot's own outline.
    import blob_edges_reference as reference
    rng = np.random.default_rng(0)
    errs, whole_clean = [], []
    for _ in range(8):
        img, c = _dot_under_a_hair_clump(rng)
        bright = cv2.bitwise_not(img)
        start = (c[0] + 0.5, c[1] - 0.4)
        x, y, used = refine_centres(bright, [start[0]], [start[1]], [9.0], [8.0], [0.0])
        errs.append(np.hypot(x[0] - c[0], y[0] - c[1]))
        monkeypatch.setattr(reference, "ARCS", 0)
        gx, gy = reference._gradients(bright)
        whole = reference._fit_edges(gx, gy, np.array([start[0]]), np.array([start[1]]), np.array([4.5]),
                                     np.array([4.0]), np.zeros(1))
        whole_clean.append(bool(whole[2][0]))
        monkeypatch.undo()
    assert np.median(errs) < 0.1 and np.sum(np.array(errs) < 0.15) >= 6, errs
    assert sum(whole_clean) <= 2, whole_clean


def test_a_white_nose_tip_is_not_replaced_by_its_blob_with_the_nose_highlight():
    """Frame 0 of the white README take (`carapost sample --white --seed 1 --markers 35`), camera 3: the
    white nose-tip dot touches the nose's specular highlight.  The dot is found (11 x 5 px) and so is a
    29 x 19 px blob of dot and highlight around it, which scores as high; duplicate removal kept the big
    one, 6.4 px off.  A detection more than twice another's size around it is that dot measured with what
    it touches, and goes first.  (Since the classifier was retrained with jaw-open frames in session 6, it
    scores the big blob lower, so the rule is no longer what decides here: the next test checks the rule.)"""
    from carapost.sample.render import leds_of, render_view
    from carapost.sample.scene import build_scene, frame_geometry, true_cameras
    sc = build_scene(markers=35, frames=120, seed=1, white=True)
    g = frame_geometry(sc, 0)
    cams = true_cameras(sc, 0)
    k = list(sc.markers.labels).index("Nose_Tip")
    img, truth = render_view(sc, g, cams[3], 3, 0, leds=leds_of(cams))

    def error():
        rec = detect(img, white=True)
        return float(np.hypot(rec["x"] - truth.centre[k, 0], rec["y"] - truth.centre[k, 1]).min())

    assert error() < 0.5


def test_a_detection_twice_the_size_around_a_smaller_one_is_that_dot_with_what_it_touches():
    """The sizes of the white nose tip above (11 x 5 px) and its blob with the highlight (29 x 19 px, 3 px off)."""
    from carapost.core.blobs.detector import _engulfing

    x, y = np.array([100.0, 102.5, 200.0, 300.0, 301.0]), np.array([50.0, 51.5, 50.0, 50.0, 50.0])
    major, minor = np.array([11.0, 29.0, 10.0, 11.0, 20.0]), np.array([5.0, 19.0, 9.0, 5.0, 14.0])
    # The last pair: under twice the size, two fits of one blob (duplicate removal's case, not this rule's).
    assert list(_engulfing(x, y, major, minor)) == [False, True, False, False, False]
    # The dot 6.4 px off its blob with the highlight (0.67 of its minor semi-axis), as measured on the README take.
    assert list(_engulfing(np.array([0.0, 6.4]), np.zeros(2), np.array([29.0, 11.0]), np.array([19.0, 5.0]))) == [
        True, False]


def test_a_fragment_on_a_large_dots_rim_does_not_take_its_place():
    """A large dot (31 x 21 px) and a fragment of its rim found from a level-1 candidate (14 px, 10 px from its
    centre, 0.95 of its minor semi-axis): the dot is not the fragment measured with what it touches."""
    from carapost.core.blobs.detector import _engulfing

    got = _engulfing(np.array([0.0, 0.0]), np.array([0.0, 10.0]), np.array([31.0, 14.0]), np.array([21.0, 10.0]))
    assert list(got) == [False, False]


def test_a_black_dot_in_brow_hair_is_measured_from_its_painted_side(monkeypatch):
    """The README take (`carapost sample --seed 1 --markers 35`): Brow_L_1's black dot sits in brow hair a
    little lighter than its paint.  On the rays through the hair the steepest fall is the hair's outer edge,
    ~2 px beyond the dot's, and the conic through all rays was ~1 px off towards the hair in cameras 0 and
    1, the same way in both, so its 3D point was ~0.5 mm off.  Paint is flat: inside those edge points the
    level is the hair's, not the dot's, and they are dropped."""
    from carapost.core.blobs import detector
    from carapost.sample.render import leds_of, render_view
    from carapost.sample.scene import build_scene, frame_geometry, true_cameras

    sc = build_scene(markers=35, frames=120, seed=1)
    k = list(sc.markers.labels).index("Brow_L_1")
    views = []
    for f in (0, 50):
        g, cams = frame_geometry(sc, f), true_cameras(sc, f)
        for c in (0, 1):
            img, truth = render_view(sc, g, cams[c], c, f, leds=leds_of(cams))
            views.append((img, truth.centre[k]))

    def errors():
        out = []
        for img, (u, v) in views:
            rec = detect(img)
            out.append(float(np.hypot(rec["x"] - u, rec["y"] - v).min()))
        return np.array(out)

    assert errors().max() < 0.3
    refine, ellipses = detector.refine_centres, detector.edge_ellipses
    monkeypatch.setattr(detector, "refine_centres", lambda *a, **kw: refine(*a, **{**kw, "flat": False}))
    monkeypatch.setattr(detector, "edge_ellipses", lambda *a, **kw: ellipses(*a, **{**kw, "flat": False}))
    assert errors().min() > 0.8


def test_a_white_lower_lip_dot_grown_into_the_teeth_is_found_from_its_own_edge(monkeypatch):
    """Frame 92 of the 300-frame white sample take seed 1, camera 0: the jaw is open and the lower lip's
    left dot, seen steeply, touches the brighter lower teeth.  Its measurement took them in (13.8 x 10 px,
    3.1 px off); its candidate's own edge outlines the dot (9.7 x 4.1 px, 0.4 px off).  Grown 1.7 times its
    candidate's radius, it was under the 1.8 that counted as drawn off for the candidate's edge to be tried."""
    from carapost.core.blobs import detector

    error = _white_dot_error(markers=35, frames=300, seed=1, frame=92, camera=0, label="Lip_Lower_L")
    assert error() < 0.5
    monkeypatch.setattr(detector, "GROWN", 1.8)
    assert error() > 1.5


def _white_dot_error(markers, frames, seed, frame, camera, label):
    """A function giving the white detector's distance (px) to ``label``'s dot in one view of a sample take."""
    from carapost.sample.render import leds_of, render_view
    from carapost.sample.scene import build_scene, frame_geometry, true_cameras

    sc = build_scene(markers=markers, frames=frames, seed=seed, white=True)
    g, cams = frame_geometry(sc, frame), true_cameras(sc, frame)
    img, truth = render_view(sc, g, cams[camera], camera, frame, leds=leds_of(cams))
    u, v = truth.centre[list(sc.markers.labels).index(label)]

    def error():
        rec = detect(img, white=True)
        return float(np.hypot(rec["x"] - u, rec["y"] - v).min())

    return error


def test_the_edge_fits_median_is_numpys():
    """``edges._median`` (selection in a scratch row, no allocation) gives ``np.median`` to the bit."""
    from carapost.core.blobs.edges import _median

    rng = np.random.default_rng(11)
    tmp = np.empty(64)
    for n in (1, 2, 3, 47, 48, 49):
        for _ in range(50):
            a = rng.normal(size=n)
            if rng.random() < 0.5:
                a = np.round(a, 1)                 # ties
            kept = a.copy()
            assert _median(a, tmp[:n]) == np.median(a), (n, a)
            np.testing.assert_array_equal(a, kept)  # the input is left as it was


def test_a_saturated_white_dot_on_a_highlight_is_found_from_its_own_edge(monkeypatch):
    """Frame 80 of the white 100-marker sample take seed 2 (one of the blob benchmark's), camera 1: the nose
    tip's dot is saturated and round (11.4 x 10.2 px) on the nose's specular highlight.  Its candidate's
    measurement grows over the highlight (19.5 x 13.5 px, 1.1 px off), holds its candidate and has a clean
    edge, so it was taken for a larger blob the candidate is part of, and stage 2 scores it 0.29: the dot was
    missed.  A grown fit that stage 2 rejects is not taken for such a blob: the candidate's own edge outlines the
    dot (docs/blobs-history.md, "Session 27")."""
    from carapost.core.blobs import detector

    error = _white_dot_error(markers=100, frames=81, seed=2, frame=80, camera=1, label="Nose_Tip")
    assert error() < 0.5
    monkeypatch.setattr(detector, "HELD_BELOW", 0.0)
    assert error() > 1.5


def test_a_black_brow_dot_touched_by_hair_takes_its_best_arc_from_a_small_offset():
    """The benchmark's seed-0 take, frame 0, cameras 0 and 1: `Brow_R_1`'s dot touches the brow's hair on one side.
    The whole edge is not a clean ellipse, and its conic lies 0.05-0.3 px from the blob: with the arcs tried only
    beyond 0.3 px (``ARC_MOVE``, as before session 34 and still for white dots) the centre stayed 0.65-0.77 px off
    towards the hair; black dots try them beyond 0.05 px (``ARC_MOVE_FLAT``), and the best arc is the dot's own."""
    from carapost.core.blobs.edges import ARC_MOVE, ARC_MOVE_FLAT
    from carapost.core.blobs.synth import sample_frames

    assert ARC_MOVE_FLAT < ARC_MOVE
    # (The benchmark's take: its motion is drawn for its 81 frames; a one-frame take's frame 0 differs.)
    for s in sample_frames(False, seed=0, frames=3, cameras=(0, 1))[:2]:
        c = s.centres[s.names.index("Brow_R_1")]
        rec = detect(s.image)
        assert np.hypot(rec["x"] - c[0], rec["y"] - c[1]).min() < 0.25
