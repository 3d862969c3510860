"""The QApplication, its look, and the main window's entry points (GUI, screenshot, shortcuts)."""
from __future__ import annotations

import os
import sys

from PySide6.QtGui import QColor, QPalette
from PySide6.QtWidgets import QApplication

from .settings import APP, ORG


def ensure_app(offscreen: bool = False) -> QApplication:
    """The QApplication (created once), Fusion style with a dark palette like CaraPost's.

    Parameters
    ----------
    offscreen : bool
        Use Qt's offscreen platform unless QT_QPA_PLATFORM is set (screenshots, shortcuts).
    """
    if offscreen:
        os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")
    from . import qtfix

    qtfix.apply()
    app = QApplication.instance()
    if app is None:
        app = QApplication(sys.argv[:1])
        app.setOrganizationName(ORG)
        app.setApplicationName(APP)
        app.setStyle("Fusion")
        app.setPalette(dark_palette())
    import pyqtgraph as pg

    pg.setConfigOptions(antialias=False, imageAxisOrder="row-major")
    return app


def dark_palette() -> QPalette:
    pal = QPalette()
    R = QPalette.ColorRole
    for role, rgb in ((R.Window, (53, 53, 53)), (R.WindowText, (225, 225, 225)), (R.Base, (38, 38, 38)),
                      (R.AlternateBase, (48, 48, 48)), (R.ToolTipBase, (255, 255, 220)), (R.ToolTipText, (0, 0, 0)),
                      (R.Text, (225, 225, 225)), (R.Button, (60, 60, 60)), (R.ButtonText, (225, 225, 225)),
                      (R.Highlight, (60, 110, 180)), (R.HighlightedText, (255, 255, 255)),
                      (R.BrightText, (255, 80, 80)), (R.Link, (100, 160, 255))):
        pal.setColor(role, QColor(*rgb))
    pal.setColor(QPalette.ColorGroup.Disabled, R.Text, QColor(120, 120, 120))
    pal.setColor(QPalette.ColorGroup.Disabled, R.ButtonText, QColor(120, 120, 120))
    pal.setColor(QPalette.ColorGroup.Disabled, R.WindowText, QColor(120, 120, 120))
    return pal


def install_error_hook() -> None:
    """Report an unexpected exception (a bug) in the Log pane and a message box instead of a traceback.

    The traceback goes to the ``carapost`` logger's handlers (and stderr) for a bug report;
    the user sees one line.
    """
    import logging

    log = logging.getLogger("carapost")

    def hook(kind, value, tb):
        log.error(f"internal error: {kind.__name__}: {value}", exc_info=(kind, value, tb))
        from PySide6.QtWidgets import QMessageBox

        win = QApplication.activeWindow()
        QMessageBox.critical(win, "carapost", f"Internal error: {kind.__name__}: {value}\n"
                                               "The Log pane has the details; please report it.")

    sys.excepthook = hook


def settle(app: QApplication, rounds: int = 5) -> None:
    """Process pending events a few times (layouts, deferred redraws)."""
    for _ in range(rounds):
        app.processEvents()


def screenshot(path: str | None, out: str, frame: int | None = None, size=(1600, 1000)) -> None:
    """Open ``path`` in a main window offscreen, go to ``frame``, save the window as PNG ``out``.

    Raises
    ------
    CaraError
        When the file cannot be opened or the image cannot be written.
    """
    from ..core.document import Document
    from ..core.errors import CaraError
    from .file_actions import load_any
    from .mainwindow import MainWindow

    app = ensure_app(offscreen=True)
    win = MainWindow(synchronous_images=True, autosave_s=0, restore=False, persist=False)
    if path:
        win.files.show_document(Document(load_any(path)))
    if frame is not None and win.session.doc is not None:
        win.navigate.set_frame(frame)
    win.resize(*size)
    win.show()
    settle(app)
    win.grid.set_layout(win.grid.layout_name)   # fit the views to their final sizes
    settle(app)
    ok = win.grab().save(str(out))
    win.close()
    if not ok:
        raise CaraError("cannot write the screenshot", out)
