#!/usr/bin/env python3
"""Convert between the time representations of a take: frame index, burnt-in frame number, timecode.

The guide's ``export_timecode.py``.  Frame indices are zero-based positions in
the take (what every carapost tool uses); burnt-in frame numbers are the
numbers the cameras stamped into each ``.pico`` frame; timecode
``HH:MM:SS:FF`` counts from the take's start timecode at its frame rate.
Give one of ``--frame``, ``--burnt-in`` or ``--timecode`` to convert it, or
nothing to list every frame::

    python export_timecode.py Example.cara
    python export_timecode.py Example.cara --timecode 10:00:01:30
    python export_timecode.py Example.cara --burnt-in 12345 --sensor 2
"""
import argparse

from carapost.api import CaraError, CaraExport, run_script


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("project", help="a .cara project (its .pico media are read for the burnt-in numbers)")
    which = ap.add_mutually_exclusive_group()
    which.add_argument("--frame", type=int, help="a zero-based frame index")
    which.add_argument("--burnt-in", type=int, help="a burnt-in frame number")
    which.add_argument("--timecode", help="a timecode HH:MM:SS:FF")
    ap.add_argument("--sensor", type=int, default=0, help="the sensor whose burnt-in numbers are used (default 0)")
    ap.add_argument("--limit", type=int, help="list at most this many frames")
    return ap.parse_args(argv)


def row(cara: CaraExport, frame: int, sensor: int) -> str:
    return f"{frame:>8} {cara.frame_to_burnt_in(frame, sensor):>10} {cara.frame_to_timecode(frame):>13}"


def main(argv=None) -> int:
    args = parse_args(argv)
    cara = CaraExport(args.project)
    if args.burnt_in is not None:
        frames = [cara.burnt_in_to_frame(args.burnt_in, args.sensor)]
    elif args.timecode is not None:
        frames = [cara.timecode_to_frame(args.timecode)]
    elif args.frame is not None:
        frames = [args.frame]
    else:
        frames = list(range(cara.frame_count))[:args.limit]
    if any(not 0 <= f < cara.frame_count for f in frames):
        raise CaraError(f"frame {frames[0]} is outside the take (0-{cara.frame_count - 1})")
    print(f"# {cara.take_name}: {cara.frame_count} frames at {cara.frame_rate:g} fps, "
          f"timecode of frame 0: {cara.timecode_start}")
    print(f"{'frame':>8} {'burnt-in':>10} {'timecode':>13}")
    for f in frames:
        print(row(cara, f, args.sensor))
    return 0


if __name__ == "__main__":
    run_script(main)
