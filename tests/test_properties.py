import pytest

from carapost.core.errors import CaraError
from carapost.core.properties import GROUPS, PROPERTY_TABLE, Properties, parse_set_options, property_def

# The guide's defaults (Reference Guide, Properties pane and Tracker pane sections).
GUIDE_DEFAULTS = {
    "display.point_labels_all": False, "display.point_labels_selected": True,
    "display.point_labels_pre_selected": True, "display.font_size": 10,
    "selection.points": True, "selection.detections": True, "selection.sensors": True, "selection.sticks": True,
    "blob.white_min_radius": 4, "blob.white_max_radius": 50, "blob.black_min_radius": 4,
    "blob.black_max_radius": 50, "blob.find_black_blobs": True, "blob.find_white_blobs": False,
    "blob.black_threshold": 0.4, "blob.white_threshold": 0.4,
    "initialize_3d.max_allowed_depth": 35, "initialize_3d.max_3d_distance_to_merge": 5,
    "initialize_3d.max_allowed_symmetric_epipolar_distance": 5,
    "initialize_from_rom.rom_face_point_tracking_distance": 50,
    "initialize_from_rom.rom_brim_point_tracking_distance": 30,
    "initialize_from_rom.rom_max_allowed_3d_point_error": 5,
    "tracking.patch_match_threshold": 0.8, "tracking.face_point_tracking_distance": 35,
    "tracking.face_point_max_elastic_prediction_distance": 15, "tracking.brim_point_tracking_distance": 15,
    "tracking.patch_match_size": 15, "tracking.remove_bad_2d_projections": True,
    "tracking.max_allowed_2d_projection_error": 5, "tracking.remove_bad_3d_points": True,
    "tracking.max_allowed_3d_point_error": 5, "tracking.allow_single_sensor_tracking": True,
    "tracking.single_sensor_tracking_threshold": 0.5, "tracking.blob_size_difference_threshold": 0.75,
    "gap_filling.overwrite_existing_filled_gaps": False, "gap_filling.use_forwards_prediction": True,
    "gap_filling.use_backwards_prediction": True, "gap_filling.allow_single_sensor_tracking_gap_filling": True,
    "stabilization.use_brim_points": False, "stabilization.base_frame_weighting": 1.0,
    "stabilization.inter_frame_weighting": 1.0, "stabilization.stable_points_percent": 0.25,
    "stabilization.max_processing_iterations": 50,
    "show_again.show_version_check_dialog_on_startup": True, "labelling.navigate_missing_labels_only": True,
    "tracker.break_threshold": 0.9,
}


def test_every_guide_default():
    props = Properties()
    for key, value in GUIDE_DEFAULTS.items():
        assert props[key] == value, key
        assert type(props[key]) is property_def(key).type


def test_every_group_of_the_guide_is_declared():
    groups = {p.group for p in PROPERTY_TABLE}
    for g in ("display", "selection", "blob", "initialize_3d", "initialize_from_rom", "tracking", "gap_filling",
              "stabilization", "export", "show_again", "labelling"):
        assert g in groups and g in GROUPS


def test_attribute_access():
    props = Properties()
    assert props.tracking.patch_match_threshold == 0.8
    props.set("tracking.patch_match_threshold", "0.7")
    assert props.tracking.patch_match_threshold == 0.7
    with pytest.raises(AttributeError):
        props.tracking.no_such_thing


@pytest.mark.parametrize("key,value,expected", [
    ("blob.find_white_blobs", "true", True), ("blob.find_white_blobs", "0", False),
    ("gap_filling.use_backwards_prediction", "false", False), ("tracking.patch_match_size", "21", 21),
    ("blob.black_threshold", "0.55", 0.55),
])
def test_coerce(key, value, expected):
    assert property_def(key).coerce(value) == expected


@pytest.mark.parametrize("key,value", [
    ("blob.black_threshold", "1.5"), ("blob.black_threshold", "-0.1"), ("blob.find_white_blobs", "maybe"),
    ("tracking.patch_match_size", "2.5"), ("blob.black_threshold", "nan"), ("stabilization.max_processing_iterations", "0"),
])
def test_bad_values_are_refused(key, value):
    with pytest.raises(CaraError, match=key.replace(".", r"\.")):
        property_def(key).coerce(value)


def test_unknown_property_suggests():
    with pytest.raises(CaraError, match="did you mean tracking.patch_match_threshold"):
        property_def("tracking.patch_match_treshold")


def test_parse_set_options():
    vals = parse_set_options(["tracking.patch_match_threshold=0.7", "blob.find_white_blobs=true",
                              "gap_filling.use_backwards_prediction=false"])
    assert vals == {"tracking.patch_match_threshold": 0.7, "blob.find_white_blobs": True,
                    "gap_filling.use_backwards_prediction": False}
    with pytest.raises(CaraError):
        parse_set_options(["tracking.patch_match_threshold"])


def test_changed_and_unknown_keys_from_file():
    props = Properties({"tracking.patch_match_threshold": 0.6, "future.thing": 3})
    assert props.changed() == {"tracking.patch_match_threshold": 0.6}


def test_restore_defaults_is_one_undoable_command(project):
    from carapost.core.document import Document
    from carapost.core.edits import SetProperties, restore_properties_to_defaults

    doc = Document(project)
    doc.run(SetProperties({"tracking.patch_match_threshold": 0.6, "blob.find_white_blobs": True}))
    doc.run(restore_properties_to_defaults())
    assert project.properties.changed() == {}
    doc.undo()
    assert project.properties.changed() == {"tracking.patch_match_threshold": 0.6, "blob.find_white_blobs": True}
    assert doc.stack.names()[-1] == "Restore Properties To Defaults"
