"""Frame sources: where a channel's images come from.

A channel of a take is a ``.pico`` file, any video file FFmpeg can read, or a
folder of images.  All three give the same interface, :class:`FrameSource`:
random, frame-exact access to grey ``uint8`` images by zero-based index, plus
sequential decoding of a range (:meth:`FrameSource.read_range`) used by the
shared frame cache (:mod:`carapost.io.framecache`).
"""
from __future__ import annotations

import itertools
from abc import ABC, abstractmethod
import logging
import os
import re
import threading
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from ..core.errors import CaraError
from .pico import DEFAULT_FRAME_RATE, PicoReader, av_frame_to_grey, decode_runs, take_and_channel

log = logging.getLogger(__name__)

IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".tif", ".tiff", ".bmp", ".pgm")

_uids = itertools.count(1)


class FrameSource(ABC):
    """A channel's frames: random access by index, grey ``uint8`` images.

    Attributes
    ----------
    path : Path
        The file or folder.
    kind : str
        ``"pico"``, ``"video"`` or ``"images"``.
    width, height : int
    frame_count : int
    frame_rate : float
    metadata : dict[str, str]
    keyframes : numpy.ndarray
        Indices decoding can start from (every index for images).
    warnings : list[str]
        Problems found, one line each naming the file (and frame).
    uid : int
        Unique for the life of the process (a cache key that is never reused,
        unlike ``id()``).
    """

    kind = ""

    def __init__(self, path):
        self.path = Path(path)
        self.uid = next(_uids)
        self.width = self.height = self.frame_count = 0
        self.frame_rate = DEFAULT_FRAME_RATE
        self.metadata: dict[str, str] = {}
        self.warnings: list[str] = []

    @abstractmethod
    def read(self, index: int) -> np.ndarray:
        """Frame ``index`` as an ``(height, width)`` ``uint8`` grey image.

        Raises
        ------
        CaraError
            When the frame cannot be read (names the file and frame).
        IndexError
            For an index outside ``0 .. frame_count-1``.
        """

    def gop_start(self, index: int) -> int:
        """Index of the frame decoding must start from to reach frame ``index``."""
        self._check(index)
        return int(index)

    def read_range(self, start: int, stop: int) -> Iterator[tuple[int, np.ndarray]]:
        """Frames ``start .. stop-1`` decoded sequentially (one seek).

        Yields
        ------
        (int, numpy.ndarray)
            Index and image of each frame that can be read, in order; frames
            that cannot be read are left out (:meth:`read` raises the reason).
        """
        for i in range(max(0, int(start)), min(int(stop), self.frame_count)):
            try:
                img = self.read(i)
            except CaraError:
                continue
            yield i, img

    def close(self) -> None:
        """Release files and decoders (idempotent)."""

    def _check(self, index: int) -> int:
        index = int(index)
        if not 0 <= index < self.frame_count:
            raise IndexError(f"{self.path}: frame {index} out of range 0..{self.frame_count - 1}")
        return index

    def __len__(self) -> int:
        return self.frame_count

    def __enter__(self):
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return (f"{type(self).__name__}({str(self.path)!r}, {self.width}x{self.height}, "
                f"{self.frame_count} frames @ {self.frame_rate:g} fps)")


# --------------------------------------------------------------------------------------------------

class PicoSource(FrameSource):
    """A ``.pico`` file (see :class:`carapost.io.pico.PicoReader`).

    Attributes
    ----------
    reader : PicoReader
    channel : int
    frame_numbers : numpy.ndarray
        Burnt-in frame numbers.
    """

    kind = "pico"

    def __init__(self, path, decode_threads: int | None = None):
        super().__init__(path)
        self.reader = PicoReader(path, decode_threads=decode_threads)
        r = self.reader
        self.width, self.height, self.frame_count = r.width, r.height, r.frame_count
        self.frame_rate, self.metadata, self.channel = r.frame_rate, r.metadata, r.channel
        self.frame_numbers = r.frame_numbers
        self.warnings = r.warnings                  # the same list: damage found later shows up here

    @property
    def keyframes(self) -> np.ndarray:
        return self.reader.keyframes

    def read(self, index: int) -> np.ndarray:
        return self.reader.read(index)

    def gop_start(self, index: int) -> int:
        return self.reader.gop_start(index)

    def read_range(self, start: int, stop: int) -> Iterator[tuple[int, np.ndarray]]:
        return self.reader.read_range(start, stop)

    def read_packet(self, index: int) -> bytes:
        """The frame's H.264 access unit (Annex-B)."""
        return self.reader.read_packet(index)

    def close(self) -> None:
        self.reader.close()


# --------------------------------------------------------------------------------------------------

