"""The search about candidates no believed fit explains: threshold components, the edge from their ellipse, and
what it finds on a sample take (docs/blobs.md, "The algorithm", the orphan search)."""
import numpy as np
import pytest

from carapost.core.blobs import default_model, detect
from carapost.core.blobs import detector as D
from carapost.core.blobs.component_kernel import COMPONENT_COLUMNS, threshold_components, unexplained
from carapost.core.blobs.edges import edge_ellipses
from carapost.core.blobs.synth import match_truth, sample_frames

COL = {name: i for i, name in enumerate(COMPONENT_COLUMNS)}


def _ellipse(img, cx, cy, a, b, angle_deg, value, ss=8):
    """Add ``value`` inside an ellipse, anti-aliased by ``ss`` x ``ss`` supersampling."""
    h, w = img.shape
    yy, xx = np.mgrid[0:h, 0:w].astype(float)
    c, s = np.cos(np.radians(angle_deg)), np.sin(np.radians(angle_deg))
    cover = np.zeros((h, w))
    for i in range(ss):
        for j in range(ss):
            dx = xx + (j + 0.5) / ss - 0.5 - cx
            dy = yy + (i + 0.5) / ss - 0.5 - cy
            u, v = (c * dx + s * dy) / a, (-s * dx + c * dy) / b
            cover += (u * u + v * v <= 1.0)
    img += value * cover / (ss * ss)


def _dot_on_a_rim(cx=40.3, cy=30.6):
    """A bright thin dot (5 x 1.4 px semi-axes, level 200) whose lower edge touches a wide dimmer band (120) on a
    dark surround (40): the nose tip's dot above the nostrils' shadow, on the "bright blob" image."""
    img = np.full((64, 80), 40.0)
    img[int(np.ceil(cy + 1.0)):int(cy + 12), 10:70] = 120.0
    _ellipse(img, cx, cy, 5.0, 1.4, 0.0, 160.0)
    return np.clip(img, 0, 255).astype(np.uint8)


def test_the_region_before_it_merges_is_the_dot():
    img = _dot_on_a_rim()
    out = np.zeros((1, len(COMPONENT_COLUMNS)))
    threshold_components(img, np.array([40.0]), np.array([31.0]), 12, 2, 2.0, 120, out)
    assert out[0, COL["ok"]] == 1
    # The dot's pixels, not the band's: its area is the ellipse's (22 px), its centroid at its centre.
    assert 12 <= out[0, COL["area"]] <= 30
    assert abs(out[0, COL["x"]] - 40.3) < 0.3 and abs(out[0, COL["y"]] - 30.6) < 0.5
    assert 3.5 < out[0, COL["a"]] < 6.0 and out[0, COL["b"]] < 2.2
    assert out[0, COL["merge"]] < out[0, COL["level"]] <= out[0, COL["peak"]]


def test_a_region_that_fills_its_window_or_is_too_large_is_no_dot():
    flat = np.full((64, 64), 100, np.uint8)
    flat[20:44, 20:44] = 180          # a square larger than the window: it reaches the window's sides at once
    out = np.zeros((1, len(COMPONENT_COLUMNS)))
    threshold_components(flat, np.array([32.0]), np.array([32.0]), 8, 2, 2.0, 120, out)
    assert out[0, COL["ok"]] == 0
    # A dot of ~200 px on a flat surround is too large for max_area 120 (and found with 400).
    img = np.full((64, 64), 40.0)
    _ellipse(img, 32.0, 32.0, 8.0, 8.0, 0.0, 150.0)
    img = img.astype(np.uint8)
    threshold_components(img, np.array([32.0]), np.array([32.0]), 12, 2, 2.0, 120, out)
    assert out[0, COL["ok"]] == 0
    threshold_components(img, np.array([32.0]), np.array([32.0]), 12, 2, 2.0, 400, out)
    assert out[0, COL["ok"]] == 1 and abs(out[0, COL["x"]] - 32.0) < 0.1


def test_a_dot_at_the_image_edge_has_not_merged():
    img = np.full((40, 40), 40.0)
    _ellipse(img, 3.0, 20.0, 3.0, 2.0, 90.0, 150.0)
    img = img.astype(np.uint8)
    out = np.zeros((1, len(COMPONENT_COLUMNS)))
    threshold_components(img, np.array([3.0]), np.array([20.0]), 12, 2, 2.0, 120, out)
    assert out[0, COL["ok"]] == 1 and abs(out[0, COL["y"]] - 20.0) < 0.2


def test_unexplained_points_lie_away_from_every_fit_and_outside_its_ellipse():
    # One fit at (50, 50): semi-axes 10 x 2 along x.
    fx, fy, fa, fb, fang = (np.array([v]) for v in (50.0, 50.0, 10.0, 2.0, 0.0))
    px = np.array([50.5, 58.0, 50.0, 80.0, 41.0])
    py = np.array([50.0, 50.5, 54.0, 80.0, 50.0])
    out = np.zeros(5, bool)
    unexplained(px, py, np.full(5, 1.0), fx, fy, fa, fb, fang, 1.5, out)
    # near the centre; inside the ellipse; off its side (4 px across a 2 px semi-axis); far away; inside its end
    assert out.tolist() == [False, False, True, True, False]
    unexplained(px, py, np.full(5, 1.0), fx[:0], fy[:0], fa[:0], fb[:0], fang[:0], 1.5, out)
    assert out.all()


