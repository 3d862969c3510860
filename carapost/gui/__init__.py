"""The desktop GUI (PySide6 + pyqtgraph): the main window, camera views, timebar and panes.

Importing this package loads no Qt (the CLI imports :mod:`carapost.gui.cli_entry`
to build its parser); :func:`carapost.gui.app.ensure_app` and the main window
apply :mod:`carapost.gui.qtfix` before widgets are made.
"""
