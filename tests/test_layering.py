"""The core, io and api never import Qt or rendering (DEVELOPERS rule 1)."""
import pkgutil
import subprocess
import sys

import carapost
from support import REPO


def test_headless_packages_do_not_import_qt():
    mods = [m.name for m in pkgutil.walk_packages(carapost.__path__, "carapost.")
            if m.name.split(".")[1] in ("core", "io", "api") or m.name.count(".") == 1 and not m.name.endswith(".gui")]
    mods = [m for m in mods if not m.startswith("carapost.gui") and not m.endswith("__main__")]
    code = ("import sys, importlib\n"
            f"for m in {mods!r}:\n    importlib.import_module(m)\n"
            "bad = sorted(k for k in sys.modules if k.split('.')[0] in ('PySide6', 'pyqtgraph', 'moderngl', 'shiboken6'))\n"
            "print(','.join(bad))\n")
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "", f"Qt imported by a headless module: {r.stdout}"
    assert len(mods) >= 10
