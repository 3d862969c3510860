"""The tracker's rotation vectors to matrices (a compiled kernel, :func:`carapost.core.tracking.geometry.rodrigues`)."""
import numpy as np
import pytest

from carapost.core.tracking.geometry import rodrigues


def _closed_form(w):
    th = np.linalg.norm(w, axis=-1)[..., None, None]
    ths = np.where(th < 1e-15, 1.0, th)
    k = w / ths[..., 0]
    K = np.zeros(w.shape[:-1] + (3, 3))
    K[..., 0, 1], K[..., 0, 2] = -k[..., 2], k[..., 1]
    K[..., 1, 0], K[..., 1, 2] = k[..., 2], -k[..., 0]
    K[..., 2, 0], K[..., 2, 1] = -k[..., 1], k[..., 0]
    return np.eye(3) + np.sin(ths) * K + (1 - np.cos(ths)) * (K @ K)


@pytest.mark.parametrize("shape", [(3,), (4, 3), (2, 5, 3)])
def test_rodrigues_matches_the_closed_form_in_any_shape(shape):
    w = np.random.default_rng(3).normal(0.0, 0.3, shape)
    R = rodrigues(w)
    assert R.shape == shape[:-1] + (3, 3)
    assert np.allclose(R, _closed_form(w), rtol=0, atol=1e-15)
    assert np.allclose(R @ np.swapaxes(R, -1, -2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(R), 1.0)
    # The axis is left where it is.
    assert np.allclose(np.einsum("...ij,...j->...i", R, w), w, atol=1e-12)


def test_rodrigues_quarter_turn_and_zero():
    R = rodrigues(np.array([[0.0, 0.0, np.pi / 2], [0.0, 0.0, 0.0]]))
    assert np.allclose(R[0] @ [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], atol=1e-15)
    assert np.array_equal(R[1], np.eye(3))
