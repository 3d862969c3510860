"""Work around a PySide6 6.12.0 reference-count bug on Python 3.11.

On Python 3.11 PySide6 6.12.0 drops one reference to ``None`` on every call
of a Qt method returning void, and one to ``True`` on every ``Signal.emit``.
Python 3.12 made these singletons immortal, which hides the bug there; on
3.11 the interpreter aborts ("Fatal Python error: none_dealloc") once a few
tens of thousands of calls have run.  When the leak is detected we give the
three singletons a reference count they cannot exhaust, which is what 3.12
does natively; nothing else changes.  The real fix is a PySide6 release
without the bug (or Python >= 3.12).
"""
from __future__ import annotations

import ctypes
import sys

_IMMORTAL = 1 << 40
applied = False


def _leaks() -> bool:
    from PySide6.QtCore import QObject, Signal

    class _Probe(QObject):
        sig = Signal()

    probe = _Probe()
    none0, true0 = sys.getrefcount(None), sys.getrefcount(True)
    for _ in range(64):
        probe.setObjectName("probe")
        probe.sig.emit()
    return sys.getrefcount(None) < none0 - 32 or sys.getrefcount(True) < true0 - 32


def apply() -> bool:
    """Protect None, True and False when the running PySide6 leaks their references; True when applied."""
    global applied
    if applied or sys.version_info >= (3, 12) or sys.implementation.name != "cpython":
        return applied
    if _leaks():
        for obj in (None, True, False):
            # ob_refcnt is the first field of every CPython object; id() is its address.
            ctypes.c_ssize_t.from_address(id(obj)).value += _IMMORTAL
        applied = True
    return applied