class VideoSource(FrameSource):
    """Any video file FFmpeg reads (mp4, mov, mkv, avi, …), frame-exact.

    Opening demuxes the whole stream once without decoding to index every
    packet's time stamp and key-frame flag.  A frame is read by seeking to the
    key frame before it and decoding forward; decoded pictures are matched to
    indices by time stamp, so the result does not depend on where the seek
    landed.  A stream without time stamps is read sequentially from the
    start instead (slow for random access, still exact).

    Parameters
    ----------
    path : str or Path
    stream : int
        Which video stream.
    """

    kind = "video"

    def __init__(self, path, stream: int = 0):
        super().__init__(path)
        import av

        self._lock = threading.RLock()
        self._live = None
        self._container = None
        self._stream_index = stream
        if not self.path.is_file():
            raise CaraError("no such file", self.path)
        try:
            self._open()
            self._index()
        except av.FFmpegError as e:
            self.close()
            raise CaraError(f"cannot be read as video: {e}", self.path) from None
        except BaseException:
            self.close()
            raise

    def _open(self) -> None:
        import av
        from av.codec.context import Flags2

        self._container = av.open(str(self.path), "r")
        vids = self._container.streams.video
        if len(vids) <= self._stream_index:
            raise CaraError("holds no video stream" if not vids else
                            f"has no video stream {self._stream_index}", self.path)
        self._stream = vids[self._stream_index]
        ctx = self._stream.codec_context
        if ctx.name in ("h264", "hevc"):
            # Start at any key frame even without recovery-point SEI (open-GOP I-frames).
            ctx.flags2 |= Flags2.show_all

    def _index(self) -> None:
        s = self._stream
        ts: list[int] = []
        keys: list[bool] = []
        any_pts = False
        for pkt in self._container.demux(s):
            if pkt.size == 0 and pkt.pts is None and pkt.dts is None:
                continue                     # the demuxer's end-of-stream packet
            if pkt.is_discard:
                continue                     # cut by an edit list: the decoder drops its picture
            t = pkt.pts if pkt.pts is not None else pkt.dts
            any_pts |= t is not None
            ts.append(t)
            keys.append(bool(pkt.is_keyframe))
        if not ts:
            raise CaraError("the video stream holds no frames", self.path)
        self.frame_count = len(ts)
        self._seekable = any_pts and None not in ts and len(set(ts)) == len(ts)
        if self._seekable:
            order = np.argsort(np.asarray(ts, np.int64), kind="stable")
            self._ts = np.asarray(ts, np.int64)[order]          # display order
            self._index_of_ts = {int(t): i for i, t in enumerate(self._ts)}
            kd = np.asarray(keys, bool)[order]
            self.keyframes = np.flatnonzero(kd).astype(np.int64)
            if not len(self.keyframes) or self.keyframes[0] != 0:
                self.keyframes = np.union1d([0], self.keyframes)
        else:
            self._ts = None
            self._index_of_ts = {}
            self.keyframes = np.asarray([0], np.int64)
            self.warnings.append(f"{self.path}: the video has no usable time stamps; random access "
                                 "decodes from the start")
        ctx = s.codec_context
        self.width, self.height = int(ctx.width), int(ctx.height)
        rate = s.average_rate or s.guessed_rate or s.base_rate
        self.frame_rate = float(rate) if rate else DEFAULT_FRAME_RATE
        md = dict(self._container.metadata)
        md.update({f"stream.{k}": v for k, v in s.metadata.items()})
        md["codec"] = ctx.name
        self.metadata = md
        self._rewind()

    def _rewind(self) -> None:
        """Back to the first packet (after indexing, or for streams that cannot seek)."""
        try:
            self._container.seek(0, backward=True, any_frame=False)
            self._stream.codec_context.flush_buffers()
        except Exception:            # noqa: BLE001 — some demuxers cannot seek: reopen instead
            self._container.close()
            self._open()

    def gop_start(self, index: int) -> int:
        index = self._check(index)
        k = int(np.searchsorted(self.keyframes, index, "right")) - 1
        return int(self.keyframes[max(k, 0)])

    def _frames_from(self, key: int) -> Iterator[tuple[int, object]]:
        """Seek to key frame ``key`` and yield (index, av frame) from there on."""
        import av

        s = self._stream
        if self._seekable and key > 0:
            self._container.seek(int(self._ts[key]), stream=s, backward=True, any_frame=False)
            s.codec_context.flush_buffers()
        else:
            self._rewind()
        last = -1
        for pkt in self._container.demux(s):
            try:
                frames = s.codec_context.decode(pkt)
            except av.FFmpegError as e:
                self.warnings.append(f"{self.path}: damaged packet near frame {last + 1}: {e}")
                continue
            for f in frames:
                if self._seekable:
                    t = f.pts if f.pts is not None else f.dts
                    idx = self._index_of_ts.get(t) if t is not None else None
                    if idx is None:
                        continue
                else:
                    idx = last + 1
                last = idx
                yield idx, f

    def _decode_from(self, want: int) -> list[tuple[int, np.ndarray]]:
        """Frames >= want from the live decoder, restarting at a key frame when needed (lock held)."""
        live = self._live
        start = self.gop_start(want)
        if live is None or not (live["last"] < want and start <= live["last"] + 1):
            kp = int(np.searchsorted(self.keyframes, want, "right")) - 1
            # The seek must land at or before the key frame; when it lands later (an inexact
            # demuxer), try the key frames before it, and at last the start of the file.
            tries = list(dict.fromkeys([p for p in (kp, kp - 1, kp - 2) if p >= 0] + [0]))
            live = None
            for p in tries:
                key = int(self.keyframes[p])
                gen = self._frames_from(key)
                first = next(gen, None)
                if first is not None and (first[0] <= want or key == 0 or not self._seekable):
                    live = {"gen": gen, "last": key - 1, "min": key, "peek": first}
                    break
            if live is None:
                self._live = None
                return []
            self._live = live
        out: list[tuple[int, np.ndarray]] = []
        while not out:
            if live["peek"] is not None:
                item, live["peek"] = live["peek"], None
            else:
                item = next(live["gen"], None)
            if item is None:
                self._live = None
                break
            idx, f = item
            if idx < live["min"] or idx <= live["last"]:
                continue
            live["last"] = idx
            if idx >= want:
                out.append((idx, self._grey(f, idx)))
        return out

    def _grey(self, frame, idx: int) -> np.ndarray:
        img = av_frame_to_grey(frame)
        if img.shape != (self.height, self.width):
            raise CaraError(f"frame {idx} is {img.shape[1]}x{img.shape[0]} pixels, the stream says "
                            f"{self.width}x{self.height}", self.path)
        return img

    def read(self, index: int) -> np.ndarray:
        index = self._check(index)
        with self._lock:
            if self._container is None:
                raise CaraError("the file is closed", self.path)
            got = self._decode_from(index)
        if got and got[0][0] == index:
            return got[0][1]
        raise CaraError(f"frame {index} cannot be decoded", self.path)

    def read_range(self, start: int, stop: int) -> Iterator[tuple[int, np.ndarray]]:
        def decode(nxt):
            with self._lock:
                if self._container is None:
                    raise CaraError("the file is closed", self.path)
                return self._decode_from(nxt)

        return decode_runs(decode, start, stop, self.frame_count)

    def close(self) -> None:
        with self._lock:
            self._live = None
            if self._container is not None:
                self._container.close()
                self._container = None