def test_the_edge_from_a_start_ellipse_and_the_circle_as_before():
    img = _dot_on_a_rim()
    x, y, r = np.array([40.0]), np.array([31.0]), np.array([4.8])
    circle = edge_ellipses(img, x, y, r, quality=True)
    same = edge_ellipses(img, x, y, r, quality=True, start=(r, np.zeros(1)))
    assert np.array_equal(circle, same)
    e = edge_ellipses(img, x, y, r, quality=True, start=(np.array([1.5]), np.zeros(1)))
    assert e[0, 5] == 1
    assert abs(e[0, 0] - 40.3) < 0.25 and abs(e[0, 1] - 30.6) < 0.25
    assert 8.0 < e[0, 2] < 11.5 and e[0, 3] < 3.5


@pytest.fixture(scope="module")
def sample_take():
    return {white: sample_frames(white, seed=0, frames=1) for white in (False, True)}


@pytest.mark.parametrize("white", [False, True])
def test_the_orphan_search_finds_more_and_adds_no_false_detection(sample_take, white, monkeypatch):
    found, false = {}, {}
    for on in (False, True):
        monkeypatch.setattr(D, "ORPHANS", on)
        found[on], false[on] = [], 0
        for s in sample_take[white]:
            r = detect(s.image, white=white)
            hit, f, _ = match_truth(np.column_stack([r["x"], r["y"]]).astype(float), s)
            found[on].append(set(np.flatnonzero(hit)))
            false[on] += f
    assert all(a <= b for a, b in zip(found[False], found[True]))
    assert false[True] == false[False]
    if not white:
        # Camera 3: Temple_L_1, an edge-on dot at the face's outline whose fits are drawn into the outline.
        s = sample_take[False][3]
        q = s.names.index("Temple_L_1")
        assert q not in found[False][3] and q in found[True][3]


def test_the_orphan_gate_lets_through_a_share_of_the_components():
    model = default_model(False)
    assert model.orphan is not None
    s = sample_frames(False, seed=0, frames=1, cameras=(3,))[0]
    img = D.as_grey_u8(s.image)
    cand, bright = D.find_candidates(img, False, 4.0, 50.0)
    logit1 = model.stage1.logit(cand.feats)
    prob1 = 1.0 / (1.0 + np.exp(-logit1))
    fitted = D.fit_stage(cand, bright, model, orphans=False)
    fin, comp = D.orphan_components(fitted, cand, bright, model, prob1)
    look = model.orphan.logit(D.orphan_features(cand, fin, comp, logit1)) >= 0
    # Most components are hair, lids and shadows; the gate looks at a fraction of them, among them Temple_L_1's.
    assert 20 < len(fin) and 0 < look.sum() < 0.6 * len(fin)
    t = s.centres[s.names.index("Temple_L_1")]
    near = np.hypot(comp[:, 0] - t[0], comp[:, 1] - t[1]) < 1.0
    assert (near & look).any()


def test_the_gates_training_examples_are_labelled_by_what_the_search_keeps():
    import importlib.util
    from pathlib import Path

    from carapost.core.blobs.model import ORPHAN_FEATURE_NAMES

    path = Path(__file__).resolve().parents[1] / "tools" / "train_blob_model.py"
    spec = importlib.util.spec_from_file_location("train_blob_model", path)
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    frames = sample_frames(False, seed=0, frames=1, cameras=(3,))
    X, Y = tool.orphan_examples(frames, False, default_model(False))
    assert X.shape == (len(Y), len(ORPHAN_FEATURE_NAMES)) and len(Y) > 20
    # Temple_L_1's component is one whose search ends as a kept fit (the test above); most are not.
    assert 1 <= Y.sum() <= 0.1 * len(Y)


def test_the_white_orphan_scorer_scores_the_searchs_fits_and_round_trips(tmp_path):
    from carapost.core.blobs.model import BlobModel

    model = default_model(True)
    assert model.orphan_score is not None and default_model(False).orphan_score is None
    rng = np.random.default_rng(1)
    F = rng.normal(size=(6, len(D.FIT_FEATURE_NAMES))).astype(np.float32)
    Q = rng.normal(size=(6, len(D.EDGE_FEATURE_NAMES))).astype(np.float32)
    # With the scorer: its own probabilities; without: as the rescue's ellipses are scored.
    assert np.allclose(model.orphan_scores(F, Q, D.RESCUE_LOGIT),
                       model.orphan_score.predict(model.edge_features(F, Q)))
    bare = BlobModel(model.stage1, model.stage2, model.edge, model.centre, model.orphan)
    assert np.allclose(bare.orphan_scores(F, Q, D.RESCUE_LOGIT), bare.score(F, np.ones(6, bool), D.RESCUE_LOGIT, Q))
    model.save(tmp_path / "m.npz")
    back = BlobModel.load(tmp_path / "m.npz")
    assert np.array_equal(back.orphan_score.w1, model.orphan_score.w1) and back.orphan_score.b2 == model.orphan_score.b2
