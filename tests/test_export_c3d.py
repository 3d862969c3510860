"""C3D export of a project, read back by the independent `c3d` package."""
import c3d as c3dpkg
import numpy as np

from carapost.io.export_c3d import export_c3d
from support import make_export_project, remove_marker_detection


def _read(path):
    with open(path, "rb") as f:
        r = c3dpkg.Reader(f)
        labels = [s.strip() for s in r.point_labels]
        frames = [pts.copy() for _i, pts, _a in r.read_frames()]
    return labels, np.array(frames)


def test_export_labels_positions_residuals_masks(tmp_path):
    p, a, b, c = make_export_project()
    out = tmp_path / "t.c3d"
    export_c3d(p, out)
    labels, fr = _read(out)
    assert labels == ["Nose_Tip", f"Point_{b.id}", "Brim_0"]
    assert np.allclose(fr[:, 0, :3], a.pos, atol=1e-3)
    word = fr[:, 0, 3]
    # measured: residual >= 0, mask of sensors 0, 2, 3
    assert np.all(word[[0, 1, 2, 7, 19]] >= 0)
    # b: missing outside 3..7
    assert np.all(fr[[0, 1, 2, 8, 19], 1, 3] < 0)
    assert np.allclose(fr[3:8, 1, :3], [1.25, -2.5, 3.75], atol=1e-3)
    # our reader agrees and gives the masks
    from carapost.io.c3d import read_c3d

    d = read_c3d(out)
    assert list(d.camera_masks[[0, 1], 0]) == [0b1101, 0b1101]
    assert d.camera_masks[5, 0] == 0 and d.camera_masks[6, 0] == 0  # interpolated / single-sensor: cleared
    assert np.isnan(d.positions[0, 1]).all()
    assert np.allclose(d.residuals[0, 0], 0.5, atol=abs(d.scale))
    p.properties.set("export.include_brim_points", False)
    export_c3d(p, out)
    assert _read(out)[0] == ["Nose_Tip", f"Point_{b.id}"]


def test_export_of_a_tracked_take_with_interpolated_and_single_sensor_samples(tmp_path):
    """Track a synthetic take, interpolate its gaps, export: the `c3d` package reads back every sample."""
    from carapost.core.gapfill_ops import interpolate_gaps
    from carapost.core.points import SRC_NONE, ST_INTERPOLATED, ST_NONE, ST_SINGLE
    from carapost.core.tracking import track
    from carapost.core.tracking.synthetic_take import initialise, make_take

    sc = make_take(35, 80, seed=0, hidden_markers=4)
    initialise(sc, 0)
    for f in range(30, 36):                  # marker 5 seen by one camera only: single-sensor samples
        for s in (1, 2, 3):
            if sc.face_det[f, s, 5] >= 0:
                remove_marker_detection(sc, f, s, 5)
    pr = sc.project
    track(pr, 0, 1).do(pr)
    gappy = [q.id for q in pr.face_points() if np.any(q.status == ST_NONE)]
    interpolate_gaps(pr, point_ids=gappy[: len(gappy) // 2]).do(pr)        # the others keep their gaps
    pts = [q for q in pr.points.values()]
    status = np.array([q.status for q in pts])                    # (P, F)
    assert np.any(status == ST_INTERPOLATED) and np.any(status == ST_SINGLE) and np.any(status == ST_NONE)
    out = tmp_path / "tracked.c3d"
    export_c3d(pr, out)
    with open(out, "rb") as f:
        r = c3dpkg.Reader(f)
        labels = [s.strip() for s in r.point_labels]
        assert r.point_rate == pr.frame_rate
        frames = np.array([pts_.copy() for _i, pts_, _a in r.read_frames(camera_sum=False)])   # (F, P, 5)
    from carapost.io.export_c3d import exported_points

    exported = exported_points(pr)
    assert labels == [q.label or f"Point_{q.id}" for q in exported]
    for k, q in enumerate(exported):
        have = q.status != ST_NONE
        assert np.all(frames[~have, k, 3] < 0)                   # missing: invalid
        assert np.allclose(frames[have, k, :3], q.pos[have], atol=1e-3)
        assert np.all(frames[have, k, 3] >= 0)
        meas = have & (q.status != ST_INTERPOLATED) & (q.status != ST_SINGLE)
        want = (q.src != SRC_NONE) @ (1 << np.arange(pr.sensor_count))
        assert np.array_equal(frames[meas, k, 4].astype(int), want[meas])
        assert np.all(frames[have & ~meas, k, 4] == 0)           # interpolated / single-sensor: no cameras
