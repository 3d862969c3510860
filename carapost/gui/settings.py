"""Per-user settings (QSettings): window layout, dock state, display options, recent files.

Stored in an INI file under the user's config folder; tests point
:meth:`QSettings.setPath` at a temporary folder.  The autosave folder is the
user's data folder, or ``$CARAPOST_DATA_DIR`` when set.
"""
from __future__ import annotations

import os
from pathlib import Path

from PySide6.QtCore import QSettings, QStandardPaths

ORG = APP = "carapost"
MAX_RECENT = 8


def app_settings() -> QSettings:
    """The user's settings file."""
    return QSettings(QSettings.Format.IniFormat, QSettings.Scope.UserScope, ORG, APP)


def recent_files(settings: QSettings) -> list[str]:
    """File > Recent Files, newest first."""
    v = settings.value("recent_files", [])
    if isinstance(v, str):           # QSettings returns a lone string for a one-item list
        v = [v]
    return [str(p) for p in (v or [])][:MAX_RECENT]


def add_recent(settings: QSettings, path: str) -> list[str]:
    """Put ``path`` first in the recent files (at most eight)."""
    path = str(Path(path).absolute())
    files = [path] + [p for p in recent_files(settings) if p != path]
    settings.setValue("recent_files", files[:MAX_RECENT])
    return files[:MAX_RECENT]


def clear_recent(settings: QSettings) -> None:
    settings.setValue("recent_files", [])


def data_dir() -> Path:
    """Folder for autosave/recovery files (not created here: only an autosave writes)."""
    env = os.environ.get("CARAPOST_DATA_DIR")
    if env:
        d = Path(env)
    else:
        loc = QStandardPaths.writableLocation(QStandardPaths.StandardLocation.GenericDataLocation)
        d = Path(loc or Path.home() / ".local" / "share") / APP
    return d


def read_bool(settings: QSettings, key: str, default: bool) -> bool:
    v = settings.value(key, default)
    if isinstance(v, str):
        return v.lower() in ("true", "1", "yes")
    return bool(v)
