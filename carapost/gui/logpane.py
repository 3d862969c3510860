"""The Log pane: the ``carapost`` logger's messages, info white, warnings yellow, errors red.

Everything logs through Python :mod:`logging` under the ``"carapost"`` logger
(the core and io modules too), so the pane shows what every operation did,
whichever thread it ran in.
"""
from __future__ import annotations

import html
import logging
import time

from PySide6.QtCore import QObject, Signal
from PySide6.QtWidgets import QHBoxLayout, QPlainTextEdit, QPushButton, QVBoxLayout, QWidget

COLORS = {logging.DEBUG: "#9a9a9a", logging.INFO: "#ffffff", logging.WARNING: "#ffd84a", logging.ERROR: "#ff5a5a"}


class _Emitter(QObject):
    record = Signal(int, str)


class QtLogHandler(logging.Handler):
    """Forwards records to the GUI thread as ``(level, text)`` signals."""

    def __init__(self):
        super().__init__(logging.INFO)
        self.emitter = _Emitter()

    def emit(self, record: logging.LogRecord) -> None:
        try:
            self.emitter.record.emit(record.levelno, record.getMessage())
        except RuntimeError:  # the pane was destroyed while a worker still logs
            pass


class LogPane(QWidget):
    """A read-only coloured log with a Clear button.

    Parameters
    ----------
    logger_name : str
        The logger to show (``"carapost"``).
    """

    def __init__(self, logger_name: str = "carapost", parent=None):
        super().__init__(parent)
        self.text = QPlainTextEdit(readOnly=True)
        self.text.setMaximumBlockCount(5000)
        self.text.setStyleSheet("QPlainTextEdit { background: #1e1e1e; font-family: monospace; }")
        clear = QPushButton("Clear Log")
        clear.clicked.connect(self.text.clear)
        row = QHBoxLayout()
        row.addStretch(1)
        row.addWidget(clear)
        lay = QVBoxLayout(self)
        lay.setContentsMargins(2, 2, 2, 2)
        lay.addWidget(self.text)
        lay.addLayout(row)
        self.lines: list[tuple[int, str]] = []   #: what was shown (tests read it)
        self.handler = QtLogHandler()
        self.handler.emitter.record.connect(self.append)
        self.logger = logging.getLogger(logger_name)
        self.logger.addHandler(self.handler)
        if self.logger.level == logging.NOTSET or self.logger.level > logging.INFO:
            self.logger.setLevel(logging.INFO)

    def append(self, level: int, message: str) -> None:
        """Show one message in its level's colour."""
        self.lines.append((level, message))
        del self.lines[:-5000]
        color = COLORS.get(level, "#ffffff" if level < logging.WARNING else "#ff5a5a")
        stamp = time.strftime("%H:%M:%S")
        self.text.appendHtml(f'<span style="color:{color}">{stamp}  {html.escape(message)}</span>')

    def detach(self) -> None:
        """Stop listening (the window is closing)."""
        self.logger.removeHandler(self.handler)
