"""Blob detection: the learned blob-centre classifier, extraction and ellipse fitting.

Public entry points: :func:`detect` (one colour, explicit parameters) and
:func:`detect_with_properties` (the Blob Parameters of a project).
"""
from __future__ import annotations

import numpy as np

from ..detections import DET_DTYPE
from .detector import as_grey_u8, detect
from .model import BlobModel, default_model

__all__ = ["detect", "detect_with_properties", "detect_with_settings", "as_grey_u8", "BlobModel", "default_model", "blob_settings"]


def blob_settings(properties) -> list[dict]:
    """The per-colour detection settings the ``blob.*`` properties ask for."""
    out = []
    for colour, white in (("black", False), ("white", True)):
        if properties[f"blob.find_{colour}_blobs"]:
            out.append({"white": white, "threshold": float(properties[f"blob.{colour}_threshold"]),
                        "min_major": float(properties[f"blob.{colour}_min_radius"]),
                        "max_major": float(properties[f"blob.{colour}_max_radius"])})
    return out


def detect_with_properties(image, properties) -> np.ndarray:
    """Blobs of every enabled colour in ``image`` with the project's Blob Parameters."""
    return detect_with_settings(image, blob_settings(properties))


def detect_with_settings(image, settings: list[dict]) -> np.ndarray:
    """Blobs of ``image`` for each of :func:`blob_settings`' entries (picklable: worker processes use it)."""
    parts = [detect(image, **s) for s in settings]
    if not parts:
        as_grey_u8(image)  # still refuse unusable images clearly
        return np.zeros(0, DET_DTYPE)
    return np.concatenate(parts) if len(parts) > 1 else parts[0]
