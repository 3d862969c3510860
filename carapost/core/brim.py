"""The calibration brim: a known rigid layout of markers that defines the world frame."""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .disc_image import camera_offsets


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
    radius : ndarray (M,)
        Each printed dot's radius in mm (an SVG circle's ``r``), 0 where not known (the default
        brims).  A dot of known radius, lying in the brim's plane (z = 0), has its image's
        perspective offset taken off its detections before the cameras are solved from it
        (:func:`brim_image_offsets`).
    """

    name: str
    markers: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    svg: str = ""
    radius: np.ndarray | None = None

    def __post_init__(self):
        self.markers = np.asarray(self.markers, np.float64).reshape(-1, 3)
        r = np.zeros(len(self.markers)) if self.radius is None else np.asarray(self.radius, np.float64).ravel()
        if r.size == 1 and len(self.markers) != 1:
            r = np.full(len(self.markers), float(r[0]))
        if r.shape != (len(self.markers),):
            raise ValueError(f"brim {self.name!r}: {r.size} dot radii for {len(self.markers)} markers")
        self.radius = r

    def __len__(self) -> int:
        return len(self.markers)

    def to_json(self) -> dict:
        d = {"name": self.name, "markers": self.markers.tolist(), "svg": self.svg}
        if np.any(self.radius > 0):
            d["radius"] = self.radius.tolist()
        return d

    @classmethod
    def from_json(cls, d: dict) -> "Brim":
        # Projects written before session 24 have no radii: no offset correction until the SVG is imported again.
        return cls(d["name"], np.asarray(d["markers"], float).reshape(-1, 3), d.get("svg", ""), d.get("radius"))


def brim_image_offsets(cameras, brim: "Brim", idx=None) -> np.ndarray:
    """The perspective offsets of the brim's dots ``idx`` (all by default) in raw pixels of each camera.

    See :func:`~carapost.core.disc_image.disc_image_offsets`.

    Returns
    -------
    ndarray (M, S, 2)
        To be taken off each detection of a brim dot before a solve that holds it at its marker.
    """
    idx = np.arange(len(brim)) if idx is None else np.asarray(idx, int)
    return camera_offsets(cameras, brim.markers[idx], brim.radius[idx])


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
