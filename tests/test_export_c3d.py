"""C3D export of a project, read back by the independent `c3d` package."""
import c3d as c3dpkg
import numpy as np

from carapost.io.export_c3d import export_c3d
from support import make_export_project


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