# --------------------------------------------------------------------------------------------------

def _natural_key(name: str):
    # "img2" before "img10": digit runs compare as numbers (same order as plain sorting for
    # zero-padded names).
    return [(0, int(t), t) if t.isdigit() else (1, 0, t.lower()) for t in re.split(r"(\d+)", name) if t]


def image_to_grey(img: np.ndarray, path) -> np.ndarray:
    """An image as read by ``cv2.imread(..., IMREAD_UNCHANGED)`` to ``uint8`` grey.

    16-bit images keep their top 8 bits; colour (BGR, BGRA) becomes grey.
    """
    import cv2

    if img.ndim == 3:
        if img.shape[2] == 1:
            img = img[:, :, 0]
        elif img.shape[2] == 2:
            img = img[:, :, 0]                              # grey + alpha
        elif img.shape[2] == 3:
            img = cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
        elif img.shape[2] == 4:
            img = cv2.cvtColor(img, cv2.COLOR_BGRA2GRAY)
        else:
            raise CaraError(f"images with {img.shape[2]} channels are not supported", path)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    elif img.dtype != np.uint8:
        raise CaraError(f"pixel type {img.dtype} is not supported (8 or 16 bit)", path)
    return np.ascontiguousarray(img)


class ImageFolderSource(FrameSource):
    """A folder of images, one frame per file, in name order.

    Files ending in .png, .jpg, .jpeg, .tif, .tiff, .bmp or .pgm are used,
    sorted by name with digit runs compared as numbers (``f2`` before
    ``f10``).  Colour becomes grey, 16-bit keeps its top 8 bits.

    Parameters
    ----------
    path : str or Path
        The folder.
    frame_rate : float
        Frames per second (a folder does not say).
    """

    kind = "images"

    def __init__(self, path, frame_rate: float = DEFAULT_FRAME_RATE):
        super().__init__(path)
        if not self.path.is_dir():
            raise CaraError("no such folder", self.path)
        try:
            names = [e.name for e in os.scandir(self.path)
                     if e.is_file() and e.name.lower().endswith(IMAGE_EXTENSIONS) and not e.name.startswith(".")]
        except OSError as e:
            raise CaraError(f"cannot list the folder: {e.strerror or e}", self.path) from None
        if not names:
            raise CaraError(f"the folder holds no images ({', '.join(IMAGE_EXTENSIONS)})", self.path)
        self.files = [self.path / n for n in sorted(names, key=_natural_key)]
        self.frame_count = len(self.files)
        self.frame_rate = float(frame_rate)
        self.keyframes = np.arange(self.frame_count, dtype=np.int64)
        first = self._load(0)
        self.height, self.width = first.shape
        self.metadata = {"first_image": self.files[0].name, "last_image": self.files[-1].name}

    def _load(self, index: int) -> np.ndarray:
        import cv2

        f = self.files[index]
        img = cv2.imread(str(f), cv2.IMREAD_UNCHANGED)
        if img is None:
            why = "missing" if not f.exists() else "not a readable image"
            raise CaraError(f"frame {index}: {why}", f)
        return image_to_grey(img, f)

    def read(self, index: int) -> np.ndarray:
        index = self._check(index)
        img = self._load(index)
        if img.shape != (self.height, self.width):
            raise CaraError(f"frame {index}: image is {img.shape[1]}x{img.shape[0]} pixels, the first is "
                            f"{self.width}x{self.height}", self.files[index])
        return img


