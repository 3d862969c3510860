"""Manual editing commands (carapost.core.editing), without Qt."""
from __future__ import annotations

import numpy as np
import pytest

from carapost.core import editing
from carapost.core.actions import ACTIONS, mnemonic_titles, shortcut_table
from carapost.core.detections import make_detections
from carapost.core.document import Document
from carapost.core.errors import CaraError
from carapost.core.points import SRC_DETECTION, SRC_KEYFRAME, SRC_NONE, ST_INTERPOLATED, ST_NONE, ST_RECONSTRUCTED
from support import make_project

TRUE_X = np.array([[5.0, -8.0, 10.0], [-20.0, 12.0, -5.0], [30.0, 25.0, 0.0]])


def take_with_markers(frames: int = 10):
    """A rigged take whose detections 0..2 in every sensor are the projections of TRUE_X (plus a stray one)."""
    p = make_project(frames=frames, points=0, with_rig=True)
    p.labels = ["Nose", "Chin"]
    for f in range(frames):
        for s in range(p.sensor_count):
            uv = p.rig.camera(s, f).project(TRUE_X)
            x = np.append(uv[:, 0], 100.0 + s)
            y = np.append(uv[:, 1], 100.0)
            p.detections[s].set_frame(f, make_detections(x, y, 9.0, 7.0, 10.0, 0.9))
    return p


def test_merge_detections_in_two_sensors_triangulates_a_new_point():
    p = take_with_markers()
    doc = Document(p)
    cmd = doc.run(editing.merge(p, 3, [], [(0, 3, 1), (2, 3, 1)]))
    (pid,) = cmd.select_after
    pt = p.point(pid)
    assert pt.status[3] == ST_RECONSTRUCTED
    np.testing.assert_allclose(pt.pos[3], TRUE_X[1], atol=1e-2)
    assert list(pt.src[3]) == [SRC_DETECTION, SRC_NONE, SRC_DETECTION, SRC_NONE]
    assert list(pt.det[3, [0, 2]]) == [1, 1]
    assert pt.residual[3] < 0.01
    doc.undo()
    assert pid not in p.points
    doc.redo()
    assert p.point(pid).status[3] == ST_RECONSTRUCTED


def test_merge_refuses_two_detections_in_one_sensor():
    p = take_with_markers()
    with pytest.raises(CaraError, match="two selected detections are in sensor 1"):
        editing.merge(p, 2, [], [(1, 2, 0), (1, 2, 1)])


def test_merge_refuses_detection_on_another_frame_and_empty_selection():
    p = take_with_markers()
    with pytest.raises(CaraError, match="not on the current frame"):
        editing.merge(p, 2, [], [(1, 3, 0)])
    with pytest.raises(CaraError, match="needs two or more points"):
        editing.merge(p, 2, [], [])


def test_merge_two_points_combines_frames_first_selected_wins():
    p = take_with_markers(frames=12)
    doc = Document(p)
    a = doc.run(editing.merge(p, 2, [], [(0, 2, 0), (1, 2, 0)])).select_after[0]
    b = doc.run(editing.merge(p, 2, [], [(2, 2, 0)])).select_after[0]
    doc.run(editing.merge(p, 6, [b], [(2, 6, 0), (3, 6, 0)]))  # b alone on frame 6
    doc.run(editing.rename_point(p, b, "Chin"))
    before = p.digest()
    doc.run(editing.merge(p, 2, [a, b], []))
    pa = p.point(a)
    assert b not in p.points
    # frame 2: a's sensors 0, 1 plus b's sensor 2, re-triangulated from three views
    assert list(pa.src[2]) == [SRC_DETECTION, SRC_DETECTION, SRC_DETECTION, SRC_NONE]
    np.testing.assert_allclose(pa.pos[2], TRUE_X[0], atol=1e-2)
    # frame 6 only b had data: it moves to a
    assert pa.status[6] == ST_RECONSTRUCTED and list(pa.det[6, 2:]) == [0, 0]
    assert pa.label == "Chin"   # the unlabelled first point takes the other's label
    doc.undo()
    assert p.digest() == before


