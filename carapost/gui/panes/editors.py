"""Editors for properties, generated from the property table.

Each editor shows one :class:`~carapost.core.properties.PropertyDef` and calls
``commit(key, value)`` when the user changes it; the pane turns that into a
:class:`~carapost.core.edits.SetProperties` command.  ``set_value`` updates
the editor from the project without committing (after an undo, for example).
"""
from __future__ import annotations

from typing import Any, Callable

from PySide6.QtCore import Qt
from PySide6.QtWidgets import QCheckBox, QComboBox, QDoubleSpinBox, QLineEdit, QSpinBox, QWidget

from ...core.properties import PropertyDef

_BIG = 1e9
Commit = Callable[[str, Any], None]


class _NoWheelMixin:
    """Spin boxes and combos in a scrolling pane ignore the wheel unless focused (no accidental edits)."""

    def wheelEvent(self, ev) -> None:  # noqa: N802 - Qt name
        if self.hasFocus():
            super().wheelEvent(ev)
        else:
            ev.ignore()


class _Spin(_NoWheelMixin, QSpinBox):
    pass


class _DSpin(_NoWheelMixin, QDoubleSpinBox):
    pass


class _Combo(_NoWheelMixin, QComboBox):
    pass


def _decimals(pdef: PropertyDef) -> int:
    d = pdef.default
    if pdef.maximum is not None and pdef.maximum <= 1.0:
        return 3
    return 2 if abs(d) < 100 else 1


def make_editor(pdef: PropertyDef, commit: Commit) -> QWidget:
    """A widget editing ``pdef`` with a ``set_value(v)`` method.

    Parameters
    ----------
    pdef : PropertyDef
    commit : callable
        ``commit(key, value)`` when the user finished a change.
    """
    key = pdef.key
    if pdef.type is bool:
        w = QCheckBox()
        w.toggled.connect(lambda on: commit(key, bool(on)))

        def set_value(v, w=w):
            w.blockSignals(True)
            w.setChecked(bool(v))
            w.blockSignals(False)
    elif pdef.type is int:
        w = _Spin()
        w.setRange(int(pdef.minimum if pdef.minimum is not None else -_BIG),
                   int(pdef.maximum if pdef.maximum is not None else _BIG))
        if pdef.unit:
            w.setSuffix(f" {pdef.unit}")
        w.setKeyboardTracking(False)      # commit on Enter / focus out, not per keystroke
        w.valueChanged.connect(lambda v: commit(key, int(v)))

        def set_value(v, w=w):
            w.blockSignals(True)
            w.setValue(int(v))
            w.blockSignals(False)
    elif pdef.type is float:
        w = _DSpin()
        w.setDecimals(_decimals(pdef))
        w.setRange(pdef.minimum if pdef.minimum is not None else -_BIG,
                   pdef.maximum if pdef.maximum is not None else _BIG)
        w.setSingleStep(0.05 if (pdef.maximum or 10) <= 1.0 else 0.5)
        if pdef.unit:
            w.setSuffix(f" {pdef.unit}")
        w.setKeyboardTracking(False)
        w.valueChanged.connect(lambda v: commit(key, float(v)))

        def set_value(v, w=w):
            w.blockSignals(True)
            w.setValue(float(v))
            w.blockSignals(False)
    elif pdef.choices:
        w = _Combo()
        w.addItems(list(pdef.choices))
        w.currentTextChanged.connect(lambda t: commit(key, t))

        def set_value(v, w=w):
            w.blockSignals(True)
            w.setCurrentText(str(v))
            w.blockSignals(False)
    else:
        w = QLineEdit()
        w.editingFinished.connect(lambda w=w: commit(key, w.text()))

        def set_value(v, w=w):
            w.blockSignals(True)
            w.setText(str(v))
            w.blockSignals(False)
    w.set_value = set_value
    w.setToolTip(pdef.help + (f"  (default {pdef.default})" if pdef.default != "" else ""))
    w.setFocusPolicy(Qt.FocusPolicy.StrongFocus)
    w.set_value(pdef.default)
    return w
