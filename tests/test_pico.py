"""The .pico reader and writer: layout, frame-exact random access, damage handling."""
from __future__ import annotations

import re
import struct
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest

from carapost.core.errors import CaraError
from carapost.io.pico import (FRAME_HEADER_SIZE, METADATA_OFFSET, VIDEO_PID, PicoReader, PicoWriter,
                              pico_info, ts_packetize, ts_to_es, write_pico)

W, H, N, GOP = 160, 120, 300, 24


def make_frames(n: int = N, w: int = W, h: int = H, seed: int = 0) -> list[np.ndarray]:
    """Distinct frames: a moving block, a per-frame grey level and a noise patch (unique per frame)."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        im = np.full((h, w), (i * 37) % 200 + 20, np.uint8)
        x = (i * 3) % (w - 20)
        im[10:30, x:x + 20] = 255 - im[0, 0]
        im[h - 20:h - 4, 4:20] = rng.integers(0, 256, (16, 16))
        im[60, :] = np.arange(w) % 256
        out.append(im)
    return out


@pytest.fixture(scope="module")
def frames():
    return make_frames()


@pytest.fixture(scope="module")
def take(tmp_path_factory, frames):
    path = tmp_path_factory.mktemp("pico") / "Example_2.pico"
    n = write_pico(path, frames, frame_rate=50.0, channel=2, gop=GOP, start_frame=1000,
                   metadata={"logger.name": "Logger A"}, timecode="10:11:12:13")
    assert n == N
    return path


def records(path: Path):
    """Walk the frame records by hand: (offset, int32 header, payload bytes)."""
    data = path.read_bytes()
    magic, first, end = struct.unpack_from("<3Q", data, 0)
    pos, out = first, []
    while pos < end:
        head = np.frombuffer(data, "<i4", 32, pos)
        size = int(head[20])
        out.append((pos, head, data[pos + FRAME_HEADER_SIZE:pos + FRAME_HEADER_SIZE + size]))
        pos += FRAME_HEADER_SIZE + size
    assert pos == end
    return out


def nal_types(es: bytes) -> list[int]:
    return [es[m.end()] & 0x1F for m in re.finditer(b"\x00\x00\x01", es)]


# ---- layout --------------------------------------------------------------------------------------

def test_file_header(take):
    data = take.read_bytes()
    magic, first, end = struct.unpack_from("<3Q", data, 0)
    u = struct.unpack_from("<8I", data, 24)
    assert magic == 101
    assert end == len(data)
    assert first > METADATA_OFFSET
    assert u[2] == 1000 and u[3] == 1000 + N - 1          # start and end frame
    assert u[4] == 2                                       # channel
    assert u[6] == 1000 + (N - 1) // GOP * GOP             # last I-frame
    with PicoReader(take) as r:
        assert r.channel == 2 and r.header["start_frame"] == 1000 and r.header["end_frame"] == 1299


def test_metadata_dictionary(take):
    data = take.read_bytes()
    first = struct.unpack_from("<Q", data, 8)[0]
    pos = METADATA_OFFSET
    (count,) = struct.unpack_from("<I", data, pos)
    pos += 4
    md = {}
    for _ in range(count):
        kv = []
        for _ in range(2):
            (n,) = struct.unpack_from("<I", data, pos)
            kv.append(data[pos + 4:pos + 4 + n].decode())
            pos += 4 + n
        md[kv[0]] = kv[1]
    assert pos == first                                    # the dictionary ends where frames begin
    assert md["this_capture.capture_name"] == "Example"
    assert int(md["this_capture.hal_time_ms"]) > 1.5e12
    assert md["this_capture.frame_rate"] == "50"
    assert md["this_capture.timecode"] == "10:11:12:13"
    assert md["logger.name"] == "Logger A"
    with PicoReader(take) as r:
        assert r.metadata == md
        assert r.frame_rate == 50.0


def test_frame_headers(take):
    recs = records(take)
    assert len(recs) == N
    for i, (_, h, payload) in enumerate(recs):
        assert h[0] == 100
        number, _chan, width, height, _rate, ftype, size, four, size184 = h[14:23]
        assert number == 1000 + i
        assert (width, height) == (W, H)
        assert ftype == (1 if i % GOP == 0 else 2)
        assert size == len(payload) and size % 188 == 0
        assert four == 4 and size184 == size - 184
        assert h[23] == VIDEO_PID
    with PicoReader(take) as r:
        assert (r.width, r.height, r.frame_count) == (W, H, N)
        assert list(r.keyframes) == list(range(0, N, GOP))
        assert list(r.frame_numbers) == list(range(1000, 1000 + N))


def test_transport_stream_and_pes(take):
    cc_expected = 0
    for i, (_, h, payload) in enumerate(records(take)[:60]):
        pk = np.frombuffer(payload, np.uint8).reshape(-1, 188)
        assert np.all(pk[:, 0] == 0x47)
        pid = ((pk[:, 1].astype(int) & 0x1F) << 8) | pk[:, 2]
        assert np.all(pid == VIDEO_PID)
        pusi = (pk[:, 1] & 0x40) != 0
        assert pusi[0] and not pusi[1:].any()
        cc = pk[:, 3] & 0x0F
        assert cc[0] == cc_expected and np.all(np.diff(cc.astype(int)) % 16 == 1)
        cc_expected = (int(cc[-1]) + 1) % 16
        afc = pk[:, 3] >> 4
        assert np.all(afc[:-1] == 1)                       # payload only ...
        if afc[-1] == 3:                                   # ... but the last packet pads with stuffing
            n = pk[-1, 4]
            assert n == 0 or (pk[-1, 5] == 0 and np.all(pk[-1, 6:5 + n] == 0xFF))
        pes = pk[0, 4:]
        assert bytes(pes[:4]) == b"\x00\x00\x01\xe0" and pes[7] & 0x80
        es, pts = ts_to_es(payload)
        assert pts == round(i * 90000 / 50.0)
        assert es.startswith(b"\x00\x00\x00\x01\x09")       # access unit delimiter first
        kinds = nal_types(es)
        if i % GOP == 0:
            assert {7, 8, 5} <= set(kinds)                 # SPS, PPS and IDR slice: decodable alone
        else:
            assert 1 in kinds and 5 not in kinds


@pytest.mark.parametrize("size", [0, 1, 183, 184, 185, 367, 368, 1000])
def test_ts_packetize_round_trip(size):
    pes = b"\x00\x00\x01\xe0\x00\x00\x81\x80\x05" + bytes([0x21, 0, 1, 0, 1]) + bytes(range(256)) * 8
    pes = pes[:14 + size]
    ts, cc = ts_packetize(pes, VIDEO_PID, 15)
    assert len(ts) % 188 == 0 and cc == (15 + len(ts) // 188) % 16
    es, pts = ts_to_es(ts)
    assert es == pes[14:] and pts == 0


# ---- decoding ----------------------------------------------------------------------------------

def test_lossless_round_trip(take, frames):
    with PicoReader(take) as r:
        got = list(r.read_range(0, N))
    assert [i for i, _ in got] == list(range(N))
    for (i, img), ref in zip(got, frames):
        assert img.dtype == np.uint8 and img.shape == (H, W)
        assert np.array_equal(img, ref), f"frame {i}"


def test_random_access_is_frame_exact(take, frames):
    with PicoReader(take) as r:
        sequential = [img for _, img in r.read_range(0, N)]
    with PicoReader(take) as r:
        for k in np.random.default_rng(5).permutation(N):
            r._decoder = None                   # force a real seek: no continuing a live decoder
            assert np.array_equal(r.read(int(k)), sequential[k]), f"frame {k}"
        # Also the mixed pattern of a user scrubbing: back, forward, back across GOPs.
        for k in [299, 298, 0, 1, 2, 100, 47, 48, 49, 23, 24, 25, 26, 288, 287]:
            assert np.array_equal(r.read(k), frames[k]), f"frame {k}"
        assert r.gop_start(47) == 24 and r.gop_start(48) == 48


def test_read_packet_decodes_alone_from_an_i_frame(take, frames):
    import av

    with PicoReader(take) as r:
        ctx = av.CodecContext.create("h264", "r")
        out = []
        for k in range(48, 52):
            out += ctx.decode(av.Packet(r.read_packet(k)))
    assert len(out) == 4
    assert np.array_equal(out[3].to_ndarray()[:H], frames[51])


def test_lossy_setting(tmp_path, frames):
    path = tmp_path / "Lossy_0.pico"
    write_pico(path, frames[:60], lossless=False, bitrate=2_000_000, gop=12, frame_rate=60)
    with PicoReader(path) as r:
        seq = [img for _, img in r.read_range(0, 60)]
        for k in (59, 13, 12, 11, 0, 37):
            r._decoder = None
            assert np.array_equal(r.read(k), seq[k])
        assert r._bitrate == 2_000_000 and r.frame_rate == 60.0
    err = np.mean([np.abs(a.astype(int) - b).mean() for a, b in zip(seq, frames)])
    assert err < 4


def test_frame_rate_fallbacks(tmp_path, frames):
    path = tmp_path / "Rate_0.pico"
    # No frame-rate metadata: the frame headers' 27 MHz clock fields give it.
    write_pico(path, frames[:4], frame_rate=25.0, metadata={"this_capture.frame_rate": ""})
    with PicoReader(path) as r:
        assert r.frame_rate == 25.0


def _slice_type(au: bytes) -> int:
    """H.264 slice_type (0 P, 1 B, 2 I) of the first slice of an access unit."""
    for m in re.finditer(b"\x00\x00\x01", au):
        t = au[m.end()] & 0x1F
        if t in (1, 5):
            rbsp = au[m.end() + 1:m.end() + 16].replace(b"\x00\x00\x03", b"\x00\x00")
            bits = "".join(f"{b:08b}" for b in rbsp)
            vals, pos = [], 0
            for _ in range(2):
                z = bits.index("1", pos) - pos
                vals.append(int(bits[pos + z:pos + 2 * z + 1], 2) - 1)
                pos += 2 * z + 1
            return vals[1] % 5
    raise AssertionError("no slice")


def _strip_sei(au: bytes) -> bytes:
    starts = [m.start() for m in re.finditer(b"\x00\x00\x01", au)]
    parts = [au[s:e] for s, e in zip(starts, starts[1:] + [len(au)])]
    return b"".join(b"\x00" + p for p in parts if p[3] & 0x1F != 6)


def test_b_frames_and_non_idr_i_frames(tmp_path, frames):
    """Like CaraLive files: B-frames (file order != display order) and open-GOP non-IDR I-frames."""
    import av

    enc = av.CodecContext.create("libx264", "w")
    enc.width, enc.height, enc.pix_fmt = W, H, "yuvj420p"
    enc.time_base, enc.framerate = Fraction(1, 60), Fraction(60)
    # x264 makes no B-frames when lossless, so this stream is lossy (qp 10).
    enc.options = {"qp": "10", "x264-params": "keyint=20:min-keyint=20:scenecut=0:bframes=2:b-adapt=0:"
                                              "b-pyramid=0:open-gop=1:aud=1"}
    enc.open()
    n = 100
    pkts = []
    for i, im in enumerate(frames[:n]):
        f = av.VideoFrame.from_ndarray(np.concatenate([im, np.full((H // 2, W), 128, np.uint8)]), format="yuvj420p")
        f.pts = i
        pkts += enc.encode(f)
    pkts += enc.encode(None)
    path = tmp_path / "Bframes_0.pico"
    kinds = []
    with PicoWriter(path, W, H, frame_rate=60) as w:
        for p in pkts:
            au = _strip_sei(bytes(p))              # no recovery-point SEI: decoding must still start at I
            kind = {2: 1, 0: 2, 1: 3}[_slice_type(au)]
            kinds.append(kind)
            w.write_access_unit(au, kind, display_index=p.pts)
    assert 3 in kinds and kinds.count(1) >= 4
    assert 5 not in nal_types(bytes(pkts[[p.pts for p in pkts].index(20)]))   # a non-IDR I-frame
    with PicoReader(path) as r:
        assert r.frame_count == n and list(r.frame_numbers) == list(range(n))
        assert set(r.frame_types) == {1, 2, 3}
        assert r.frame_types[20] == 1 and r.frame_types[19] == 3      # 19 is decoded after 20 (open GOP)
        seq = list(r.read_range(0, n))
        assert [i for i, _ in seq] == list(range(n))
        for i, img in seq:
            assert np.abs(img.astype(int) - frames[i]).mean() < 3, f"frame {i}"
        for k in np.random.default_rng(2).permutation(n):
            r._decoder = None
            assert np.array_equal(r.read(int(k)), seq[k][1]), f"frame {k} after a seek"


def test_take_starting_without_an_i_frame(tmp_path, frames):
    """A recording cut mid-GOP: frames before the first I-frame cannot be decoded, the rest can."""
    from carapost.io.pico import H264Encoder

    enc = H264Encoder(W, H, gop=GOP)
    aus = [au for im in frames[:60] for au in enc.encode(im)] + enc.encode(None)
    path = tmp_path / "Cut_0.pico"
    with PicoWriter(path, W, H) as w:
        for au, kind in aus[5:]:
            w.write_access_unit(au, kind)
    with PicoReader(path) as r:
        assert r.frame_count == 55 and r.keyframes[0] == GOP - 5
        with pytest.raises(CaraError, match=r"Cut_0\.pico: frame 3 cannot be decoded: no I-frame before it"):
            r.read(3)
        assert np.array_equal(r.read(GOP - 5), frames[GOP])
        assert [i for i, _ in r.read_range(0, 30)] == list(range(GOP - 5, 30))


# ---- damage --------------------------------------------------------------------------------------

def test_missing_empty_and_wrong_magic(tmp_path, take):
    with pytest.raises(CaraError, match="no such file") as e:
        PicoReader(tmp_path / "nope.pico")
    assert "nope.pico" in str(e.value)
    empty = tmp_path / "empty.pico"
    empty.write_bytes(b"")
    with pytest.raises(CaraError, match="empty.pico: not a .pico file"):
        PicoReader(empty)
    bad = tmp_path / "bad.pico"
    data = bytearray(take.read_bytes())
    data[0] = 7
    bad.write_bytes(bytes(data))
    with pytest.raises(CaraError, match=r"bad.pico: not a \.pico file: header magic is 7"):
        PicoReader(bad)


def test_truncated_file(tmp_path, take, frames):
    recs = records(take)
    off = recs[150][0]
    path = tmp_path / "Trunc_0.pico"
    path.write_bytes(take.read_bytes()[:off + FRAME_HEADER_SIZE + 200])     # cut inside frame 150
    with PicoReader(path) as r:
        assert r.frame_count == 151
        assert any("truncated" in w and "Trunc_0.pico" in w for w in r.warnings)
        assert any("frame 150" in w for w in r.warnings)
        with pytest.raises(CaraError, match=r"Trunc_0\.pico: frame 150 is damaged"):
            r.read(150)
        assert np.array_equal(r.read(149), frames[149])
        assert np.array_equal(r.read(3), frames[3])


def test_corrupt_packet(tmp_path, take, frames):
    recs = records(take)
    data = bytearray(take.read_bytes())
    data[recs[100][0] + FRAME_HEADER_SIZE + 2 * 188] = 0x00        # sync byte of the third packet
    path = tmp_path / "Corrupt_0.pico"
    path.write_bytes(bytes(data))
    with PicoReader(path) as r:
        assert r.warnings == []                       # payloads are checked lazily ...
        assert np.array_equal(r.read(99), frames[99])
        with pytest.raises(CaraError, match=r"Corrupt_0\.pico: frame 100 is damaged: TS packet 2 has a bad sync"):
            r.read(100)
        assert any("frame 100" in w and "sync" in w for w in r.warnings)
        assert 100 in r.damaged
        img = r.read(101)                             # decodable, though it may show artefacts
        assert img.shape == (H, W)
        assert np.array_equal(r.read(120), frames[120])  # next GOP is clean
        with pytest.raises(CaraError, match="frame 100"):
            r.read_packet(100)
    with PicoReader(path, verify=True) as r:          # ... or all at once
        assert any("frame 100" in w for w in r.warnings)
    info = pico_info(path)
    assert info["damaged_frames"] == 1 and "frame 100" in info["warnings"][0]


def test_corrupt_frame_header(tmp_path, take, frames):
    recs = records(take)
    data = bytearray(take.read_bytes())
    data[recs[50][0]:recs[50][0] + 4] = b"\xde\xad\xbe\xef"
    path = tmp_path / "Header_0.pico"
    path.write_bytes(bytes(data))
    with PicoReader(path) as r:
        assert r.frame_count == N                     # the lost frame keeps its place
        assert r.frame_numbers[50] == 1050 and r.frame_numbers[51] == 1051
        assert any("frame 50" in w and "Header_0.pico" in w for w in r.warnings)
        with pytest.raises(CaraError, match=r"Header_0\.pico: frame 50 is damaged"):
            r.read(50)
        assert np.array_equal(r.read(49), frames[49])
        assert np.array_equal(r.read(72), frames[72])
        assert np.array_equal(r.read(299), frames[299])


def test_unfinalised_header(tmp_path, take, frames):
    data = bytearray(take.read_bytes())
    data[16:24] = bytes(8)                            # end offset 0: the recorder never closed the file
    path = tmp_path / "Open_0.pico"
    path.write_bytes(bytes(data))
    with PicoReader(path) as r:
        assert r.frame_count == N and any("end of frames" in w for w in r.warnings)
        assert np.array_equal(r.read(N - 1), frames[N - 1])


# ---- writer --------------------------------------------------------------------------------------

def test_writer_is_atomic(tmp_path, frames):
    path = tmp_path / "Keep_0.pico"
    path.write_bytes(b"old contents")

    def bad():
        yield frames[0]
        yield frames[1]
        raise RuntimeError("source failed")

    with pytest.raises(RuntimeError):
        write_pico(path, bad())
    assert path.read_bytes() == b"old contents"
    with pytest.raises(CaraError, match="differs from the first frame"):
        write_pico(path, [frames[0], frames[0][:, :80]])
    assert path.read_bytes() == b"old contents"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["Keep_0.pico"]


def test_writer_rejects_bad_input(tmp_path, frames):
    p = tmp_path / "x_0.pico"
    with pytest.raises(CaraError, match="no frames"):
        write_pico(p, [])
    with pytest.raises(CaraError, match="uint8"):
        write_pico(p, [frames[0].astype(np.float32)])
    with pytest.raises(CaraError, match="even"):
        write_pico(p, [np.zeros((11, 16), np.uint8)])
    with pytest.raises(CaraError, match="timecode"):
        write_pico(p, frames[:1], timecode="noon")
    assert not p.exists()


def test_pico_info(take):
    info = pico_info(take)
    assert info["take"] == "Example" and info["channel"] == 2
    assert info["size"] == f"{W}x{H}" and info["frames"] == N and info["frame_rate"] == 50.0
    assert info["i_frame_interval"] == GOP and info["frame_types"]["I"] == 13
    assert info["frame_numbers"] == "1000..1299" and info["warnings"] == "none"
    assert info["metadata"]["this_capture.timecode"] == "10:11:12:13"
