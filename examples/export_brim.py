#!/usr/bin/env python3
"""Print the 3D data of the calibration brim of a ``.cara`` file to the console.

The guide's ``export_brim.py``: first the brim's marker layout (its definition,
which fixes the world frame), then, per frame, every tracked brim marker's
position, in millimetres::

    python export_brim.py Example.cara
    python export_brim.py Example.cara --layout-only
"""
import argparse

import numpy as np

from carapost.api import CaraExport, run_script


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("project", help="a .cara project")
    ap.add_argument("--layout-only", action="store_true", help="only the brim's marker layout")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    cara = CaraExport(args.project)
    layout = cara.brim_markers()
    print(f"# brim layout: {len(layout)} markers (mm)")
    for i, (x, y, z) in enumerate(layout):
        print(f"marker {i:>3} {x:10.3f} {y:10.3f} {z:10.3f}")
    if args.layout_only:
        return 0
    tracked = dict(sorted(cara.brim_3d().items()))
    print(f"# tracked brim markers: {len(tracked)} in {cara.frame_count} frames (mm, brim frame)")
    print(f"{'frame':>6} {'marker':>6} {'x':>10} {'y':>10} {'z':>10}")
    for f in range(cara.frame_count):
        for index, xyz in tracked.items():
            if np.isfinite(xyz[f, 0]):
                print(f"{f:>6} {index:>6} {xyz[f, 0]:10.3f} {xyz[f, 1]:10.3f} {xyz[f, 2]:10.3f}")
    return 0


if __name__ == "__main__":
    run_script(main)
