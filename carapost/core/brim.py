"""The calibration brim: a known rigid layout of markers that defines the world frame."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np


@dataclass(eq=False)
class Brim:
    """A calibration brim.

    Attributes
    ----------
    name : str
        ``"v2.0"``, ``"v1.1"``, ``"v1.0"`` for the default brims, or the SVG's file name.
    markers : ndarray (M, 3)
        Marker centres in mm, in the world frame the brim defines.
    svg : str
        The SVG text when imported from SVG (View > Show Calibration Brim SVG), else ``""``.
    """

    name: str
    markers: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    svg: str = ""

    def __post_init__(self):
        self.markers = np.asarray(self.markers, np.float64).reshape(-1, 3)

    def __len__(self) -> int:
        return len(self.markers)

    def to_json(self) -> dict:
        return {"name": self.name, "markers": self.markers.tolist(), "svg": self.svg}

    @classmethod
    def from_json(cls, d: dict) -> "Brim":
        return cls(d["name"], np.asarray(d["markers"], float).reshape(-1, 3), d.get("svg", ""))


DEFAULT_BRIMS = ("v2.0", "v1.1", "v1.0")


def default_brim(version: str) -> Brim:
    """Process > Initialize Default Calibration Brim [version]: the project's own layouts.

    Vicon's geometry is not public; ``resources/brims/<version>.json`` holds ours
    (``tools/make_default_brims.py``, ``docs/brims.md``).
    """
    import json

    from ..resources import resource_path

    if version not in DEFAULT_BRIMS:
        from .errors import CaraError

        raise CaraError(f"unknown default brim {version!r} (choose {', '.join(DEFAULT_BRIMS)})")
    d = json.loads(resource_path("brims", f"{version}.json").read_text())
    return Brim(version, np.asarray(d["markers"], float))
