"""The blob classifier: a tiny multilayer perceptron over candidate features.

Weights live in ``resources/blob_model_{black,white}.npz`` and are produced by
``tools/train_blob_model.py`` (deterministic seed).  Evaluation is a few small
matrix products, numpy only.
"""
from __future__ import annotations

import functools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CaraError
from .features import FEATURE_NAMES

RESOURCE_DIR = Path(__file__).resolve().parents[3] / "resources"


@dataclass
class BlobModel:
    """Standardisation plus one tanh hidden layer and a logistic output."""

    mean: np.ndarray
    std: np.ndarray
    w1: np.ndarray
    b1: np.ndarray
    w2: np.ndarray
    b2: float

    def predict(self, F: np.ndarray) -> np.ndarray:
        """Probability (0-1) that each feature row is a blob centre."""
        if len(F) == 0:
            return np.zeros(0, np.float32)
        z = (F - self.mean) / self.std
        h = np.tanh(z @ self.w1 + self.b1)
        s = h @ self.w2 + self.b2
        return (1.0 / (1.0 + np.exp(-np.clip(s, -30, 30)))).astype(np.float32)

    def save(self, path) -> None:
        np.savez(path, mean=self.mean, std=self.std, w1=self.w1, b1=self.b1, w2=self.w2,
                 b2=np.float32(self.b2), feature_names=np.array(FEATURE_NAMES))

    @classmethod
    def load(cls, path) -> "BlobModel":
        try:
            z = np.load(path)
        except (OSError, ValueError) as e:
            raise CaraError(f"{path}: cannot read blob model ({e})") from None
        if tuple(str(n) for n in z["feature_names"]) != FEATURE_NAMES:
            raise CaraError(f"{path}: blob model was trained on other features; run tools/train_blob_model.py")
        f32 = lambda k: np.asarray(z[k], np.float32)  # noqa: E731
        return cls(f32("mean"), f32("std"), f32("w1"), f32("b1"), f32("w2"), float(z["b2"]))


@functools.lru_cache(maxsize=4)
def default_model(white: bool) -> BlobModel:
    """The shipped model for white (True) or black (False) blobs."""
    path = RESOURCE_DIR / f"blob_model_{'white' if white else 'black'}.npz"
    if not path.exists():
        raise CaraError(f"{path} is missing; run tools/train_blob_model.py")
    return BlobModel.load(path)