# --------------------------------------------------------------------------------------------------

def open_source(path, decode_threads: int | None = None, **kwargs) -> FrameSource:
    """Open a channel's frames: a ``.pico`` file, a video file or a folder of images.

    Parameters
    ----------
    path : str or Path
    decode_threads : int, optional
        A ``.pico`` file's decoder threads (:class:`~carapost.io.pico.PicoReader`); other
        sources ignore it.
    **kwargs
        Passed to the source class (e.g. ``frame_rate`` for a folder).

    Raises
    ------
    CaraError
        Naming the path, when it is missing or cannot be read.
    """
    p = Path(path)
    if not p.exists():
        raise CaraError("no such file or folder", p)
    if p.is_dir():
        return ImageFolderSource(p, **kwargs)
    if p.suffix.lower() == ".pico":
        return PicoSource(p, decode_threads=decode_threads)
    if not os.access(p, os.R_OK):
        raise CaraError("permission denied", p)
    return VideoSource(p, **kwargs)


def take_files(pico_path) -> list[Path]:
    """All channel files of the take of ``pico_path``, by channel.

    ``Example_2.pico`` gives ``[Example_0.pico, …, Example_3.pico]`` (those
    present beside it, sorted by channel number).  A name without the
    ``_<channel>`` suffix gives just ``[pico_path]``.

    Raises
    ------
    CaraError
        When ``pico_path`` does not exist.
    """
    p = Path(pico_path)
    if not p.is_file():
        raise CaraError("no such file", p)
    tc = take_and_channel(p)
    if tc is None:
        return [p]
    take = tc[0]
    found = []
    for e in os.scandir(p.parent):
        t = take_and_channel(e.name)
        if t is not None and t[0] == take and e.is_file():
            found.append((t[1], e.name))
    found.sort()
    return [p.parent / n for _, n in found]


def group_takes(paths: Iterable) -> dict[str, list[Path]]:
    """Group ``.pico`` files by take (File > Import Pico Files).

    Parameters
    ----------
    paths : iterable of str or Path
        Files (folders contribute their ``.pico`` files).

    Returns
    -------
    dict[str, list[Path]]
        Take name -> its files sorted by channel.  A file without a channel
        suffix is a take of its own.  When two folders hold takes of the same
        name the key includes the folder.
    """
    files: list[Path] = []
    for p in map(Path, paths):
        if p.is_dir():
            files += sorted(q for q in p.iterdir() if q.suffix.lower() == ".pico")
        else:
            files.append(p)
    groups: dict[tuple[Path, str], list[tuple[int, Path]]] = {}
    for f in dict.fromkeys(files):                     # de-duplicate, keep order
        tc = take_and_channel(f)
        take, ch = (tc if tc else (f.stem, -1))
        groups.setdefault((f.parent, take), []).append((ch, f))
    names: dict[str, int] = {}
    for _, take in groups:
        names[take] = names.get(take, 0) + 1
    out: dict[str, list[Path]] = {}
    for (folder, take), items in groups.items():
        key = take if names[take] == 1 else str(folder / take)
        out[key] = [f for _, f in sorted(items, key=lambda x: x[0])]
    return out
