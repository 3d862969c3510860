"""The ``carapost gui`` and ``carapost shortcuts`` subcommands (wired into carapost.cli by the lead)."""
from __future__ import annotations

import json


def add_gui_commands(subparsers) -> None:
    """Add ``gui`` and ``shortcuts`` to the CLI's subparsers."""
    p = subparsers.add_parser("gui", help="open the GUI (FILE: a .cara project or a .pico of a take)")
    p.add_argument("file", nargs="?", help="a .cara project or a .pico file of a take")
    p.add_argument("--screenshot", metavar="OUT.png", help="render the window offscreen to OUT.png and exit")
    p.add_argument("--frame", type=int, default=None, help="frame shown in the screenshot")
    p.set_defaults(func=gui_main)
    p = subparsers.add_parser("shortcuts", help="every menu action of the main window with its shortcut")
    p.add_argument("--json", action="store_true", help='[{"menu", "action", "shortcut", "path"}, ...]')
    p.set_defaults(func=shortcuts_main)


def gui_main(args) -> int:
    """``carapost gui [FILE] [--screenshot OUT.png [--frame N]]``; no FILE: the built-in sample take."""
    if not args.file:
        from ..sample.builtin import builtin_sample_project

        args.file = str(builtin_sample_project())
    if args.screenshot:
        from .app import screenshot

        screenshot(args.file, args.screenshot, args.frame)
        return 0
    from PySide6.QtCore import QTimer

    from .app import ensure_app, install_error_hook
    from .mainwindow import MainWindow

    app = ensure_app()
    install_error_hook()
    win = MainWindow()
    win.show()
    if win.files.open_path(args.file) and args.frame is not None:
        win.navigate.set_frame(args.frame)
    QTimer.singleShot(0, win.recovery.offer)
    return int(app.exec())


def shortcuts_main(args) -> int:
    """``carapost shortcuts [--json]``: read from the live main window's menus (created offscreen)."""
    from .app import ensure_app
    from .mainwindow import MainWindow
    from .menus import menubar_table

    ensure_app(offscreen=True)
    win = MainWindow(autosave_s=0, restore=False, persist=False)
    rows = menubar_table(win.menuBar())
    win.close()
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    width = max(len(r["action"]) for r in rows)
    for r in rows:
        print(f"{r['path']:<22} {r['action']:<{width}}  {r['shortcut']}")
    return 0
