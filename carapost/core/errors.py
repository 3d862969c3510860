class CaraError(Exception):
    """A user-facing error: names the file (if any) and what is wrong. Never shown as a traceback."""
    def __init__(self, message: str, path: str | None = None):
        self.path = str(path) if path is not None else None
        super().__init__(f"{self.path}: {message}" if self.path else message)


def read_bytes(path) -> bytes:
    """The bytes of a file, or a :class:`CaraError` naming it (missing, unreadable)."""
    from pathlib import Path

    path = Path(path)
    try:
        return path.read_bytes()
    except FileNotFoundError:
        raise CaraError("no such file", path) from None
    except IsADirectoryError:
        raise CaraError("is a folder, not a file", path) from None
    except OSError as e:
        raise CaraError(f"cannot read: {e.strerror}", path) from None
