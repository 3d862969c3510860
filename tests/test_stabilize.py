"""Stabilize Data [Manual] / [Assisted] and Align Data on a synthetic take with rig slip and expressions."""
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from carapost.core.document import Document
from carapost.core.errors import CaraError
from carapost.core.points import ST_NONE
from carapost.core.progress import Cancelled, Progress
from carapost.core.stabilize import apply_transforms, kabsch, most_stable
from carapost.core.stabilize_ops import align_data, stabilize_assisted, stabilize_manual, stabilized_positions
from carapost.core.stabilize_synthetic import make_slip_take
from carapost.io.cara import load_project, save_project
from support import REPO

FRAMES = 240


@pytest.fixture(scope="module")
def take():
    return make_slip_take(markers=40, frames=FRAMES, seed=3)


@pytest.fixture
def fresh():
    """A take of its own (for tests that edit it)."""
    return make_slip_take(markers=32, frames=120, seed=1)


def _ids(st, mask):
    return [st.face_ids[i] for i in np.flatnonzero(mask)]


def _slip_error(st, transforms) -> float:
    """RMS (mm) between the neutral face stabilised by ``transforms`` and by the true transforms."""
    got = apply_transforms(transforms, st.neutral)
    want = apply_transforms(st.truth, st.neutral)
    return float(np.sqrt(np.nanmean(np.sum((got - want) ** 2, axis=-1))))


def _poor_choice(st):
    """Two rigid points and two that move with expressions, as a user might pick."""
    rigid = _ids(st, st.rigid & st.gap_free)
    moving = _ids(st, ~st.rigid & st.gap_free)
    return rigid[:2] + moving[:2]


# ----------------------------------------------------------------- the maths
def test_kabsch_recovers_a_rotation_and_translation_with_weights_and_gaps():
    rng = np.random.default_rng(0)
    r = Rotation.from_rotvec(rng.normal(0, 0.3, (5, 3))).as_matrix()
    t = rng.normal(0, 20, (5, 3))
    src = rng.normal(0, 50, (5, 8, 3))
    dst = np.einsum("fij,fnj->fni", r, src) + t[:, None]
    src[:, 0] += 100.0                  # an outlier with weight 0
    w = np.ones((5, 8))
    w[:, 0] = 0
    src[1, 3] = np.nan                  # a missing point is ignored
    got = kabsch(src, dst, w)
    assert np.allclose(got[:, :, :3], r, atol=1e-9) and np.allclose(got[:, :, 3], t, atol=1e-7)
    w[2, 3:] = 0                        # frame 2 keeps two points: no transform
    assert np.isnan(kabsch(src, dst, w)[2]).all() and np.isfinite(kabsch(src, dst, w)[3]).all()


def test_most_stable_keeps_the_fraction_with_the_smallest_residuals():
    r2 = np.array([[5.0, 1.0, 3.0, 2.0, 4.0, 0.5, 9.0, 8.0], [1, 2, 3, 4, 5, 6, 7, 8.0]])
    present = np.ones_like(r2, bool)
    present[1, :4] = False
    s = most_stable(r2, present, 0.5)
    assert s[0].tolist() == [False, True, True, True, False, True, False, False]
    assert s[1].tolist() == [False] * 4 + [True, True, True, False]    # at least three of the four present


