"""The property table: every setting of the guide's Properties and Tracker panes, declared once.

The Properties pane, ``--set GROUP.NAME=VALUE``, ``carapost properties`` and the
project file are all generated from :data:`PROPERTY_TABLE`; nothing else lists
property names or defaults.  Defaults are the Reference Guide's.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Iterator

from .errors import CaraError


@dataclass(frozen=True)
class PropertyDef:
    """One property: where it lives, what it holds and what it starts as.

    Attributes
    ----------
    group : str
        snake_case group key, e.g. ``"tracking"``.
    name : str
        snake_case property key, e.g. ``"patch_match_threshold"``.
    title : str
        The label the guide uses in the Properties pane.
    type : type
        ``bool``, ``int``, ``float`` or ``str``.
    default : Any
        The guide's default.
    minimum, maximum : float or None
        Inclusive range for numbers.
    unit : str
        ``"px"``, ``"mm"`` or ``""``.
    help : str
        One sentence shown as the tooltip.
    choices : tuple of str
        Allowed values of a ``str`` property (empty: free text).
    """

    group: str
    name: str
    title: str
    type: type
    default: Any
    minimum: float | None = None
    maximum: float | None = None
    unit: str = ""
    help: str = ""
    choices: tuple[str, ...] = ()

    @property
    def key(self) -> str:
        """``group.name``, the form ``--set`` takes."""
        return f"{self.group}.{self.name}"

    def coerce(self, value: Any) -> Any:
        """Convert ``value`` (possibly a string from the command line) to this property's type.

        Raises
        ------
        CaraError
            When the value has the wrong type or lies outside the range.
        """
        try:
            if self.type is bool:
                if isinstance(value, str):
                    low = value.strip().lower()
                    if low in ("true", "1", "yes", "on"):
                        v: Any = True
                    elif low in ("false", "0", "no", "off"):
                        v = False
                    else:
                        raise ValueError(value)
                elif isinstance(value, (bool, int)) and value in (0, 1):
                    v = bool(value)
                else:
                    raise ValueError(value)
            elif self.type is int:
                if isinstance(value, bool):
                    raise ValueError(value)
                f = float(value)
                if f != int(f):
                    raise ValueError(value)
                v = int(f)
            elif self.type is float:
                if isinstance(value, bool):
                    raise ValueError(value)
                v = float(value)
                if v != v:  # NaN
                    raise ValueError(value)
            else:
                v = str(value)
        except (TypeError, ValueError):
            raise CaraError(f"property {self.key} needs a {self.type.__name__}, not {value!r}") from None
        if self.minimum is not None and v < self.minimum:
            raise CaraError(f"property {self.key} must be >= {self.minimum:g}, not {v}")
        if self.maximum is not None and v > self.maximum:
            raise CaraError(f"property {self.key} must be <= {self.maximum:g}, not {v}")
        if self.choices and v not in self.choices:
            raise CaraError(f"property {self.key} must be one of {', '.join(self.choices)}, not {v!r}")
        return v


# Group keys with the titles the Properties pane shows, in the guide's order.
GROUPS: dict[str, str] = {
    "display": "Display",
    "selection": "Selection",
    "blob": "Blob Parameters",
    "initialize_3d": "Initialize 3D Parameters",
    "initialize_from_rom": "Initialize From ROM Parameters",
    "tracking": "Tracking Parameters",
    "gap_filling": "Gap-Filling Parameters",
    "stabilization": "Stabilization Parameters",
    "export": "Export",
    "show_again": "Show Again Flags",
    "labelling": "Labelling",
    "tracker": "Tracker",
}

_P = PropertyDef
PROPERTY_TABLE: tuple[PropertyDef, ...] = (
    # Display
    _P("display", "point_labels_all", "Point Labels : All", bool, False,
       help="Show all assigned point labels in 2D and 3D views."),
    _P("display", "point_labels_selected", "Point Labels : Selected", bool, True,
       help="Show the labels of selected points."),
    _P("display", "point_labels_pre_selected", "Point Labels : Pre-Selected", bool, True,
       help="Show the labels of points under the mouse."),
    _P("display", "font_size", "Font Size", int, 10, 4, 72, "pt", "Font size of point labels."),
    # Selection
    _P("selection", "points", "Points", bool, True, help="Points are selectable in 2D and 3D views."),
    _P("selection", "detections", "Detections", bool, True, help="Detections are selectable."),
    _P("selection", "sensors", "Sensors", bool, True, help="Sensors (cameras) are selectable."),
    _P("selection", "sticks", "Sticks", bool, True, help="Sticks are selectable."),
    # Blob Parameters
    _P("blob", "white_min_radius", "White Min Radius", float, 4.0, 0.5, 500, "px",
       "Minimum length of the longest ellipse axis of a white blob."),
    _P("blob", "white_max_radius", "White Max Radius", float, 50.0, 0.5, 500, "px",
       "Maximum length of the longest ellipse axis of a white blob."),
    _P("blob", "black_min_radius", "Black Min Radius", float, 4.0, 0.5, 500, "px",
       "Minimum length of the longest ellipse axis of a black blob."),
    _P("blob", "black_max_radius", "Black Max Radius", float, 50.0, 0.5, 500, "px",
       "Maximum length of the longest ellipse axis of a black blob."),
    _P("blob", "find_black_blobs", "Find Black Blobs", bool, True, help="Search for black markers."),
    _P("blob", "find_white_blobs", "Find White Blobs", bool, False, help="Search for white markers."),
    _P("blob", "black_threshold", "Black Threshold", float, 0.4, 0.0, 1.0, "",
       "Probability above which a black blob is detected: lower finds more."),
    _P("blob", "white_threshold", "White Threshold", float, 0.4, 0.0, 1.0, "",
       "Probability above which a white blob is detected: lower finds more."),
    _P("blob", "learned_centres", "Learned Centre Correction", bool, True,
       help="Correct each blob's centre by what the classifier's centre stage reads in the skin around it "
            "(trained on generated faces; step 9 of docs/blobs.md). Off: the centre from the dot's own edge "
            "and intensities."),
    # Initialize 3D Parameters
    _P("initialize_3d", "max_allowed_depth", "Max Allowed Depth", float, 35.0, 0.0, 1000, "mm",
       "Largest 3D distance of a new point from an existing one during Initialize 3D."),
    _P("initialize_3d", "max_3d_distance_to_merge", "Max 3D Distance To Merge", float, 5.0, 0.0, 1000, "mm",
       "Points of the two caddies closer than this are merged."),
    _P("initialize_3d", "max_allowed_symmetric_epipolar_distance", "Max Allowed Symmetric Epipolar Distance",
       float, 5.0, 0.0, 1000, "px", "Largest epipolar error of a match between the two cameras of a caddy."),
    # Initialize From ROM Parameters
    _P("initialize_from_rom", "rom_frame_index", "ROM Frame Index", int, 0, 0, None, "",
       "Frame of the ROM take used to initialise the current frame."),
    _P("initialize_from_rom", "rom_face_point_tracking_distance", "ROM Face Point Tracking Distance",
       float, 50.0, 0.0, 10000, "px", "How far face points are searched from the ROM frame."),
    _P("initialize_from_rom", "rom_brim_point_tracking_distance", "ROM Brim Point Tracking Distance",
       float, 30.0, 0.0, 10000, "px", "How far brim points are searched from the ROM frame."),
    _P("initialize_from_rom", "rom_max_allowed_3d_point_error", "ROM Max Allowed 3D Point Error",
       float, 5.0, 0.0, 1000, "mm", "Largest distance of a point from its neighbour prediction in the ROM."),
    # Tracking Parameters
    _P("tracking", "patch_match_threshold", "Patch Match Threshold", float, 0.8, 0.0, 1.0, "",
       "Score above which two patches or detections match (1 = perfect)."),
    _P("tracking", "face_point_tracking_distance", "Face Point Tracking Distance", float, 35.0, 0.0, 10000, "px",
       "How far face points are searched from one frame to the next."),
    _P("tracking", "face_point_max_elastic_prediction_distance", "Face Point Max Elastic Prediction Distance",
       float, 15.0, 0.0, 10000, "px", "Search distance once the elastic prediction from neighbours is known."),
    _P("tracking", "brim_point_tracking_distance", "Brim Point Tracking Distance", float, 15.0, 0.0, 10000, "px",
       "How far brim points are searched from one frame to the next."),
    _P("tracking", "patch_match_size", "Patch Match Size", int, 15, 3, 101, "px",
       "Side of the grey-level patch compared between frames."),
    _P("tracking", "remove_bad_2d_projections", "Remove Bad 2D Projections", bool, True,
       help="Detach detections whose reprojection error is too large."),
    _P("tracking", "max_allowed_2d_projection_error", "Max Allowed 2D Projection Error", float, 5.0, 0.0, 1000, "px",
       "Largest allowed reprojection error of an attached detection."),
    _P("tracking", "remove_bad_3d_points", "Remove Bad 3D Points", bool, True,
       help="Detach detections that put a point far from its neighbour prediction."),
    _P("tracking", "max_allowed_3d_point_error", "Max Allowed 3D Point Error", float, 5.0, 0.0, 1000, "mm",
       "Largest distance of a point from its neighbour prediction."),
    _P("tracking", "allow_single_sensor_tracking", "Allow Single Sensor Tracking", bool, True,
       help="Track a point seen by one camera along that camera's ray."),
    _P("tracking", "single_sensor_tracking_threshold", "Single Sensor Tracking Threshold", float, 0.5, 0.0, 1000,
       "mm", "Largest distance of a single-sensor result from its neighbour prediction."),
    _P("tracking", "blob_size_difference_threshold", "Blob Size Difference Threshold", float, 0.75, 0.0, 1.0, "",
       "How much a blob's width and height may change between frames (0 none, 1 any)."),
    _P("tracking", "add_points_for_new_markers", "Add Points For New Markers", bool, True,
       help="Give a marker that no point follows (hidden when Initialize 3D ran) a new, unlabelled point once "
            "two frames in a row match it in two or more cameras, on the face and clear of every point. "
            "Not in CaraPost's guide."),
    _P("tracking", "search_missing_views", "Search Missing Views", bool, True,
       help="Where fewer than two cameras detect a point near its prediction, look for its dot again in the other "
            "cameras at full resolution, at any score; keep what makes the point whole (two or more cameras' "
            "dots meeting near the prediction). The dots kept are added to the frame's detections. "
            "Not in CaraPost's guide."),
    # Gap-Filling Parameters
    _P("gap_filling", "overwrite_existing_filled_gaps", "Overwrite Existing Filled Gaps", bool, False,
       help="Recompute gaps already filled (points with zero or one detection)."),
    _P("gap_filling", "use_forwards_prediction", "Use Forwards Prediction", bool, True,
       help="Predict from the sample before the gap."),
    _P("gap_filling", "use_backwards_prediction", "Use Backwards Prediction", bool, True,
       help="Predict from the sample after the gap."),
    _P("gap_filling", "allow_single_sensor_tracking_gap_filling", "Allow Single Sensor Tracking Gap-Filling",
       bool, True, help="Keep a filled point on the ray of its one attached detection."),
    # Stabilization Parameters
    _P("stabilization", "use_brim_points", "Use Brim Points", bool, False,
       help="Include brim points in the stable set."),
    _P("stabilization", "base_frame_weighting", "Base Frame Weighting", float, 1.0, 0.0, None, "",
       "Weight of the base-frame stabilisation error."),
    _P("stabilization", "inter_frame_weighting", "Inter Frame Weighting", float, 1.0, 0.0, None, "",
       "Weight of the inter-frame stabilisation error."),
    _P("stabilization", "stable_points_percent", "Stable Points Percent", float, 0.25, 0.0, 1.0, "",
       "Fraction of points assumed stable in each frame."),
    _P("stabilization", "max_processing_iterations", "Max Processing Iterations", int, 50, 1, 100000, "",
       "Most optimisation iterations of assisted stabilisation."),
    # Export (the guide names the section without listing it; these are ours)
    _P("export", "include_brim_points", "Include Brim Points", bool, True,
       help="Write brim points to C3D and FBX."),
    _P("export", "use_stabilized_data", "Use Stabilized Data", bool, False,
       help="Export stabilised positions where they exist."),
    _P("export", "active_range_only", "Active Range Only", bool, False,
       help="Export the active range instead of the whole take."),
    _P("export", "include_interpolated", "Include Interpolated Samples", bool, True,
       help="Write interpolated samples (camera mask cleared) instead of leaving gaps."),
    # Show Again Flags
    _P("show_again", "show_version_check_dialog_on_startup", "Show Version Check Dialog On Startup", bool, True,
       help="Show a dialog at start-up when a newer version is available."),
    # Labelling
    _P("labelling", "navigate_missing_labels_only", "Navigate Missing Labels Only", bool, True,
       help="Select Next/Previous Label goes to labels missing on this frame."),
    # Tracker pane settings
    _P("tracker", "stop_after_n_frames", "Stop after N Frames", bool, False,
       help="Limit Track forward/back to N frames."),
    _P("tracker", "n_frames", "N", int, 10, 1, None, "frames", "Frames tracked when Stop after N Frames is on."),
    _P("tracker", "overwrite_existing_tracks", "Overwrite Existing Tracks", bool, False,
       help="Target tracking overwrites existing 2D data."),
    _P("tracker", "automatically_add_keyframes", "Automatically Add Keyframes", bool, True,
       help="Add a keyframe to the selected points before tracking when there is none."),
    _P("tracker", "stop_on_next_keyframe", "Stop On Next Keyframe", bool, True,
       help="Stop tracking at the next keyframe of any selected point."),
    _P("tracker", "allow_single_sensor_tracking", "Allow Single Sensor Tracking", bool, True,
       help="Reconstruct target-tracked points seen in one camera along its ray."),
    _P("tracker", "break_threshold", "Break Threshold", float, 0.9, 0.0, 1.0, "",
       "Tracking stops when the best patch scores below this."),
    _P("tracker", "update_timeline_every_frame", "Update Timeline Every Frame", bool, True,
       help="Refresh the continuity displays while tracking."),
    _P("tracker", "update_2d_view_every_frame", "Update 2D View Every Frame", bool, False,
       help="Show each frame while tracking (slower)."),
)
del _P

_BY_KEY: dict[str, PropertyDef] = {p.key: p for p in PROPERTY_TABLE}
assert len(_BY_KEY) == len(PROPERTY_TABLE), "duplicate property key"
assert all(p.group in GROUPS for p in PROPERTY_TABLE)


def property_def(key: str) -> PropertyDef:
    """Return the definition of ``group.name``.

    Raises
    ------
    CaraError
        For an unknown key, naming close matches.
    """
    try:
        return _BY_KEY[key]
    except KeyError:
        import difflib

        near = difflib.get_close_matches(key, list(_BY_KEY), n=3)
        hint = f" (did you mean {', '.join(near)}?)" if near else ""
        raise CaraError(f"unknown property {key!r}{hint}") from None


def defaults() -> dict[str, Any]:
    """All properties at their defaults, keyed ``group.name``."""
    return {p.key: p.default for p in PROPERTY_TABLE}


class Properties:
    """The values of every property of a project.

    Reads by attribute group, e.g. ``props.tracking.patch_match_threshold``, or by
    key, ``props["tracking.patch_match_threshold"]``.  Writes go through
    :meth:`set` (validated); in a project, through the ``SetProperty`` command so
    they can be undone.
    """

    def __init__(self, values: dict[str, Any] | None = None):
        self._values = defaults()
        if values:
            for k, v in values.items():
                if k in _BY_KEY:  # unknown keys from newer files are dropped, not fatal
                    self._values[k] = _BY_KEY[k].coerce(v)

    def __getitem__(self, key: str) -> Any:
        return self._values[property_def(key).key]

    def set(self, key: str, value: Any) -> Any:
        """Validate and store a value; return the stored (coerced) value."""
        pdef = property_def(key)
        v = pdef.coerce(value)
        self._values[key] = v
        return v

    def __getattr__(self, group: str) -> "_GroupView":
        if group.startswith("_") or group not in GROUPS:
            raise AttributeError(group)
        return _GroupView(self, group)

    def items(self) -> Iterator[tuple[str, Any]]:
        """``(key, value)`` in table order."""
        for p in PROPERTY_TABLE:
            yield p.key, self._values[p.key]

    def to_dict(self) -> dict[str, Any]:
        """A plain dict, for the project file."""
        return dict(self.items())

    def changed(self) -> dict[str, Any]:
        """Only the values that differ from the defaults."""
        return {k: v for k, v in self.items() if v != _BY_KEY[k].default}

    def copy(self) -> "Properties":
        return Properties(self._values)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Properties) and self._values == other._values


class _GroupView:
    __slots__ = ("_props", "_group")

    def __init__(self, props: Properties, group: str):
        self._props = props
        self._group = group

    def __getattr__(self, name: str) -> Any:
        key = f"{self._group}.{name}"
        if key not in _BY_KEY:
            raise AttributeError(key)
        return self._props._values[key]


def parse_set_options(items: list[str] | None) -> dict[str, Any]:
    """Parse ``--set GROUP.NAME=VALUE`` options into validated values.

    Raises
    ------
    CaraError
        For a malformed item, an unknown property or a bad value.
    """
    out: dict[str, Any] = {}
    for item in items or []:
        if "=" not in item:
            raise CaraError(f"--set needs GROUP.PROPERTY=VALUE, not {item!r}")
        key, value = item.split("=", 1)
        key = key.strip()
        out[key] = property_def(key).coerce(value.strip())
    return out
