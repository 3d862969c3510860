#!/usr/bin/env python3
"""Track a take: from an initialised ``.cara``, or from a ``.pico`` initialised with a ROM.

The guide's ``process_track.py``.  With a ``.cara`` (points already initialised,
e.g. by Initialize 3D) it tracks from the first frame of the active range
onwards.  With a ``.pico`` and ``--rom ROM.cara`` it imports all the take's
channel files, detects blobs, initialises the take from the ROM (Initialize from
ROM: cameras, brim, labelled face points and sticks of the ROM's frame) and
then tracks::

    python process_track.py Example.cara
    python process_track.py Example_0.pico --rom ROM.cara -o Example.cara --c3d Example.c3d

With ``--frame N`` tracking starts there and also runs backwards to the start
of the active range.
"""
import argparse
from pathlib import Path

import numpy as np

from carapost.api import CaraError, CaraExport, CaraProcess, run_script


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("input", help="an initialised .cara project, or a .pico of the take (with --rom)")
    ap.add_argument("--rom", help="a ROM .cara of the same actor and marker set: initialise the .pico take from it")
    ap.add_argument("--brim-only", action="store_true", help="initialise only the brim and cameras from the ROM")
    ap.add_argument("--frame", type=int, help="frame to start from (default: start of the active range)")
    ap.add_argument("-o", "--output", help="project to write (default: the input .cara, or <take>.cara "
                                           "beside the .pico)")
    ap.add_argument("--c3d", help="also export a C3D file")
    ap.add_argument("--fill-gaps", action="store_true", help="Interpolate Gaps after tracking")
    ap.add_argument("--set", action="append", default=[], metavar="GROUP.NAME=VALUE",
                    help="a property, e.g. tracking.patch_match_threshold=0.7")
    return ap.parse_args(argv)


def track_take(args) -> Path:
    source = Path(args.input)
    is_pico = source.suffix.lower() == ".pico"
    if is_pico != bool(args.rom):
        raise CaraError("give a .cara, or a .pico with --rom ROM.cara")
    process = CaraProcess(source)
    for item in args.set:
        key, _, value = item.partition("=")
        process.set_property(key.strip(), value)
    start, end = process.project.active_range
    frame = start if args.frame is None else args.frame
    if is_pico:
        process.detect_blobs()
        process.load_rom(args.rom)
        report = process.initialize_from_rom(frame, brim_only=args.brim_only)
        print(f"Initialize from ROM on frame {frame}: {report.get('points', 0)} points, "
              f"{report.get('brim_markers', 0)} brim markers")
    if frame < end:
        process.track(frame)
    if frame > start:
        process.track(frame, backwards=True)
    if args.fill_gaps:
        process.interpolate_gaps()
    out = Path(args.output) if args.output else (source.with_name(f"{process.project.name}.cara") if is_pico
                                                 else source)
    process.save(out)
    if args.c3d:
        process.export_c3d(args.c3d)
    return out


def main(argv=None) -> int:
    out = track_take(parse_args(argv))
    result = CaraExport(out)
    ids = result.point_ids()
    tracked = sum(bool(np.any(result.point_status(pid) != 0)) for pid in ids)
    samples = sum(int(np.count_nonzero(result.point_status(pid))) for pid in ids)
    print(f"{tracked} of {len(ids)} face points tracked, {samples} 3D samples in {result.frame_count} "
          f"frames -> {out}")
    return 0


if __name__ == "__main__":
    run_script(main)
