"""Where the repository's ``resources/`` (trained models, default brims) are."""
from __future__ import annotations

from pathlib import Path

from .core.errors import CaraError

RESOURCES = Path(__file__).resolve().parent.parent / "resources"


def resource_path(*parts: str) -> Path:
    """Path of a file under ``resources/``.

    Raises
    ------
    CaraError
        When the file is missing (an installation without the resources folder).
    """
    p = RESOURCES.joinpath(*parts)
    if not p.exists():
        raise CaraError("resource file missing from the installation", p)
    return p
