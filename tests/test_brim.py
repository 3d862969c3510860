import numpy as np
import pytest

from carapost.core.brim import DEFAULT_BRIMS, default_brim
from carapost.core.errors import CaraError
from carapost.io.brim_svg import brim_to_svg, parse_transform, read_brim_svg


@pytest.mark.parametrize("version", DEFAULT_BRIMS)
def test_default_brims_are_planar_and_not_self_similar(version):
    b = default_brim(version)
    assert len(b) >= 12 and np.all(b.markers[:, 2] == 0)
    xy = b.markers[:, :2]
    d = np.linalg.norm(xy[:, None] - xy[None], axis=2)
    assert d[~np.eye(len(xy), dtype=bool)].min() > 5  # markers well apart
    # no mirror (x or y) maps the layout onto itself
    for flip in (np.array([-1, 1]), np.array([1, -1]), np.array([-1, -1])):
        f = xy * flip
        f = f - f.mean(0) + xy.mean(0)
        nearest = np.linalg.norm(f[:, None] - xy[None], axis=2).min(1)
        assert nearest.max() > 2


def test_svg_round_trip_and_transforms(tmp_path):
    b = default_brim("v2.0")
    (tmp_path / "b.svg").write_text(brim_to_svg(b))
    r = read_brim_svg(tmp_path / "b.svg")
    assert np.allclose(r.markers, b.markers, atol=1e-6)
    assert "<circle" in r.svg
    svg = ('<svg xmlns="http://www.w3.org/2000/svg" viewBox="0 0 200 50">'
           '<g transform="translate(10,5)"><circle cx="1" cy="2" r="1"/>'
           '<g transform="rotate(90)"><circle cx="1" cy="0" r="1"/></g></g>'
           '<circle cx="3" cy="4" r="1" transform="matrix(2 0 0 2 1 1)"/>'
           '<circle cx="0" cy="0" r="1" transform="scale(3) translate(1 1)"/></svg>')
    (tmp_path / "t.svg").write_text(svg)
    m = read_brim_svg(tmp_path / "t.svg").markers
    assert np.allclose(m[:, :2], [[11, 7], [10, 6], [7, 9], [3, 3]])


def test_parse_transform_order():
    m = parse_transform("translate(5) scale(2)")
    assert np.allclose(m @ [1, 1, 1], [7, 2, 1])


def test_bad_svgs(tmp_path):
    with pytest.raises(CaraError, match="no such file"):
        read_brim_svg(tmp_path / "none.svg")
    (tmp_path / "x.svg").write_text("<svg><circle")
    with pytest.raises(CaraError, match="x.svg"):
        read_brim_svg(tmp_path / "x.svg")
    (tmp_path / "few.svg").write_text('<svg xmlns="http://www.w3.org/2000/svg"><circle cx="1" cy="1" r="1"/></svg>')
    with pytest.raises(CaraError, match="at least 4"):
        read_brim_svg(tmp_path / "few.svg")
