"""File > Import XCP into a take: cameras per frame from KeyFrames, undoable."""
import logging

import numpy as np
import pytest

from carapost.core.document import Document
from carapost.core.errors import CaraError
from carapost.io import cara
from carapost.io.imports import import_xcp
from carapost.io.xcp import write_xcp, xcp_from_cameras
from support import make_project, shared_file


def test_import_moving_cameras(tmp_path):
    p = make_project(frames=30, with_rig=True)
    cams = p.rig.cameras
    kfs = []
    for s, c in enumerate(cams):
        moved = c.with_pose(c.rotation, c.position + np.array([0, 0, 5.0 + s]))
        kfs.append([(0, c), (10, moved)])
    write_xcp(tmp_path / "moving.xcp", xcp_from_cameras(kfs))
    q = make_project(frames=30)
    doc = Document(q)
    before = q.digest()
    doc.run(import_xcp(q, tmp_path / "moving.xcp"))
    assert np.allclose(q.rig.camera(2, 9).position, cams[2].position)
    assert np.allclose(q.rig.camera(2, 10).position, cams[2].position + [0, 0, 7])
    assert np.allclose(q.rig.camera(2, 29).position, cams[2].position + [0, 0, 7])
    cara.save_project(q, tmp_path / "t.cara")
    r = cara.load_project(tmp_path / "t.cara")
    assert np.allclose(r.rig.camera(3, 20).position, cams[3].position + [0, 0, 8])
    doc.undo()
    assert q.digest() == before and q.rig is None


def test_import_real_nexus_xcp_uses_first_cameras(caplog):
    xcp = shared_file("xcp", "opencap-core_testCalibration.xcp")
    q = make_project(frames=5)
    with caplog.at_level(logging.WARNING):
        cmd = import_xcp(q, xcp, log=logging.getLogger("carapost"))
    Document(q).run(cmd)
    assert q.rig.sensors == 4
    assert "25 cameras" in caplog.text
    for s in range(4):
        assert q.rig.camera(s, 0).depth(np.zeros((1, 3)))[0] > 0


def test_import_xcp_with_too_few_cameras(tmp_path):
    p = make_project(frames=5, sensors=2, with_rig=True)
    write_xcp(tmp_path / "two.xcp", xcp_from_cameras([[(0, c)] for c in p.rig.cameras]))
    with pytest.raises(CaraError, match="2 cameras; the take has 4 sensors"):
        import_xcp(make_project(frames=5), tmp_path / "two.xcp")