def test_merge_detaches_a_detection_from_its_previous_point():
    p = take_with_markers()
    doc = Document(p)
    a = doc.run(editing.merge(p, 4, [], [(0, 4, 2), (1, 4, 2)])).select_after[0]
    b = doc.run(editing.merge(p, 4, [], [(1, 4, 2), (3, 4, 2)])).select_after[0]
    assert p.point(a).src[4, 1] == SRC_NONE
    assert p.point(b).det[4, 1] == 2


def test_merge_with_label_renames():
    p = take_with_markers()
    doc = Document(p)
    pid = doc.run(editing.merge(p, 0, [], [(0, 0, 0), (1, 0, 0)], label="Nose",
                                name="Merge and Select Next Label")).select_after[0]
    assert p.point(pid).label == "Nose"
    assert doc.stack.names()[-1] == "Merge and Select Next Label"


def test_create_points_delete_and_index_fix():
    p = take_with_markers()
    doc = Document(p)
    ids = doc.run(editing.create_points_from_detections(p, [(0, 1, 0), (0, 1, 2)])).select_after
    assert len(ids) == 2
    assert p.point(ids[1]).det[1, 0] == 2
    # deleting detection 1 of that frame shifts the second point's index down
    doc.run(editing.delete_selected(p, [], [(0, 1, 1)]))
    assert p.detections[0].count(1) == 3
    assert p.point(ids[1]).det[1, 0] == 1
    doc.run(editing.delete_selected(p, [ids[0]], [(0, 1, 1)]))
    assert ids[0] not in p.points
    assert p.point(ids[1]).src[1, 0] == SRC_NONE
    doc.undo()
    doc.undo()
    assert p.point(ids[1]).det[1, 0] == 2 and p.detections[0].count(1) == 4


def test_detach_clear_split_unlabel():
    p = take_with_markers(frames=8)
    doc = Document(p)
    pid = doc.run(editing.merge(p, 0, [], [(0, 0, 0), (1, 0, 0), (2, 0, 0)])).select_after[0]
    for f in range(1, 8):
        doc.run(editing.merge(p, f, [pid], [(0, f, 0), (1, f, 0), (2, f, 0)]))
    pt = p.point(pid)
    doc.run(editing.detach_detections(p, [pid], [1], 2, 2, "Detach Detections [Current Frame]"))
    assert pt.src[2, 1] == SRC_NONE and pt.src[3, 1] == SRC_DETECTION
    doc.run(editing.clear_selected(p, [pid], 4, 4, "Clear Selected [Current Frame]"))
    assert pt.status[4] == ST_NONE
    new = doc.run(editing.split_point(p, pid, 6)).select_after[0]
    assert not pt.present()[6:].any() and p.point(new).present()[6:].all()
    with pytest.raises(CaraError, match="has no data"):
        editing.split_point(p, pid, 7)
    doc.run(editing.rename_point(p, pid, "Nose"))
    doc.run(editing.unlabel(p, [pid]))
    assert pt.label == ""
    with pytest.raises(CaraError, match="needs a channel"):
        editing.detach_detections(p, [pid], [], 0, 0, "Detach Detections [Current Frame]")


def test_clear_active_range_and_remove_interpolated():
    p = make_project(frames=30, points=4)
    doc = Document(p)
    pid = next(iter(p.points))
    pt = p.point(pid)
    pt.status[0:5] = ST_INTERPOLATED
    pt.pos[0:5] = 1.0
    doc.run(editing.remove_interpolated(p, [pid], 0, 29))
    assert (pt.status[0:5] == ST_NONE).all() and np.isnan(pt.pos[0:5]).all()
    with pytest.raises(CaraError, match="no interpolated"):
        editing.remove_interpolated(p, [], 0, 29)
    p.active_range = (10, 19)
    doc.run(editing.clear_active_range(p))
    assert not any(q.present()[10:20].any() for q in p.points.values())