# ----------------------------------------------------------------- manual
def test_manual_stabilisation_recovers_the_rig_slip(take):
    p = take.project
    raw = {pid: p.points[pid].pos.copy() for pid in take.face_ids}
    assert _slip_error(take, np.broadcast_to(np.eye(3, 4), take.truth.shape)) > 1.0    # there is slip to undo
    cmd = stabilize_manual(p, _ids(take, take.rigid & take.gap_free), 0)
    assert _slip_error(take, cmd.new.transforms) < 0.05
    # the rigid points, stabilised, stay where they are on the base frame (noise is 0.03 mm)
    rigid = _ids(take, take.rigid & take.gap_free)
    y = stabilized_positions(p, slice(None), rigid)   # not applied yet: the raw positions
    assert np.allclose(y, np.stack([p.points[i].pos for i in rigid], 1), atol=1e-4)
    doc = Document(p)
    doc.run(cmd)
    y = stabilized_positions(p, slice(None), rigid)
    assert np.sqrt(np.mean(np.sum((y - y[0]) ** 2, axis=-1))) < 0.1
    assert cmd.report["weighted"] < 0.2 and "stabilisation error" in cmd.summary
    for pid, a in raw.items():          # the raw data is never changed
        assert np.array_equal(p.points[pid].pos, a, equal_nan=True)
    doc.undo()


def test_assisted_finds_the_stable_points_a_poor_manual_choice_missed(take):
    p = take.project
    poor = _poor_choice(take)
    manual = stabilize_manual(p, poor, 0)
    assisted = stabilize_assisted(p, poor, 0)
    assert assisted.report["weighted"] < 0.5 * manual.report["weighted"]
    assert assisted.report["base_frame"] < manual.report["base_frame"]
    assert _slip_error(take, assisted.new.transforms) < 0.1 < 0.5 < _slip_error(take, manual.new.transforms)
    assert assisted.report["converged"] and assisted.report["iterations"] <= 50
    # the points it leans on most are rigid ones
    col = {pid: i for i, pid in enumerate(take.face_ids)}
    assert all(take.rigid[col[i]] for i in assisted.report["most_used"][:5])


def test_inter_frame_weighting_trades_base_error_for_less_jitter(take):
    p = take.project
    p.properties.set("stabilization.inter_frame_weighting", 0.0)
    calm = stabilize_assisted(p, None, 0).report
    p.properties.set("stabilization.inter_frame_weighting", 5.0)
    smooth = stabilize_assisted(p, None, 0).report
    p.properties.set("stabilization.inter_frame_weighting", 1.0)
    assert smooth["inter_frame"] < calm["inter_frame"]
    assert calm["base_frame"] <= smooth["base_frame"]


def test_brim_points_join_only_when_asked(take):
    p = take.project
    n_face = len(take.face_ids)
    assert stabilize_assisted(p, None, 0, end=40).report["candidates"] == n_face
    p.properties.set("stabilization.use_brim_points", True)
    try:
        with_brim = stabilize_assisted(p, None, 0, end=40)
    finally:
        p.properties.set("stabilization.use_brim_points", False)
    assert with_brim.report["candidates"] == n_face + len(take.brim_ids)


def test_bad_requests_are_refused_naming_the_problem(fresh):
    p = fresh.project
    rigid = _ids(fresh, fresh.rigid & fresh.gap_free)
    gappy = _ids(fresh, ~fresh.gap_free)[0]
    with pytest.raises(CaraError, match="at least three"):
        stabilize_manual(p, rigid[:2], 0)
    with pytest.raises(CaraError, match="has no 3D data on frame"):
        stabilize_manual(p, rigid[:3] + [gappy], 0)
    p.active_range = (10, 60)
    with pytest.raises(CaraError, match="outside the frames being stabilised"):
        stabilize_assisted(p, rigid[:3], 5)
    p.active_range = (0, p.frame_count - 1)
    with pytest.raises(CaraError, match="at least three"):
        stabilize_assisted(p, rigid[:1], 0)
    with pytest.raises(CaraError, match="exactly three"):
        align_data(p, rigid[:2], 0)


def test_stabilising_only_the_active_range_leaves_other_frames_unstabilised(fresh):
    p = fresh.project
    p.active_range = (20, 80)
    doc = Document(p)
    doc.run(stabilize_manual(p, _ids(fresh, fresh.rigid & fresh.gap_free), 50))
    t = p.stabilization.transforms
    assert np.isnan(t[:20]).all() and np.isnan(t[81:]).all() and np.isfinite(t[20:81]).all()
    assert np.allclose(t[50], np.eye(3, 4))
    assert np.isnan(stabilized_positions(p, 10)).all()
    assert p.stabilization.base_frame == 50 and p.stabilization.frame_range == (20, 80)


