"""Writes tests/data/golden_v<N>.cara with the current format version.

Run once per new format version (``python tests/data/make_golden.py``) and keep
every older golden file: tests load them all.
"""
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))

from test_cara import _full_project  # noqa: E402  (tests/ is on sys.path)

from carapost.io import cara  # noqa: E402

if __name__ == "__main__":
    out = HERE / f"golden_v{cara.FORMAT_VERSION}.cara"
    cara.save_project(_full_project(), out)
    print(out, out.stat().st_size)
