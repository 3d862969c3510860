"""Step 9: the centre stage's correction of each detection's centre (docs/blobs.md)."""
from __future__ import annotations

import numpy as np
import pytest

from carapost.core.blobs import blob_settings, detect, detect_with_properties, detector
from carapost.core.blobs import centre_net as cn
from carapost.core.blobs.model import BlobModel, default_model
from carapost.core.blobs.synth import disc_image, match_truth, sample_frames
from carapost.core.errors import CaraError
from carapost.core.properties import Properties


def _reference_inputs(img, x, y, major, minor, angle, noise):
    """The grid and inputs written out point by point (bilinear, inside the image)."""
    g = np.linspace(-1.0, 1.0, cn.GRID)
    out = []
    for k in range(len(x)):
        a, b, t = major[k] / 2, minor[k] / 2, np.deg2rad(angle[k])
        vals = np.empty((cn.GRID, cn.GRID))
        for i, v in enumerate((b + cn.MARGIN) * g):
            for j, u in enumerate((a + cn.MARGIN) * g):
                px, py = x[k] + np.cos(t) * u - np.sin(t) * v, y[k] + np.sin(t) * u + np.cos(t) * v
                ix, iy = int(np.floor(px)), int(np.floor(py))
                fx, fy = px - ix, py - iy
                p = img[iy:iy + 2, ix:ix + 2].astype(float)
                vals[i, j] = (p[0, 0] * (1 - fx) * (1 - fy) + p[0, 1] * fx * (1 - fy) + p[1, 0] * (1 - fx) * fy
                              + p[1, 1] * fx * fy)
        border = np.concatenate([vals[0], vals[-1], vals[1:-1, 0], vals[1:-1, -1]])
        s = np.median(border)
        c = vals[cn.GRID // 2 - 1:cn.GRID // 2 + 2, cn.GRID // 2 - 1:cn.GRID // 2 + 2].mean() - s
        out.append(np.concatenate([((vals - s) / c).ravel(), [a, b, b / a, np.log(abs(c) / noise)]]))
    return np.array(out)


def test_the_inputs_are_the_grid_in_the_dots_frame_over_its_contrast():
    rng = np.random.default_rng(3)
    img = rng.integers(0, 256, (80, 90)).astype(np.uint8)
    img[30:42, 35:50] = 250
    x, y = np.array([42.3, 41.0, 44.7]), np.array([36.1, 35.6, 40.2])
    major, minor, angle = np.array([9.0, 7.5, 12.0]), np.array([6.0, 7.5, 3.0]), np.array([20.0, 0.0, 135.0])
    mine, texture = cn.centre_inputs(img, x, y, major, minor, angle, 2.0)
    ref = _reference_inputs(img, x, y, major, minor, angle, 2.0)
    np.testing.assert_allclose(mine, ref, rtol=1e-4, atol=1e-4)
    assert np.all(texture > 5)          # random grey levels about the dot: a textured surround
    # Either polarity gives the same inputs: black dots are corrected on the inverted image by the same code.
    inv, _ = cn.centre_inputs(255 - img, x, y, major, minor, angle, 2.0)
    np.testing.assert_allclose(inv, mine, rtol=1e-4, atol=1e-4)


def test_the_shipped_models_have_a_centre_stage():
    for white in (False, True):
        net = default_model(white).centre
        assert net is not None and net.w1.shape == (cn.N_INPUTS, len(net.b1))
    # White's has two layers (session 40); black's one (two were no better on black dots).
    white, black = default_model(True).centre, default_model(False).centre
    assert white.wh.shape == (len(white.b1), len(white.bh)) and white.w2.shape == (len(white.bh), 2)
    assert black.wh is None and black.w2.shape == (len(black.b1), 2)


def _one_layer(net: cn.CentreNet) -> cn.CentreNet:
    """A one-layer network as session 39's files held (its first layer and an output of its own)."""
    w2 = np.random.default_rng(2).normal(0.0, 0.05, (len(net.b1), 2)).astype(np.float32)
    return cn.CentreNet(net.mean, net.std, net.w1, net.b1, w2, np.array([0.01, -0.02], np.float32))


def test_a_model_file_with_a_one_layer_centre_stage_still_loads_and_corrects(tmp_path):
    shipped = default_model(True)
    model = BlobModel(shipped.stage1, shipped.stage2, shipped.edge, _one_layer(shipped.centre))
    path = tmp_path / "m.npz"
    model.save(path)
    assert "sc_wh" not in np.load(path)
    back = BlobModel.load(path).centre
    assert back.wh is None and back.bh is None
    np.testing.assert_array_equal(back.w2, model.centre.w2)
    frames = sample_frames(True, seed=7, frames=1, cameras=(2,))
    on = detector.detect(frames[0].image, white=True, model=BlobModel.load(path))
    off = detector.detect(frames[0].image, white=True, learned_centres=False)
    assert len(on) == len(off) and np.any(on["x"] != off["x"])


def test_a_model_file_with_another_grid_is_refused(tmp_path):
    model = default_model(False)
    path = tmp_path / "m.npz"
    model.save(path)
    assert BlobModel.load(path).centre is not None
    z = dict(np.load(path))
    z["centre_grid"] = np.array([cn.GRID + 2, cn.MARGIN, cn.N_INPUTS], np.float64)
    np.savez(path, **z)
    with pytest.raises(CaraError, match="centre stage was trained on another grid"):
        BlobModel.load(path)


def _rms(white: bool, frames, learned: bool) -> float:
    errs = []
    for s in frames:
        r = detect(s.image, white=white, learned_centres=learned)
        hit, _, e = match_truth(np.column_stack([r["x"], r["y"]]).astype(float), s)
        errs.append(e)
    e = np.concatenate(errs)
    return float(np.sqrt((e ** 2).sum(1).mean()))


@pytest.mark.parametrize("white", [False, True])
def test_step9_brings_the_centres_of_a_sample_take_it_was_not_trained_on_closer(white):
    # Seeds 7 and 8 (the benchmark's takes are 0-5, the training's 1000 and up), frame 0 of all four cameras.
    frames = sample_frames(white, seed=7, frames=1) + sample_frames(white, seed=8, frames=1)
    before, after = _rms(white, frames, False), _rms(white, frames, True)
    # Measured (session 39): black 0.063 -> 0.049 px, white 0.109 -> 0.078 px.
    assert after < 0.9 * before, (before, after)


def test_a_dot_on_a_flat_surround_is_not_moved():
    rng = np.random.default_rng(5)
    for snr in (15.0, 150.0):
        img, _ = disc_image(rng, 61, 4.0, 1.0, 100.0, 60.0, 100.0 / snr, dark=False)
        img = np.clip(np.rint(img), 0, 255).astype(np.uint8)
        on, off = detect(img, white=True), detect(img, white=True, learned_centres=False)
        assert len(on) == 1
        np.testing.assert_array_equal(on, off)


def test_the_property_turns_step9_off():
    frames = sample_frames(False, seed=7, frames=1, cameras=(0,))
    props = Properties()
    assert blob_settings(props)[0]["learned_centres"] is True
    props.set("blob.learned_centres", False)
    off = detect_with_properties(frames[0].image, props)
    np.testing.assert_array_equal(off, detect(frames[0].image, learned_centres=False))
    props.set("blob.learned_centres", True)
    on = detect_with_properties(frames[0].image, props)
    np.testing.assert_array_equal(on, detect(frames[0].image))
    assert len(on) == len(off) and np.any(on["x"] != off["x"])


def test_a_model_without_a_centre_stage_leaves_the_centres(monkeypatch):
    frames = sample_frames(False, seed=7, frames=1, cameras=(1,))
    model = default_model(False)
    bare = BlobModel(model.stage1, model.stage2, model.edge, orphan=model.orphan, orphan_score=model.orphan_score)
    np.testing.assert_array_equal(detector.detect(frames[0].image, model=bare),
                                  detector.detect(frames[0].image, learned_centres=False))


@pytest.mark.parametrize("layers", [2, 1])
def test_the_compiled_network_is_the_numpy_one(layers):
    frames = sample_frames(True, seed=7, frames=1, cameras=(2,))
    rec = detect(frames[0].image, white=True, learned_centres=False)
    img = detector.as_grey_u8(frames[0].image)
    net = default_model(True).centre if layers == 2 else _one_layer(default_model(True).centre)
    inputs, texture = cn.centre_inputs(img, rec["x"], rec["y"], rec["major"], rec["minor"], rec["angle"], 2.0)
    geo = cn._geometry(rec["x"], rec["y"], rec["major"], rec["minor"], rec["angle"])
    err, tex = np.empty((len(rec), 2)), np.empty(len(rec))
    cn._errors(img, *geo, 2.0, *net.kernel_arrays, err, tex)
    np.testing.assert_allclose(tex, texture, rtol=1e-9)
    np.testing.assert_allclose(err, net.error(inputs), atol=2e-5)
    assert len(rec) > 50 and np.abs(err).max() > 0.05        # it does move centres
