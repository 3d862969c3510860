"""The blob preview overlay's detector (View > Toggle Blob Preview, Ctrl+B).

The overlay calls ``preview(image, properties) -> detection records``.  By
default that is :func:`carapost.core.blob_ops.blob_preview` (blob detection,
issue 5) when it is in the build; :func:`set_preview` replaces it (None: no
preview, and the views say it is not available instead of silently showing
nothing).
"""
from __future__ import annotations

from typing import Callable

import numpy as np

#: ``preview(image, properties) -> detection records`` (see carapost.core.detections.DET_DTYPE)
Preview = Callable[[np.ndarray, object], np.ndarray]

NOT_AVAILABLE = "not available (blob detection is not in this build)"

_UNSET = object()
_preview = _UNSET


def set_preview(fn: Preview | None) -> None:
    """Register the function the overlay calls on the shown image with the project's properties."""
    global _preview
    _preview = fn


def reset() -> None:
    """Back to the default (blob detection's preview when present)."""
    global _preview
    _preview = _UNSET


def get_preview() -> Preview | None:
    """The preview function, or None when there is none."""
    global _preview
    if _preview is _UNSET:
        try:
            from ..core.blob_ops import blob_preview
        except ImportError:
            _preview = None
        else:
            _preview = blob_preview
    return _preview
