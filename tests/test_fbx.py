"""FBX export, read back by the independent `ufbx` reader, by assimp, and by a tiny structural reader here."""
import re
import shutil
import struct
import subprocess
import zlib

import numpy as np
import pytest
import ufbx

from carapost.cli import main
from carapost.core.errors import CaraError
from carapost.core.points import ST_NONE
from carapost.io import cara
from carapost.io.export_fbx import write_fbx
from carapost.io.fbx import KTIME_PER_SECOND, FbxScene, Int64, Record, encode_records
from support import make_export_project

# ---------------------------------------------------------------- a structural reader of our own


def _read_records(data: bytes):
    """(version, top-level records) of a binary FBX 7.x file with 32-bit offsets; checks every offset."""
    assert data[:23] == b"Kaydara FBX Binary  \x00\x1a\x00"
    version = struct.unpack_from("<I", data, 23)[0]

    def prop(at):
        code = chr(data[at])
        at += 1
        scalar = {"C": "?", "Y": "<h", "I": "<i", "L": "<q", "F": "<f", "D": "<d"}
        if code in scalar:
            v = struct.unpack_from(scalar[code], data, at)[0]
            return (code, v), at + struct.calcsize(scalar[code])
        if code in "SR":
            n = struct.unpack_from("<I", data, at)[0]
            return (code, data[at + 4:at + 4 + n]), at + 4 + n
        count, encoding, nbytes = struct.unpack_from("<III", data, at)
        raw = data[at + 12:at + 12 + nbytes]
        raw = zlib.decompress(raw) if encoding == 1 else raw
        dtype = {"b": "?", "i": "<i4", "l": "<i8", "f": "<f4", "d": "<f8"}[code]
        arr = np.frombuffer(raw, dtype)
        assert len(arr) == count
        return (code, arr), at + 12 + nbytes

    def record(at):
        end, nprops, plen, nlen = struct.unpack_from("<IIIB", data, at)
        if end == 0:
            assert data[at:at + 13] == b"\x00" * 13
            return None, at + 13
        name = data[at + 13:at + 13 + nlen].decode()
        at += 13 + nlen
        props, p_end = [], at + plen
        for _ in range(nprops):
            v, at = prop(at)
            props.append(v)
        assert at == p_end
        children = []
        while at < end:
            child, at = record(at)
            if child is None:
                break
            children.append(child)
        assert at == end, f"{name}: record ends at {at}, its offset says {end}"
        return (name, props, children), end

    at, top = 27, []
    while True:
        r, at = record(at)
        if r is None:
            break
        top.append(r)
    footer = data[at:]
    assert footer[-16:] == bytes.fromhex("f85a8c6adef5d97eece90ce3758f290b")
    assert struct.unpack_from("<I", footer, len(footer) - 16 - 120 - 4)[0] == version
    assert (len(data) - 16 - 120 - 4) % 16 == 0        # the version is 16-byte aligned
    return version, top


def _find(records, name):
    return [r for r in records if r[0] == name]


# ---------------------------------------------------------------- the project under test


def _project():
    """make_export_project's points (an interpolated and a single-sensor sample, an unlabelled
    point, a brim point) with a gap on frames 12-14 and fractional positions."""
    p, a, b, c = make_export_project()
    a.pos[:] += np.arange(20)[:, None] * [-0.5, -1.25, -0.875]
    a.status[12:15] = ST_NONE
    a.pos[12:15] = np.nan
    c.pos[:] = [-80.123, 5.5, 0.0]
    return p, a, b, c


