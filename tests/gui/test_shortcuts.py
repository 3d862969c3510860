"""Every menu item and shortcut of the guide's menu tables is in the live window (carapost shortcuts)."""
from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

pytestmark = pytest.mark.gui

# Typed from the Reference Guide's "Vicon CaraPost menus" tables (File, Edit, View, Process, Help),
# with the shortcuts the tables give (and "Shortcuts and mouse interactions": Shift+S, Ctrl+W).
GUIDE = {
    "File": [("Open", "Ctrl+O"), ("Clear", ""), ("Save", "Ctrl+S"), ("Save As", ""), ("Import Pico Files", ""),
             ("Import Calibration Brim [svg]", ""), ("Import XCP", ""), ("Import Labels From Cara File", ""),
             ("Import Labels From Text File", ""), ("Export XCP [Current Frame]", ""), ("Export C3D", ""),
             ("Export FBX", ""), ("Recent Files", ""), ("Clear Recent Files", ""), ("Exit", "")],
    "Edit": [("Undo", "Ctrl+Z"), ("Redo", "Ctrl+Y"), ("Clear History", ""), ("Create Points From Detections", ""),
             ("Delete Selected", "Ctrl+D"), ("Split Selected Point", ""), ("Merge", "M"),
             ("Merge and Select Next Label", "L"), ("Clear Selected [Current Frame]", ""),
             ("Clear Selected [Active Range]", ""), ("Detach Detections [Current Frame]", "Ctrl+H"),
             ("Detach Detections [Active Range]", "Ctrl+Shift+H"), ("Relocate Files", ""),
             ("Increment Image Sequence Offset", ""), ("Add Target Track", "Shift+A"),
             ("Edit Target Track", "Shift+E"), ("Stop Point Edit mode", "Shift+S"), ("Gaps To Keys", ""),
             ("Remove Unused Detections", ""), ("Remove Interpolated 3D Points", ""), ("Rename Point", "Ctrl+R"),
             ("Clear All Labels", ""), ("Delete Selected Labels", ""), ("Unlabel Selected Points", "Ctrl+U"),
             ("Create Stick from Selected Point", "S"), ("Create Stick Mesh", ""), ("Edit Stick Color", ""),
             ("Clear Active Range", ""), ("Restore Properties To Defaults", ""),
             ("Read Blob Parameters From Pico Files", "")],
    "View": [("Panels", ""), ("New Floating Workspace", ""), ("Show Calibration Brim SVG", ""),
             ("Full Screen", "F"), ("Toggle Dock Widget Visibility", "Ctrl+F"), ("Toggle Blob Preview", "Ctrl+B"),
             ("Toggle Show Stabilized", "Ctrl+Shift+S"), ("Go To Frame", "Ctrl+G"), ("Go to Start Frame", "Home"),
             ("Go to End Frame", "End"), ("Play", "Space"), ("Next Frame", "Right"), ("Prev Frame", "Left"),
             ("Lock To Point", ""), ("Next Key Frame", "Shift+Right"), ("Prev Key Frame", "Shift+Left"),
             ("Select Point", "Ctrl+P"), ("Get Point Information", ""),
             ("Rotate Selected Sensors Clockwise", "Ctrl+Right"),
             ("Rotate Selected Sensors Anticlockwise", "Ctrl+Left"), ("Select Point With Fewest Gaps", "Ctrl+A"),
             ("Go To Next Gap of Selected Point", ""), ("Distance Between Two Points", ""),
             ("Select Next Label", "K"), ("Select Previous Label", "J"), ("Set Active Range Start", "Ctrl+1"),
             ("Set Active Range End", "Ctrl+2"), ("Reset Active Range", "Ctrl+3"),
             ("Set View Range to Active Range", ""), ("Reset View Range", "")],
    "Process": [("Center Selection All 2D Views", "C"), ("Frame Selection All 2D Views", "Shift+C"),
                ("Detect Blobs [Active Range]", ""), ("Detect Blobs [Current Frame]", ""), ("Load ROM", ""),
                ("Initialize from ROM", ""), ("Initialize from ROM [Brim Only]", ""), ("ROM Tools", ""),
                ("Display ROM Timebar", ""), ("Add 2D To ROM Correspondence", "Ctrl+L"),
                ("Clear 2D To ROM Correspondence", ""), ("Solve ROM Camera From Correspondences", ""),
                ("Solve ROM Face Alignment From Correspondences", ""),
                ("Initialize Default Calibration Brim [v2.0]", ""), ("Initialize Default Calibration Brim [v1.1]", ""),
                ("Initialize Default Calibration Brim [v1.0]", ""), ("Solve Calibration Brim [Manual]", ""),
                ("Initialize 3D", ""), ("Bundle Current Frame [Unconstrained]", ""),
                ("Bundle Sequence [Unconstrained]", ""), ("Track Forwards [Sequence]", ""),
                ("Track Backwards [Sequence]", ""), ("Track Forwards [Single Frame]", "Ctrl+W"),
                ("Track Backwards [Single Frame]", ""), ("Stabilize Data [Manual]", ""),
                ("Stabilize Data [Assisted]", ""), ("Align Data", ""), ("Interpolate Gaps", "")],
    "Help": [("View latest help on vicon.com", ""), ("View installed help", ""), ("Check For Updates", ""),
             ("Licensing", ""), ("Show 3rd Party Licenses", ""), ("About", "")],
}
PANELS = ["Labelling", "History", "Selected Point", "Log", "Properties", "Selection", "Tracker"]


