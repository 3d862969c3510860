"""Stabilize Data [Manual] / [Assisted], Align Data (Process menu) and Toggle Show Stabilized (View menu).

The operations are in the Qt-free :mod:`carapost.core.stabilize_ops`; these
handlers gather the selected points, the current frame (the base frame, or the
frame Align Data reads) and the active range, run the solve off the GUI thread
(assisted: with progress and cancel), and push the resulting command on the
undo stack; its summary, with the stabilisation error, goes to the Log pane.
Show Stabilized is a view setting of the document, not an edit: the 3D view
draws :func:`~carapost.core.stabilize_ops.stabilized_positions` while it is on.
"""
from __future__ import annotations

import logging

log = logging.getLogger("carapost")

SHOW_ACTION = "view.show_stabilized"


class StabilizeActions:
    """Handlers of the stabilisation items."""

    def __init__(self, window):
        self.w = window
        window.session.documentChanged.connect(self.sync_check)

    @property
    def s(self):
        return self.w.session

    def _run(self, title: str, build, cancellable: bool) -> bool:
        if self.s.project is None:
            return False
        return self.w.runner.run(build, title, cancellable=cancellable)

    def stabilize_manual(self) -> None:
        """Stabilize Data [Manual]: the selected points onto the current frame, over the active range."""
        from ..core.stabilize_ops import stabilize_manual

        p, f, ids = self.s.project, self.s.frame, list(self.s.selection.points)
        self._run("Stabilize Data [Manual]", lambda _progress: stabilize_manual(p, ids, f), cancellable=False)

    def stabilize_assisted(self) -> None:
        """Stabilize Data [Assisted]: from the selected points, with the Stabilization Parameters."""
        from ..core.stabilize_ops import stabilize_assisted

        p, f, ids = self.s.project, self.s.frame, list(self.s.selection.points)
        self._run("Stabilize Data [Assisted]", lambda progress: stabilize_assisted(p, ids, f, progress=progress),
                  cancellable=True)

    def align(self) -> None:
        """Align Data: the three selected points, in selection order, as they are on the current frame."""
        from ..core.stabilize_ops import align_data

        self.s.attempt(align_data, self.s.project, list(self.s.selection.points), self.s.frame)

    def toggle_show(self) -> None:
        """Toggle Show Stabilized (Ctrl+Shift+S)."""
        doc = self.s.doc
        if doc is None:
            return
        doc.set_show_stabilized(not doc.show_stabilized)
        self.sync_check()
        self.s.displayChanged.emit()
        if doc.show_stabilized and doc.project.stabilization is None:
            log.info("Show Stabilized: on (the take is not stabilised yet: raw positions are shown)")
        else:
            log.info(f"Show Stabilized: {'on' if doc.show_stabilized else 'off'}")

    def sync_check(self) -> None:
        """The menu item's check mark follows the document's setting."""
        actionset = getattr(self.w, "actionset", None)
        if actionset is None:
            return
        qa = actionset.actions[SHOW_ACTION]
        on = bool(self.s.doc is not None and self.s.doc.show_stabilized)
        if qa.isChecked() != on:
            qa.blockSignals(True)
            qa.setChecked(on)
            qa.blockSignals(False)
