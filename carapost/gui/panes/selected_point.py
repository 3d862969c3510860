"""The Selected Point pane: the continuity of the selected point, overall and per channel.

The top bar is the point's bar of the Continuity chart (its label at the left),
then one row per sensor (blob detection, patch track, target track by score,
keyframes).  The pane is empty when no point or several points are selected,
and it follows every edit; while a track runs with Update Timeline Every Frame
it also shows the frames tracked so far, read from the track's live overlay
(:mod:`carapost.gui.live_preview`) before the project holds them.  Clicking a
bar goes to the clicked frame.
"""
from __future__ import annotations

from PySide6.QtCore import QEvent
from PySide6.QtWidgets import QVBoxLayout, QWidget


class SelectedPointPane(QWidget):
    """Dock contents of View > Panels > Selected Point.

    Parameters
    ----------
    session : Session, optional
        When omitted the pane attaches to the session of the window it is
        docked in (the first ancestor with a ``session`` attribute).
    """

    def __init__(self, session=None, parent=None):
        super().__init__(parent)
        self.session = None
        self.bars = None
        self._lay = QVBoxLayout(self)
        self._lay.setContentsMargins(0, 0, 0, 0)
        self.setMinimumHeight(90)
        if session is not None:
            self.attach(session)

    def attach(self, session) -> None:
        """Show the selected point of ``session``."""
        from ..continuity import SelectedPointBars

        if self.session is session:
            return
        if self.bars is not None:
            self._lay.removeWidget(self.bars)
            self.bars.deleteLater()
        self.session = session
        self.bars = SelectedPointBars(session, self)
        self._lay.addWidget(self.bars)

    def _find_session(self) -> None:
        w = self.parentWidget()
        while w is not None and self.session is None:
            s = getattr(w, "session", None)
            if s is not None and hasattr(s, "selectionChanged"):
                self.attach(s)
            w = w.parentWidget()

    def event(self, ev) -> bool:
        if self.session is None and ev.type() in (QEvent.Type.ParentChange, QEvent.Type.Show):
            self._find_session()
        return super().event(ev)

    # -------------------------------------------------------- for scripts/tests
    def color_at(self, frame: int, channel: int = -1):
        """RGBA shown at ``frame`` on the top bar (``channel`` -1) or a sensor row; None when empty."""
        if self.bars is None or not self.bars.rows:
            self.bars is not None and self.bars.ensure_drawn()
            if self.bars is None or not self.bars.rows:
                return None
        return self.bars.color_at(self.bars.rows[0][0], frame, channel)

    def label(self) -> str:
        """Label of the point shown ('' when empty)."""
        if self.bars is None:
            return ""
        self.bars.ensure_drawn()
        return self.bars.row_label(*self.bars.rows[0]) if self.bars.rows else ""
