#!/usr/bin/env python3
"""Print the 3D face data of a ``.cara`` file to the console.

The guide's ``export_3d_simple.py``: one line per point and frame that has a
3D position, in millimetres in the calibration brim's frame (CONTRACT section
4); frames are zero-based::

    python export_3d_simple.py Example.cara
    python export_3d_simple.py Example.cara --start 100 --end 199 --label Nose_Tip
"""
import argparse

import numpy as np

from carapost.api import CaraExport, run_script


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("project", help="a .cara project")
    ap.add_argument("--start", type=int, default=0, help="first frame (default 0)")
    ap.add_argument("--end", type=int, help="last frame, inclusive (default: the last)")
    ap.add_argument("--label", action="append", help="only the point with this label; repeatable")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    cara = CaraExport(args.project)
    end = cara.frame_count - 1 if args.end is None else min(args.end, cara.frame_count - 1)
    points = [(pid, cara.point_label(pid) or f"Point_{pid}") for pid in cara.point_ids()]
    if args.label:
        points = [(pid, name) for pid, name in points if name in args.label]
    print(f"# {cara.take_name}: {len(points)} face points, frames {args.start}-{end} of {cara.frame_count} "
          f"at {cara.frame_rate:g} fps; mm, brim frame")
    print(f"{'frame':>6}  {'point':<24} {'x':>10} {'y':>10} {'z':>10}")
    data = {pid: cara.point_3d(pid) for pid, _ in points}
    for f in range(args.start, end + 1):
        for pid, name in points:
            x, y, z = data[pid][f]
            if np.isfinite(x):
                print(f"{f:>6}  {name:<24} {x:10.3f} {y:10.3f} {z:10.3f}")
    return 0


if __name__ == "__main__":
    run_script(main)
