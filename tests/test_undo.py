"""The undo stack: every edit undone returns the project to exactly its first state."""
import numpy as np
import pytest

from carapost.core.commands import CompoundCommand
from carapost.core.detections import make_detections
from carapost.core.document import Document
from carapost.core.edits import (AddPoints, ClearPointRange, DeletePoints, RenamePoint, RotateSensors,
                                 SetFrameDetections, SetLabels, SetPointData, SetProperties, SetRange,
                                 SetSticks, ShiftImageOffset, Unlabel)
from carapost.core.errors import CaraError
from carapost.core.points import SRC_PATCH, ST_INTERPOLATED
from carapost.core.project import Stick
from support import make_project


def _random_command(rng, project):
    ids = list(project.points)
    F = project.frame_count
    kind = int(rng.integers(0, 13))
    if kind == 0 or not ids:
        pts = []
        for _ in range(int(rng.integers(1, 3))):
            pt = project.new_point(point_id=project.next_point_id + len(pts))
            f = int(rng.integers(0, F))
            pt.pos[f] = rng.normal(size=3)
            pt.status[f] = 1
            pts.append(pt)
        return AddPoints(pts)
    pid = int(rng.choice(ids))
    a, b = sorted(int(x) for x in rng.integers(0, F, 2))
    if kind == 1:
        return DeletePoints([pid])
    if kind == 2:
        return ClearPointRange([pid], a, b)
    if kind == 3:
        return ClearPointRange([pid], a, b, sensors=[int(rng.integers(0, 4))], name="Detach Detections")
    if kind == 4:
        n = b - a + 1
        return SetPointData([(pid, a, {"pos": rng.normal(size=(n, 3)), "status": np.full(n, ST_INTERPOLATED, np.uint8),
                                       "src": np.full((n, 4), SRC_PATCH, np.uint8)})], name="Interpolate Gaps")
    if kind == 5:
        return RenamePoint(pid, str(rng.choice(["Nose_Tip", "Chin", "Brow_L", ""])))
    if kind == 6:
        return Unlabel([pid])
    if kind == 7:
        return SetLabels(list(rng.permutation(project.labels + ["X"]))[:3])
    if kind == 8:
        n = int(rng.integers(0, 5))
        return SetFrameDetections({(int(rng.integers(0, 4)), a): make_detections(rng.uniform(0, 100, n), rng.uniform(0, 100, n))})
    if kind == 9:
        return SetRange(str(rng.choice(["active", "view"])), a, b)
    if kind == 10:
        return SetProperties({"tracking.patch_match_threshold": float(rng.uniform(0, 1))})
    if kind == 11:
        return CompoundCommand("Rotate and shift", [RotateSensors([0, 2], int(rng.choice([-1, 1]))),
                                                   ShiftImageOffset([1])])
    other = int(rng.choice(ids))
    return SetSticks(project.sticks + [Stick(pid, other)])


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_long_sequence_undone_returns_exactly_the_first_state(seed):
    project = make_project(frames=60, points=8, seed=seed)
    doc = Document(project)
    rng = np.random.default_rng(seed)
    first = project.digest()
    digests = [first]
    for _ in range(300):
        doc.run(_random_command(rng, project))
        digests.append(project.digest())
    assert len(set(digests)) > 100  # the edits really changed things
    for i in range(300, 0, -1):
        doc.undo()
        assert project.digest() == digests[i - 1], f"undo of step {i} ({doc.stack.redo_name()})"
    assert project.digest() == first
    for i in range(1, 301):
        doc.redo()
        assert project.digest() == digests[i]


def test_history_stores_only_slices():
    project = make_project(frames=10_000, points=3)
    doc = Document(project)
    pid = next(iter(project.points))
    doc.run(ClearPointRange([pid], 100, 109))
    per_frame = sum(a[0].nbytes for a in project.points[pid].arrays.values())
    assert doc.stack.memory_bytes() < 10 * per_frame + 4096
    doc.run(ClearPointRange([pid], 0, 9_999))
    assert doc.stack.memory_bytes() > 10_000 * per_frame


def test_failed_command_changes_nothing_and_is_not_pushed(project):
    doc = Document(project)
    before = project.digest()
    with pytest.raises(CaraError):
        doc.run(DeletePoints([list(project.points)[0], 9999]))
    with pytest.raises(CaraError):
        doc.run(SetRange("active", 10, project.frame_count + 5))
    assert project.digest() == before
    assert len(doc.stack) == 0


def test_compound_rolls_back_on_failure(project):
    doc = Document(project)
    before = project.digest()
    with pytest.raises(CaraError):
        doc.run(CompoundCommand("x", [RotateSensors([0], 1), DeletePoints([12345])]))
    assert project.digest() == before


def test_redo_branch_is_discarded_and_clean_state_tracked(project):
    doc = Document(project)
    doc.stack.mark_clean()
    doc.run(RotateSensors([0], 1))
    assert doc.modified
    doc.undo()
    assert not doc.modified
    doc.run(RotateSensors([1], 1))
    assert doc.stack.names() == ["Rotate Selected Sensors Clockwise"]
    assert not doc.stack.can_redo()


def test_set_index_and_clear(project):
    doc = Document(project)
    start = project.digest()
    for s in range(4):
        doc.run(RotateSensors([s], 1))
    end = project.digest()
    doc.stack.set_index(0)
    assert project.digest() == start
    doc.stack.set_index(4)
    assert project.digest() == end
    doc.stack.clear()
    assert len(doc.stack) == 0 and not doc.stack.can_undo() and doc.stack.memory_bytes() == 0


def test_rename_moves_label_and_undo_restores(project):
    doc = Document(project)
    a, b = list(project.points)[:2]
    project.points[a].label = "Nose_Tip"
    doc.run(RenamePoint(b, "Nose_Tip"))
    assert project.points[b].label == "Nose_Tip" and project.points[a].label == ""
    assert "Nose_Tip" in project.labels
    doc.undo()
    assert project.points[a].label == "Nose_Tip" and project.points[b].label != "Nose_Tip"


def test_listeners_and_selection_cleanup(project):
    doc = Document(project)
    seen = []
    doc.add_listener(seen.append)
    pid = list(project.points)[0]
    doc.select_points([pid])
    doc.run(DeletePoints([pid]))
    assert pid not in doc.selection.points
    assert "project" in seen and "selection" in seen
