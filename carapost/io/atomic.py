"""Atomic file writes: a temporary file beside the target, fsync, rename.

Every writer of the project (.cara, .xcp, .c3d) goes through here, so a crash,
a full disk or a bad value never leaves a half-written file, and an existing
file is replaced only by a complete one.
"""
from __future__ import annotations

import os
import uuid
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO, Iterable, Iterator

from ..core.errors import CaraError


@contextmanager
def atomic_open(path: str | os.PathLike, what: str = "the file") -> Iterator[BinaryIO]:
    """Open a temporary file for writing that replaces ``path`` when the block ends without error.

    Parameters
    ----------
    path : path-like
        The target.
    what : str
        Named in error messages ("cannot write <what>: ...").

    Raises
    ------
    CaraError
        When the folder is missing or not writable, or writing fails; the target
        is untouched and no temporary file is left.
    """
    path = Path(path)
    folder = path.parent if str(path.parent) else Path(".")
    if not folder.is_dir():
        raise CaraError(f"cannot write {what}: the folder {folder} does not exist", path)
    tmp = folder / f".{path.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp"
    try:
        # 0o666 lets the umask decide the mode, as for any new file (mkstemp would make it 0600).
        fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    except OSError as exc:
        raise CaraError(f"cannot write {what}: {exc.strerror or exc}", path) from None
    try:
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        if path.exists():  # an overwritten file keeps its permissions
            try:
                os.chmod(tmp, path.stat().st_mode & 0o7777)
            except OSError:
                pass
        os.replace(tmp, path)
    except OSError as exc:
        _unlink(tmp)
        raise CaraError(f"cannot write {what}: {exc.strerror or exc}", path) from None
    except BaseException:
        _unlink(tmp)
        raise
    _fsync_dir(folder)


def atomic_write(path: str | os.PathLike, parts: Iterable[bytes], what: str = "the file") -> None:
    """Write byte strings to ``path`` atomically (see :func:`atomic_open`)."""
    with atomic_open(path, what) as fh:
        for p in parts:
            fh.write(p)


def _unlink(p: Path) -> None:
    try:
        os.unlink(p)
    except OSError:
        pass


def _fsync_dir(folder: Path) -> None:
    """Make the rename itself durable (POSIX); harmless where unsupported."""
    try:
        dfd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(dfd)
    except OSError:
        pass
    finally:
        os.close(dfd)