class _Read:
    """What ufbx reads from a file, as plain Python data.

    ufbx 0.0.5's Python wrappers crash when touched after other wrappers of the
    same scene were freed (and Node.parent always does), so everything is read in
    one pass that keeps every wrapper alive until it is done.
    """

    def __init__(self, path):
        self._alive = []
        scene = self._keep(ufbx.load_file(str(path)))
        st = scene.settings
        self.fps, self.unit_meters, self.axes = st.frames_per_second, st.unit_meters, st.axes
        self.tree, self.translation, self.types = {}, {}, {}
        self._walk(scene.root_node)
        stack = self._items(scene.anim_stacks)[0]
        self.take, self.span = stack.name, (stack.time_begin, stack.time_end)
        self.keys = {}
        for ap in self._items(self._items(scene.anim_layers)[0].anim_props):
            assert ap.prop_name == "Lcl Translation"
            keys = [self._items(c.keyframes) for c in self._items(ap.anim_value.curves)]
            times = [np.array([k.time for k in ks]) for ks in keys]
            assert all(np.array_equal(times[0], t) for t in times)
            assert all(k.interpolation == ufbx.Interpolation.LINEAR for ks in keys for k in ks)
            self.keys[ap.element.name] = (times[0], np.array([[k.value for k in ks] for ks in keys]).T)
        del self._alive

    def _keep(self, obj):
        self._alive.append(obj)
        return obj

    def _items(self, seq):
        self._keep(seq)
        return [self._keep(seq[i]) for i in range(len(seq))]

    def _walk(self, node):
        self._keep(node)
        kids = self._items(node.children)
        self.tree[node.name] = [c.name for c in kids]
        self.types[node.name] = node.attrib_type
        t = self._keep(node.local_transform).translation
        self.translation[node.name] = np.array([t.x, t.y, t.z])
        for c in kids:
            self._walk(c)

    def frames(self, name, rate=60.0):
        return np.rint(self.keys[name][0] * rate).astype(int).tolist()


# ---------------------------------------------------------------- tests


def test_export_read_back_by_ufbx(tmp_path):
    p, a, b, c = _project()
    p.frame_rate = 59.94                               # a rate FBX has no name for: written as custom
    out = tmp_path / "t.fbx"
    write_fbx(p, out)
    r = _Read(out)
    assert r.fps == pytest.approx(59.94)
    assert r.unit_meters == pytest.approx(0.001)       # values are mm
    assert r.axes == ufbx.axes_right_handed_z_up
    assert r.tree[""] == ["Face", "Brim"]
    assert r.tree["Face"] == ["Nose_Tip", f"Point_{b.id}"] and r.tree["Brim"] == ["Brim_0"]
    assert all(t == ufbx.ElementType.EMPTY for name, t in r.types.items() if name)
    for pt in (a, b, c):
        have = np.flatnonzero(pt.status != 0)           # gaps are missing keys, nothing else is
        t, v = r.keys[pt.name]
        np.testing.assert_allclose(t * 59.94, have, atol=1e-6)
        np.testing.assert_allclose(v, pt.pos[have], atol=1e-3)
    assert 12 not in r.frames("Nose_Tip", 59.94)
    assert r.span[0] == 0 and r.span[1] == pytest.approx(19 / 59.94)
    # the static translation (what a reader shows without animation) is the first sample
    np.testing.assert_allclose(r.translation["Nose_Tip"], a.pos[0], atol=1e-4)
    np.testing.assert_allclose(r.translation[f"Point_{b.id}"], b.pos[3], atol=1e-4)
    assert np.all(r.translation["Face"] == 0)


def test_export_properties_and_frame_range(tmp_path):
    p, a, b, c = _project()
    out = tmp_path / "t.fbx"
    p.properties.set("export.include_interpolated", False)
    p.properties.set("export.include_brim_points", False)
    p.properties.set("export.active_range_only", True)
    p.active_range = (4, 16)
    write_fbx(p, out)
    r = _Read(out)
    assert r.fps == 60.0
    assert r.tree[""] == ["Face"]
    assert set(r.keys) == {"Nose_Tip", f"Point_{b.id}"}
    assert r.frames("Nose_Tip") == [4, 6, 7, 8, 9, 10, 11, 15, 16]   # 5 interpolated, 12-14 a gap
    np.testing.assert_allclose(r.keys["Nose_Tip"][1], a.pos[r.frames("Nose_Tip")], atol=1e-3)
    assert r.frames(f"Point_{b.id}") == [4, 5, 6, 7]
    assert r.span == pytest.approx((4 / 60, 16 / 60))
    # an explicit range wins over the properties; one outside the take is refused
    write_fbx(p, out, frame_range=(0, 3))
    assert _Read(out).frames("Nose_Tip") == [0, 1, 2, 3]
    with pytest.raises(CaraError, match="outside the take"):
        write_fbx(p, out, frame_range=(0, 20))