def test_a_cancelled_assisted_run_changes_nothing(fresh):
    p = fresh.project
    before = p.digest()
    progress = Progress()
    progress.cancel()
    with pytest.raises(Cancelled):
        stabilize_assisted(p, None, 0, progress=progress)
    assert p.digest() == before and p.stabilization is None


# ----------------------------------------------------------------- align
def test_align_data_puts_the_three_points_on_the_axes(fresh):
    p = fresh.project
    doc = Document(p)
    rigid = _ids(fresh, fresh.rigid & fresh.gap_free)
    doc.run(stabilize_assisted(p, rigid[:3], 0))
    before = stabilized_positions(p, slice(None))
    a, b, c = rigid[0], rigid[3], rigid[5]
    doc.run(align_data(p, [a, b, c], 30))
    o, x, xy = stabilized_positions(p, 30, [a, b, c])
    assert np.allclose(o, 0, atol=1e-9)
    assert np.allclose(x[1:], 0, atol=1e-9) and x[0] > 0
    assert abs(xy[2]) < 1e-9 and xy[1] > 0
    # a rigid motion: distances between points are kept on every frame
    after = stabilized_positions(p, slice(None))
    d0 = np.linalg.norm(before[:, :, None] - before[:, None], axis=-1)
    d1 = np.linalg.norm(after[:, :, None] - after[:, None], axis=-1)
    assert np.allclose(d0, d1, atol=1e-6, equal_nan=True)
    # the guide's warning: stabilising again works on the raw data, so the alignment is gone
    doc.run(stabilize_assisted(p, rigid[:3], 0))
    assert p.stabilization.alignment is None
    assert not np.allclose(stabilized_positions(p, 30, [a])[0], 0, atol=1e-3)


def test_align_data_without_a_stabilisation_moves_the_whole_take(fresh):
    p = fresh.project
    rigid = _ids(fresh, fresh.rigid & fresh.gap_free)
    Document(p).run(align_data(p, rigid[:3], 0))
    s = p.stabilization
    assert s.method == "none" and np.isfinite(s.transforms).all()
    for f in (0, 60, 119):
        o = stabilized_positions(p, f, [rigid[0]])[0]
        raw = p.points[rigid[0]].pos[f]
        assert np.allclose(o, apply_transforms(s.alignment, raw[None])[0])
    assert np.allclose(stabilized_positions(p, 0, [rigid[0]]), 0, atol=1e-9)
    with pytest.raises(CaraError, match="one line"):
        q = p.points[rigid[1]].pos[0]
        mid = p.new_point(label="mid")
        mid.pos[0] = 2 * q - p.points[rigid[0]].pos[0]
        mid.status[0] = 1
        p.add_point(mid)
        align_data(p, [rigid[0], rigid[1], mid.id], 0)


# ----------------------------------------------------------------- undo and files
def test_undo_restores_every_previous_digest(fresh):
    p = fresh.project
    doc = Document(p)
    rigid = _ids(fresh, fresh.rigid & fresh.gap_free)
    digests = [p.digest()]
    for cmd in (stabilize_manual(p, _poor_choice(fresh), 0), stabilize_assisted(p, rigid[:3], 0),
                align_data(p, rigid[:3], 10)):
        doc.run(cmd)
        assert p.digest() != digests[-1]
        digests.append(p.digest())
    assert doc.stack.names()[-3:] == ["Stabilize Data [Manual]", "Stabilize Data [Assisted]", "Align Data"]
    for want in reversed(digests[:-1]):
        doc.undo()
        assert p.digest() == want
    assert p.stabilization is None
    for want in digests[1:]:
        doc.redo()
        assert p.digest() == want


