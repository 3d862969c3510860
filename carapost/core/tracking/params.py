"""The Tracking Parameters section as one plain value object."""
from __future__ import annotations

from dataclasses import dataclass, fields


@dataclass(frozen=True)
class TrackingParams:
    """Every ``tracking.*`` property (see the reference guide, Tracking Parameters).

    Distances are pixels unless the name says mm.
    """

    patch_match_threshold: float = 0.8
    face_point_tracking_distance: float = 35.0
    face_point_max_elastic_prediction_distance: float = 15.0
    brim_point_tracking_distance: float = 15.0
    patch_match_size: int = 15
    remove_bad_2d_projections: bool = True
    max_allowed_2d_projection_error: float = 5.0
    remove_bad_3d_points: bool = True
    max_allowed_3d_point_error: float = 5.0
    allow_single_sensor_tracking: bool = True
    single_sensor_tracking_threshold: float = 0.5
    blob_size_difference_threshold: float = 0.75
    add_points_for_new_markers: bool = True
    search_missing_views: bool = True

    @classmethod
    def from_project(cls, project, overrides: dict | None = None) -> "TrackingParams":
        """The project's values (``overrides``: name -> value replaces some)."""
        vals = {f.name: project.properties[f"tracking.{f.name}"] for f in fields(cls)}
        vals.update(overrides or {})
        return cls(**vals)
