"""Blob detection: the learned blob-centre classifier, extraction and ellipse fitting.

Public entry points: :func:`detect` (one colour, explicit parameters) and
:func:`detect_with_properties` (the Blob Parameters of a project).
"""
from __future__ import annotations

import numpy as np

from ..detections import DET_DTYPE
from .detector import as_grey_u8, detect
from .model import BlobModel, default_model

__all__ = ["detect", "detect_with_properties", "detect_with_settings", "as_grey_u8", "BlobModel", "default_model", "blob_settings",
           "warm_up"]


def blob_settings(properties) -> list[dict]:
    """The per-colour detection settings the ``blob.*`` properties ask for."""
    out = []
    for colour, white in (("black", False), ("white", True)):
        if properties[f"blob.find_{colour}_blobs"]:
            out.append({"white": white, "threshold": float(properties[f"blob.{colour}_threshold"]),
                        "min_major": float(properties[f"blob.{colour}_min_radius"]),
                        "max_major": float(properties[f"blob.{colour}_max_radius"]),
                        "learned_centres": bool(properties["blob.learned_centres"])})
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


def warm_up() -> float:
    """Compile (or load from numba's disk cache) every blob-detection kernel; returns the seconds it took.

    The first detection after installing carapost, or after a kernel changed,
    compiles them (~20-40 s on a 2-core machine); later processes load them in
    well under a second.  Call this where that first wait must not fall on a
    user's click or a timed step (the test suite does at its start).
    """
    import time

    from .component_kernel import COMPONENT_COLUMNS, threshold_components, unexplained
    from .gauss_kernel import fit_gaussians
    from .profile_kernel import fit_profiles
    from .synth import disc_image

    t = time.perf_counter()
    rng = np.random.default_rng(0)
    img = np.full((96, 96), 150.0)
    for cx, cy, r in ((30.3, 30.6, 4.0), (64.7, 40.2, 3.0), (45.1, 70.8, 5.0)):
        disc, _ = disc_image(rng, 41, r, 1.0, 110.0, 0.0, 1.0, centre=(20 + cx % 1, 20 + cy % 1))
        x0, y0 = int(cx) - 20, int(cy) - 20
        img[y0:y0 + 41, x0:x0 + 41] -= disc
    img = np.clip(img, 0, 255).astype(np.uint8)
    detect(img)
    detect(255 - img, white=True)
    # Step 6 runs only where a faint thin dot was measured round: compile it here, not on such a dot.
    fit_gaussians(img, np.array([30.3]), np.array([30.6]), np.array([6]), np.empty((1, 8)))
    # Step 7 runs only on elongated dots (these are round).
    one = np.array([1.0])
    fit_profiles(img, 30.3 * one, 30.6 * one, 0.0 * one, 8.0 * one, 3.0 * one, np.empty((1, 6)))
    # The orphan search runs only where a candidate is left unexplained (these dots are all found).
    threshold_components(img, 30.3 * one, 30.6 * one, 12, 2, 2.0, 120, np.empty((1, len(COMPONENT_COLUMNS))))
    unexplained(one, one, one, one, one, one, one, one, 1.5, np.empty(1, bool))
    return time.perf_counter() - t