def test_stabilisation_is_saved_and_loaded_identically(fresh, tmp_path):
    p = fresh.project
    doc = Document(p)
    rigid = _ids(fresh, fresh.rigid & fresh.gap_free)
    p.active_range = (5, 100)
    doc.run(stabilize_assisted(p, rigid[:3], 20))
    doc.run(align_data(p, rigid[:3], 20))
    save_project(p, tmp_path / "s.cara")
    q = load_project(tmp_path / "s.cara")
    assert q.digest() == p.digest()
    assert np.array_equal(stabilized_positions(q, slice(None)), stabilized_positions(p, slice(None)),
                          equal_nan=True)
    s, t = p.stabilization, q.stabilization
    assert (t.method, t.base_frame, t.frame_range, t.errors) == (s.method, s.base_frame, s.frame_range, s.errors)
    assert np.array_equal(t.point_ids, s.point_ids) and np.array_equal(t.alignment, s.alignment)
    # and a project without one stays without one
    doc.undo()
    doc.undo()
    save_project(p, tmp_path / "n.cara")
    assert load_project(tmp_path / "n.cara").stabilization is None


def test_old_project_files_load_unstabilised():
    p = load_project(REPO / "tests" / "data" / "golden_v1.cara")
    assert p.stabilization is None
    want = np.array([x.pos[3] if x.status[3] != ST_NONE else [np.nan] * 3 for x in p.points.values()], float)
    assert np.array_equal(stabilized_positions(p, 3), want, equal_nan=True)    # views get the raw positions


# ----------------------------------------------------------------- exports and scripting
def test_c3d_export_writes_stabilised_positions_when_asked(fresh, tmp_path):
    from carapost.io.c3d import read_c3d
    from carapost.io.export_c3d import export_c3d

    p = fresh.project
    p.active_range = (0, 99)
    Document(p).run(stabilize_manual(p, _ids(fresh, fresh.rigid & fresh.gap_free), 0))
    export_c3d(p, tmp_path / "raw.c3d")
    p.properties.set("export.use_stabilized_data", True)
    export_c3d(p, tmp_path / "stab.c3d")
    raw, stab = read_c3d(tmp_path / "raw.c3d"), read_c3d(tmp_path / "stab.c3d")
    want = stabilized_positions(p, slice(None))
    assert np.allclose(stab.positions[:100], want[:100], atol=0.01, equal_nan=True)
    assert np.isnan(stab.positions[100:]).all()           # frames outside the stabilised range: missing
    assert not np.allclose(raw.positions[:100], stab.positions[:100], atol=0.1, equal_nan=True)


def test_scripting_api_stabilises_aligns_and_reads_back(fresh, tmp_path):
    from carapost.api import CaraExport, CaraProcess

    proc = CaraProcess.from_project(fresh.project)
    rigid = _ids(fresh, fresh.rigid & fresh.gap_free)
    labels = [fresh.project.points[i].label for i in rigid[:4]]
    manual = proc.stabilize(labels)
    assisted = proc.stabilize_assisted(rigid[:3])
    assert set(manual) >= {"base_frame", "inter_frame", "weighted"} and assisted["weighted"] > 0
    proc.align_data(*rigid[:3], frame=0)
    proc.save(tmp_path / "api.cara")
    e = CaraExport(tmp_path / "api.cara")
    got = e.point_3d_stabilized(rigid[0])
    assert got.shape == (fresh.project.frame_count, 3) and np.allclose(got[0], 0, atol=1e-9)
    assert np.allclose(e.point_3d(rigid[0]), fresh.project.points[rigid[0]].pos)   # raw kept
    assert e.stabilization_transforms().shape == (fresh.project.frame_count, 3, 4)
    proc.undo()
    proc.undo()
    proc.undo()
    assert proc.project.stabilization is None
