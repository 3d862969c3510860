"""Frame sources (pico, video files, image folders), take grouping and the frame cache."""
from __future__ import annotations

import threading

import cv2
import numpy as np
import pytest

from carapost.core.errors import CaraError
from carapost.io.framecache import FrameCache
from carapost.io.media import (ImageFolderSource, PicoSource, VideoSource, group_takes, open_source,
                               take_files)
from carapost.io.pico import write_pico

W, H, N = 160, 120, 72


def make_frames(n: int = N, seed: int = 1) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        im = np.full((H, W), (i * 29) % 180 + 30, np.uint8)
        im[20:40, (i * 2) % (W - 20):(i * 2) % (W - 20) + 20] = 250
        im[80:96, 8:24] = rng.integers(0, 256, (16, 16))
        out.append(im)
    return out


@pytest.fixture(scope="module")
def frames():
    return make_frames()


@pytest.fixture(scope="module")
def media(tmp_path_factory, frames):
    """The same frames as a pico, an ffv1 .mkv, an H.264 .mp4 (with B-frames) and a folder of PNGs."""
    import av

    d = tmp_path_factory.mktemp("media")
    write_pico(d / "Take_0.pico", frames, gop=12)
    for name, codec, fmt, opts in [("grey.mkv", "ffv1", "gray", {"g": "12"}),
                                   ("h264.mp4", "libx264", "yuvj420p",
                                    {"qp": "0", "x264-params": "keyint=12:min-keyint=12:scenecut=0"})]:
        c = av.open(str(d / name), "w")
        s = c.add_stream(codec, rate=30)
        s.width, s.height, s.pix_fmt = W, H, fmt
        s.options = opts
        for im in frames:
            a = im if fmt == "gray" else np.concatenate([im, np.full((H // 2, W), 128, np.uint8)])
            for p in s.encode(av.VideoFrame.from_ndarray(a, format=fmt)):
                c.mux(p)
        for p in s.encode(None):
            c.mux(p)
        c.close()
    img = d / "images"
    img.mkdir()
    for i, im in enumerate(frames):
        cv2.imwrite(str(img / f"frame{i}.png"), im)       # unpadded numbers: natural sort needed
    (img / "notes.txt").write_text("not an image")
    return d


KINDS = {"pico": "Take_0.pico", "ffv1": "grey.mkv", "h264": "h264.mp4", "images": "images"}


@pytest.mark.parametrize("kind", list(KINDS))
def test_sources_give_the_frames_they_were_made_from(media, frames, kind):
    with open_source(media / KINDS[kind]) as src:
        assert (src.width, src.height, src.frame_count) == (W, H, N)
        assert src.kind == {"ffv1": "video", "h264": "video"}.get(kind, kind)
        got = list(src.read_range(0, N))
        assert [i for i, _ in got] == list(range(N))
        for i, img in got:
            assert img.dtype == np.uint8 and img.shape == (H, W)
            assert np.array_equal(img, frames[i]), f"{kind} frame {i}"


@pytest.mark.parametrize("kind", list(KINDS))
def test_random_access_is_frame_exact(media, frames, kind):
    with open_source(media / KINDS[kind]) as src:
        for k in np.random.default_rng(3).permutation(N):
            assert np.array_equal(src.read(int(k)), frames[k]), f"{kind} frame {k}"
        for k in [N - 1, 0, N - 2, 13, 12, 11, 35, 36, 5]:
            assert np.array_equal(src.read(k), frames[k]), f"{kind} frame {k}"
            g = src.gop_start(k)
            assert 0 <= g <= k
        with pytest.raises(IndexError):
            src.read(N)


def test_h264_mp4_has_b_frames_and_long_gops(media):
    with VideoSource(media / "h264.mp4") as src:
        assert len(src.keyframes) == N // 12
        assert src.gop_start(30) == 24
        assert src.frame_rate == 30.0 and src.metadata["codec"] == "h264"


def test_image_folder_conversions(tmp_path, frames):
    d = tmp_path / "mixed"
    d.mkdir()
    cv2.imwrite(str(d / "a2.png"), frames[0].astype(np.uint16) * 256 + 77)   # 16-bit: top byte kept
    bgr = np.dstack([frames[1], frames[2], frames[3]])
    cv2.imwrite(str(d / "a10.bmp"), bgr)                                      # colour -> grey
    cv2.imwrite(str(d / "a1.pgm"), frames[4])
    cv2.imwrite(str(d / "a3.tif"), frames[5])
    with ImageFolderSource(d, frame_rate=25) as src:
        assert [f.name for f in src.files] == ["a1.pgm", "a2.png", "a3.tif", "a10.bmp"]
        assert src.frame_rate == 25
        assert np.array_equal(src.read(0), frames[4])
        assert np.array_equal(src.read(1), frames[0])
        assert np.array_equal(src.read(2), frames[5])
        assert np.array_equal(src.read(3), cv2.cvtColor(bgr, cv2.COLOR_BGR2GRAY))
    (d / "a11.png").write_bytes(b"garbage")
    cv2.imwrite(str(d / "a12.png"), np.zeros((10, 10), np.uint8))
    with ImageFolderSource(d) as src:
        with pytest.raises(CaraError, match=r"a11\.png: frame 4: not a readable image"):
            src.read(4)
        with pytest.raises(CaraError, match=r"a12\.png: frame 5: image is 10x10"):
            src.read(5)
        assert [i for i, _ in src.read_range(0, 6)] == [0, 1, 2, 3]


def test_open_source_errors(tmp_path):
    with pytest.raises(CaraError, match="missing.mp4: no such file"):
        open_source(tmp_path / "missing.mp4")
    (tmp_path / "empty").mkdir()
    with pytest.raises(CaraError, match="empty: the folder holds no images"):
        open_source(tmp_path / "empty")
    bad = tmp_path / "bad.mp4"
    bad.write_bytes(b"this is not a video at all" * 10)
    with pytest.raises(CaraError, match="bad.mp4: cannot be read as video"):
        open_source(bad)
    bad = tmp_path / "bad_0.pico"
    bad.write_bytes(bytes(1000))
    with pytest.raises(CaraError, match="bad_0.pico: not a .pico file"):
        open_source(bad)


def test_take_files_and_grouping(tmp_path, media):
    data = (media / "Take_0.pico").read_bytes()
    for name in ["Example_0.pico", "Example_1.pico", "Example_3.pico", "Example_2.pico", "Example_10.pico",
                 "Other_0.pico", "Other_1.pico", "Loose.pico", "Example_x.pico"]:
        (tmp_path / name).write_bytes(data)
    names = [p.name for p in take_files(tmp_path / "Example_2.pico")]
    assert names == ["Example_0.pico", "Example_1.pico", "Example_2.pico", "Example_3.pico", "Example_10.pico"]
    assert take_files(tmp_path / "Loose.pico") == [tmp_path / "Loose.pico"]
    with pytest.raises(CaraError, match="no such file"):
        take_files(tmp_path / "Gone_0.pico")
    g = group_takes(sorted(tmp_path.glob("*.pico"), reverse=True))
    assert set(g) == {"Example", "Other", "Loose", "Example_x"}
    assert [p.name for p in g["Other"]] == ["Other_0.pico", "Other_1.pico"]
    assert [p.name for p in g["Example"]][-1] == "Example_10.pico"
    g2 = group_takes([tmp_path])                         # a folder contributes its .pico files
    assert set(g2) == set(g)
    # The same take name in two folders stays two takes.
    sub = tmp_path / "day2"
    sub.mkdir()
    (sub / "Other_0.pico").write_bytes(data)
    g3 = group_takes([tmp_path / "Other_0.pico", sub / "Other_0.pico"])
    assert len(g3) == 2 and all(len(v) == 1 for v in g3.values())


def test_pico_source_exposes_the_reader(media):
    with open_source(media / "Take_0.pico") as src:
        assert isinstance(src, PicoSource)
        assert list(src.keyframes) == list(range(0, N, 12))
        assert list(src.frame_numbers) == list(range(N))
        assert src.read_packet(0).startswith(b"\x00\x00\x00\x01\x09")
        assert src.metadata["this_capture.capture_name"] == "Take"


# ---- cache ---------------------------------------------------------------------------------------

class Counting:
    """Wraps a source and counts the frames it decodes."""

    def __init__(self, src):
        self.src, self.uid, self.decoded, self.runs = src, src.uid, 0, 0
        self.frame_count = src.frame_count

    def gop_start(self, i):
        return self.src.gop_start(i)

    def read(self, i):
        self.decoded += 1
        return self.src.read(i)

    def read_range(self, a, b):
        self.runs += 1
        for item in self.src.read_range(a, b):
            self.decoded += 1
            yield item


def test_cache_stepping_backwards_uses_the_cached_gop(media, frames):
    with open_source(media / "Take_0.pico") as raw:
        src = Counting(raw)
        cache = FrameCache(max_mb=64)
        assert np.array_equal(cache.get(src, 35), frames[35])
        assert src.decoded == 12 and src.runs == 1          # frames 24..35: the GOP run up to 35
        for k in range(34, 23, -1):                         # step back through the GOP
            assert np.array_equal(cache.get(src, k), frames[k])
        assert src.decoded == 12 and src.runs == 1          # ... all dictionary lookups
        assert cache.stats()["hits"] == 11
        assert np.array_equal(cache.get(src, 23), frames[23])   # previous GOP: one more run
        assert src.decoded == 24 and src.runs == 2
        for k in range(36, 48):                             # stepping forwards continues the decoder
            assert np.array_equal(cache.get(src, k), frames[k])
        assert src.decoded == 36
        frame = cache.get(src, 40)
        assert not frame.flags.writeable                     # shared with the cache
        cache.close()


def test_cache_memory_bound(media, frames):
    with open_source(media / "Take_0.pico") as src:
        one = W * H
        cache = FrameCache(max_mb=10.5 * one / 2 ** 20)      # room for ten frames
        for k in list(range(N)) + list(range(N - 1, -1, -7)):
            assert np.array_equal(cache.get(src, k), frames[k])
            st = cache.stats()
            assert st["bytes"] <= st["max_bytes"] and st["entries"] <= 10
        assert cache.stats()["evictions"] > 0
        assert cache.contains(src, 0) and not cache.contains(src, 30)
        cache.clear()
        assert cache.stats()["entries"] == 0 and cache.stats()["bytes"] == 0


def test_cache_prefetch_and_threads(media, frames):
    sources = [open_source(media / KINDS[k]) for k in ("pico", "ffv1", "images")]
    cache = FrameCache(max_mb=32, workers=2)
    futs = [cache.prefetch(s, range(10, 40)) for s in sources]
    assert [f.result(timeout=30) for f in futs] == [0, 0, 0]
    assert all(cache.contains(s, k) for s in sources for k in range(10, 40))
    errors = []

    def worker(seed):
        rng = np.random.default_rng(seed)
        for _ in range(60):
            s = sources[int(rng.integers(3))]
            k = int(rng.integers(N))
            if not np.array_equal(cache.get(s, k), frames[k]):
                errors.append((s.kind, k))

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == []
    cache.close()
    for s in sources:
        s.close()


def test_cache_reports_damaged_frames(tmp_path, frames):
    path = tmp_path / "Dmg_0.pico"
    write_pico(path, frames[:24], gop=12)
    data = bytearray(path.read_bytes())
    from carapost.io.pico import PicoReader

    with PicoReader(path) as r:
        off = int(r._rec_off[5])
    data[off + 128] = 0                                     # bad sync byte in frame 5
    path.write_bytes(bytes(data))
    with open_source(path) as src:
        cache = FrameCache()
        with pytest.raises(CaraError, match=r"Dmg_0\.pico: frame 5 is damaged"):
            cache.get(src, 5)
        assert np.array_equal(cache.get(src, 4), frames[4])
        assert cache.prefetch(src, [3, 5, 12]).result() == 1
        assert any("frame 5" in w for w in src.warnings)