def test_file_structure_by_our_own_reader(tmp_path):
    p, a, b, c = _project()
    out = tmp_path / "t.fbx"
    write_fbx(p, out)
    version, top = _read_records(out.read_bytes())
    assert version == 7400
    names = [r[0] for r in top]
    for needed in ("FBXHeaderExtension", "GlobalSettings", "Documents", "Definitions", "Objects", "Connections"):
        assert needed in names
    settings = {r[1][0][1]: r[1][4:] for r in _find(_find(top, "GlobalSettings")[0][2], "Properties70")[0][2]}
    assert settings[b"TimeMode"] == [("I", 3)]                  # 60 fps by name
    assert settings[b"UnitScaleFactor"] == [("D", 0.1)]
    assert settings[b"TimeSpanStop"] == [("L", 19 * KTIME_PER_SECOND // 60)]
    objects = _find(top, "Objects")[0][2]
    models = {r[1][1][1].split(b"\x00\x01")[0].decode(): r[1][0] for r in _find(objects, "Model")}
    assert set(models) == {"Face", "Brim", "Nose_Tip", f"Point_{b.id}", "Brim_0"}
    assert all(code == "L" for code, _ in models.values())      # object ids are int64
    curve = _find(objects, "AnimationCurve")[0][2]
    times = _find(curve, "KeyTime")[0][1][0]
    assert times[0] == "l" and times[1][1] - times[1][0] == KTIME_PER_SECOND // 60
    conns = [tuple(v for _c, v in r[1]) for r in _find(_find(top, "Connections")[0][2], "C")]
    ids = {n: v for n, (_c, v) in models.items()}
    assert (b"OO", ids["Nose_Tip"], ids["Face"]) in conns and (b"OO", ids["Brim_0"], ids["Brim"]) in conns
    assert (b"OO", ids["Face"], 0) in conns
    assert sum(1 for c in conns if c[0] == b"OP" and c[3:] == (b"Lcl Translation",)) == 3


def test_scene_api_for_custom_trees(tmp_path):
    """What the guide's cara_fbx_export.py does: face points under sub-nodes of its choosing."""
    scene = FbxScene(30.0, take_name="Custom")
    face = scene.add_null("Face")
    brows = scene.add_null("Brows", parent=face)
    mouth = scene.add_null("Mouth", parent=face)
    frames = np.array([10, 11, 12, 20])
    scene.set_translation_keys(scene.add_null("Brow_L", parent=brows), frames, np.ones((4, 3)) * [1, 2, 3])
    scene.set_translation_keys(scene.add_null("Lip_C", parent=mouth), frames[:2], [[0, 0, 1], [0, 0, 2]])
    scene.set_translation(mouth, (0, 5, 0))
    out = tmp_path / "c.fbx"
    scene.write(out)
    r = _Read(out)
    assert r.tree["Face"] == ["Brows", "Mouth"] and r.tree["Brows"] == ["Brow_L"] and r.tree["Mouth"] == ["Lip_C"]
    assert r.take == "Custom" and r.span == pytest.approx((10 / 30, 20 / 30))
    assert r.fps == 30.0
    np.testing.assert_allclose(r.keys["Brow_L"][0] * 30, frames)
    np.testing.assert_allclose(r.keys["Lip_C"][1], [[0, 0, 1], [0, 0, 2]])
    np.testing.assert_allclose(r.translation["Mouth"], [0, 5, 0])
    with pytest.raises(ValueError, match="increase"):
        scene.set_translation_keys(brows, [3, 2], np.zeros((2, 3)))
    with pytest.raises(ValueError, match="finite"):
        scene.set_translation_keys(brows, [1, 2], [[0, 0, np.nan], [0, 0, 0]])
    with pytest.raises(ValueError, match="not a node of this scene"):
        scene.add_null("X", parent=FbxScene(30.0).add_null("Y"))
    with pytest.raises(CaraError, match="does not exist"):
        scene.write(tmp_path / "no" / "c.fbx")


def test_records_encoding_round_trip():
    """Every property type and both array encodings come back as written."""
    r = Record("Root", (True, 7, Int64(-(1 << 40)), 2.5, "name\x00\x01Model", b"\x00\xff"))
    r.add("Big", np.arange(1000, dtype=np.int64), np.linspace(0, 1, 50, dtype=np.float32))
    r.add("Small", np.array([1.5, 2.5]), np.array([True, False]), np.array([3], np.int32))
    r.add("Empty")
    for compress in (True, False):
        _v, top = _read_records(b"".join(encode_records([r], compress=compress)))
        name, props, children = top[0]
        assert name == "Root"
        assert props == [("C", True), ("I", 7), ("L", -(1 << 40)), ("D", 2.5), ("S", b"name\x00\x01Model"),
                         ("R", b"\x00\xff")]
        big, small, empty = children
        assert np.array_equal(big[1][0][1], np.arange(1000)) and big[1][1][0] == "f"
        assert np.allclose(big[1][1][1], np.linspace(0, 1, 50))
        assert [c for c, _ in small[1]] == ["d", "b", "i"] and list(small[1][1][1]) == [True, False]
        assert empty == ("Empty", [], [])


def test_cli_and_api_export(tmp_path, capsys):
    from carapost.api import CaraProcess

    p, a, b, c = _project()
    cara.save_project(p, tmp_path / "t.cara")
    assert main(["export", "fbx", str(tmp_path / "t.cara"), str(tmp_path / "t.fbx")]) == 0
    assert set(_Read(tmp_path / "t.fbx").keys) == {"Nose_Tip", f"Point_{b.id}", "Brim_0"}
    CaraProcess.from_project(p).export_fbx(tmp_path / "api.fbx", frame_range=(2, 9))
    assert _Read(tmp_path / "api.fbx").frames("Brim_0") == list(range(2, 10))


def test_cli_errors_exit_2_naming_the_file(tmp_path):
    from test_cli import run_cli

    r = run_cli("export", "fbx", tmp_path / "missing.cara", tmp_path / "t.fbx")
    assert r.returncode == 2 and "missing.cara" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    p, *_ = _project()
    cara.save_project(p, tmp_path / "t.cara")
    r = run_cli("export", "fbx", tmp_path / "t.cara", tmp_path / "no" / "t.fbx")
    assert r.returncode == 2 and "t.fbx" in r.stderr and "Traceback" not in r.stderr
    assert not (tmp_path / "no").exists()


def test_assimp_reads_the_export(tmp_path):
    exe = shutil.which("assimp")
    if exe is None:
        pytest.skip("the assimp command is absent (Debian: apt-get install assimp-utils)")
    p, a, b, c = _project()
    write_fbx(p, tmp_path / "t.fbx")
    r = subprocess.run([exe, "info", str(tmp_path / "t.fbx")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    assert "Animation Channels: 3" in r.stdout
    tree = r.stdout.split("Node hierarchy:")[1]
    for name in ("Face", "Nose_Tip", f"Point_{b.id}", "Brim", "Brim_0"):
        assert name in tree
    # assimp's own conversion keeps the key times and values (as 4x4 matrices)
    r = subprocess.run([exe, "export", str(tmp_path / "t.fbx"), str(tmp_path / "t.dae")], capture_output=True,
                       text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    dae = (tmp_path / "t.dae").read_text()
    times = re.search(r'id="Nose_Tip_matrix-input-array" count="\d+">([^<]*)<', dae).group(1).split()
    mats = re.search(r'id="Nose_Tip_matrix-output-array" count="\d+">([^<]*)<', dae).group(1).split()
    have = np.flatnonzero(a.status != 0)
    np.testing.assert_allclose(np.array(times, float), have, atol=1e-4)    # assimp counts in frames of the take
    m = np.array(mats, float).reshape(-1, 4, 4)
    np.testing.assert_allclose(m[:, :3, 3], a.pos[have], atol=1e-3)
