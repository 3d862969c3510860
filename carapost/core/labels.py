"""Label lists: parsing label text files and merging imported labels."""
from __future__ import annotations

from pathlib import Path

from .errors import CaraError, read_bytes


def parse_label_text(text: str) -> list[str]:
    """Split a label file's text into names (space-delimited, any number per line).

    Parameters
    ----------
    text : str
        The file's content.

    Returns
    -------
    list of str
        Names in file order.
    """
    return text.split()


def read_label_file(path: str | Path) -> list[str]:
    """Read a label text file (File > Import Labels From Text File).

    Raises
    ------
    CaraError
        When the file is missing, unreadable or not text.
    """
    path = Path(path)
    data = read_bytes(path)
    if b"\0" in data:
        raise CaraError("not a label text file (binary data)", path)
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        text = data.decode("latin-1")
    return parse_label_text(text)


def merge_labels(existing: list[str], new: list[str]) -> list[str]:
    """Append ``new`` to ``existing``; a name already present gets `` - Copy`` appended.

    Returns
    -------
    list of str
        The combined list (``existing`` is not modified).
    """
    out = list(existing)
    taken = set(out)
    for name in new:
        while name in taken:
            name = f"{name} - Copy"
        out.append(name)
        taken.add(name)
    return out