def test_labels_sticks_channels():
    p = take_with_markers()
    doc = Document(p)
    a = doc.run(editing.merge(p, 0, [], [(0, 0, 0), (1, 0, 0)], label="Nose")).select_after[0]
    b = doc.run(editing.merge(p, 0, [], [(0, 0, 1), (1, 0, 1)])).select_after[0]
    c = doc.run(editing.merge(p, 0, [], [(0, 0, 2), (1, 0, 2)])).select_after[0]
    doc.run(editing.RenameLabel("Nose", "NoseTip"))
    assert p.point(a).label == "NoseTip" and p.labels[0] == "NoseTip"
    doc.run(editing.reorder_labels(p, ["Chin", "NoseTip"]))
    doc.run(editing.delete_labels(p, ["NoseTip"]))
    assert p.point(a).label == "" and p.labels == ["Chin"]
    doc.run(editing.create_stick(p, [a, b]))
    with pytest.raises(CaraError, match="already have a stick"):
        editing.create_stick(p, [b, a])
    doc.run(editing.create_stick_mesh(p, 0))
    assert len(p.sticks) == 3
    doc.run(editing.set_stick_color(p, [0], (255, 0, 0)))
    assert p.sticks[0].color == (255, 0, 0) and p.sticks[1].color != (255, 0, 0)
    doc.run(editing.SetChannelSelection([2, 0]))
    assert p.selected_channels(1) == [0, 2]
    doc.undo()
    assert p.selected_channels(1) == [1]
    doc.run(editing.clear_all_labels(p))
    assert p.labels == [] and c in p.points


def test_target_tracks():
    p = take_with_markers()
    doc = Document(p)
    uv0 = p.rig.camera(0, 1).project(TRUE_X[2])
    uv3 = p.rig.camera(3, 1).project(TRUE_X[2])
    pid = doc.run(editing.add_target_track(p, 0, 1, uv0)).select_after[0]
    assert p.point(pid).src[1, 0] == SRC_KEYFRAME and (1, 0) in p.point(pid).keyframes
    doc.run(editing.edit_target_track(p, pid, 3, 1, uv3))
    np.testing.assert_allclose(p.point(pid).pos[1], TRUE_X[2], atol=1e-2)
    assert editing.next_keyframe(p, [pid], 0, 1) == 1
    assert editing.next_keyframe(p, [pid], 1, 1) == 1   # wraps to the first
    assert editing.next_keyframe(p, [], 1, 1) is None


def test_navigation_queries():
    p = make_project(frames=40, points=0)
    doc = Document(p)
    a = p.new_point(label="A")
    a.status[[1, 2, 3, 6, 7, 12, 13]] = ST_RECONSTRUCTED
    b = p.new_point(label="B", point_id=a.id + 1)
    b.status[[1, 2, 5, 6]] = ST_RECONSTRUCTED
    from carapost.core.edits import AddPoints

    doc.run(AddPoints([a, b]))
    assert list(editing.gap_starts(a)) == [4, 8]
    assert editing.next_gap(a, 0) == 3 and editing.next_gap(a, 3) == 7 and editing.next_gap(a, 9) == 3
    assert editing.point_with_fewest_gaps(p) == b.id
    p.labels = ["A", "B", "C"]
    assert editing.label_states(p, 1) == {"A": "assigned", "B": "assigned", "C": "unassigned"}
    assert editing.label_states(p, 4)["A"] == "absent"
    assert editing.next_label(p, None, 1, 1, missing_only=False) == "A"
    assert editing.next_label(p, "A", 1, 1, missing_only=True) == "B"   # no 2D: disconnected
    assert editing.next_label(p, "C", 1, 1, missing_only=False) == "A"
    assert editing.next_label(p, "A", 1, -1, missing_only=False) == "C"


def test_registry_titles_and_mnemonics():
    table = shortcut_table()
    assert {"menu": "Edit", "action": "Merge", "shortcut": "M"} in table
    assert len({a.id for a in ACTIONS}) == len(ACTIONS)
    shortcuts = [a.shortcut for a in ACTIONS if a.shortcut]
    assert len(shortcuts) == len(set(shortcuts)), "a shortcut is bound twice"
    unavailable = [a for a in ACTIONS if not a.available]
    assert unavailable and all(a.tooltip.startswith("Not available") for a in unavailable)
    texts = mnemonic_titles(["Open", "Save", "Save As", "Exit"], fixed={3: "x"})
    assert texts == ["&Open", "&Save", "Save &As", "E&xit"]