def test_carapost_shortcuts_json_lists_every_guide_item(capsys, qapp):
    from carapost.gui.cli_entry import shortcuts_main

    assert shortcuts_main(SimpleNamespace(json=True)) == 0
    rows = json.loads(capsys.readouterr().out)
    have = {(r["menu"], r["action"]): r["shortcut"] for r in rows}
    for menu, items in GUIDE.items():
        for title, shortcut in items:
            assert (menu, title) in have, f"{menu} > {title} is missing"
            assert have[(menu, title)] == shortcut, f"{menu} > {title}: {have[(menu, title)]!r} != {shortcut!r}"
    panels = [r["action"] for r in rows if r["path"] == "View > Panels"]
    assert panels == PANELS
    # menu order follows the guide's tables
    for menu, items in GUIDE.items():
        got = [r["action"] for r in rows if r["menu"] == menu and r["path"] == menu]
        assert got == [t for t, _s in items if (menu, t) not in {("Process", n) for n, _ in GUIDE["Process"][8:13]}]


def test_menus_have_mnemonics_and_unavailable_items_say_why(qtbot, window):
    from carapost.core.actions import ACTIONS

    for qa in window.menuBar().actions():
        assert qa.text().startswith("&")
    for a in ACTIONS:
        qa = window.action(a.id)
        if not a.available:
            assert not qa.isEnabled() and qa.toolTip().startswith("Not available"), a.id
    assert window.action("process.align").isEnabled()
    assert window.action("process.initialize_3d").isEnabled()
    # each menu's Alt letters are unique; an item has none only when every letter of its title is taken
    for top in window.menuBar().actions():
        taken = set()
        for a in top.menu().actions():
            if a.isSeparator():
                continue
            if "&" in a.text():
                letter = a.text().lower().split("&")[1][0]
                assert letter not in taken, a.text()
                taken.add(letter)
        for a in top.menu().actions():
            if not a.isSeparator() and "&" not in a.text():
                assert {c for c in a.text().lower() if c.isalnum()} <= taken, a.text()


def test_user_guide_lists_every_action():
    from pathlib import Path

    from carapost.core.actions import ACTIONS

    text = (Path(__file__).resolve().parents[2] / "docs" / "gui.md").read_text()
    for a in ACTIONS:
        assert f"| {a.title} |" in text or f"▸ {a.title} |" in text, a.title
        if a.shortcut:
            assert f"`{a.shortcut}`" in text, a.shortcut


def test_cli_entry_imports_no_qt():
    """The CLI builds its parser with add_gui_commands: that must not load Qt for headless commands."""
    import subprocess
    import sys

    code = ("import sys, carapost.gui.cli_entry\n"
            "print(sorted(m for m in sys.modules if m.split('.')[0] in ('PySide6', 'shiboken6', 'pyqtgraph')))")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and r.stdout.strip() == "[]", r.stdout + r.stderr
