#!/usr/bin/env python3
"""Make a ``.cara`` for a ROM take, ready to be processed in carapost.

The guide's ``process_setup_ROM.py``.  A ROM (range of motion) take is the one
an actor's later takes are initialised from, so it is set up carefully once:
all the take's channels are imported, the camera calibration (``.xcp``) and the
calibration brim are set, the marker labels imported, and blobs detected on
every frame.  Given the clicks of ``seeds.json`` (CONTRACT section 3) it also
solves the brim and runs Initialize 3D on the seeds' frame, so the project
opens ready to track::

    python process_setup_ROM.py ROM_0.pico --xcp calibration.xcp --brim v2.0 --labels labels.txt
    python process_setup_ROM.py ROM_0.pico --xcp calibration.xcp --brim-svg brim.svg --seeds seeds.json -o ROM.cara
"""
import argparse
from pathlib import Path

from carapost.api import CaraProcess, run_script


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pico", help="one .pico file of the ROM take (every channel is loaded)")
    ap.add_argument("--xcp", required=True, help="the camera calibration of the shoot")
    brim = ap.add_mutually_exclusive_group(required=True)
    brim.add_argument("--brim", choices=["v2.0", "v1.1", "v1.0"], help="a default calibration brim")
    brim.add_argument("--brim-svg", help="a custom calibration brim (.svg)")
    ap.add_argument("--labels", help="marker labels, one per line (or a .cara to take them from)")
    ap.add_argument("--seeds", help="seeds.json: solve the brim and Initialize 3D on its frame")
    ap.add_argument("-o", "--output", help="project to write (default: <take>.cara beside the input)")
    ap.add_argument("--set", action="append", default=[], metavar="GROUP.NAME=VALUE",
                    help="a property, e.g. blob.black_threshold=0.3")
    return ap.parse_args(argv)


def set_up(args) -> tuple[CaraProcess, list[str]]:
    """The ROM's project and a line per step done."""
    process = CaraProcess(args.pico)
    done = [f"imported {process.project.sensor_count} channels of {process.project.frame_count} frames"]
    for item in args.set:
        key, _, value = item.partition("=")
        process.set_property(key.strip(), value)
    process.import_xcp(args.xcp)
    process.set_brim(args.brim or args.brim_svg)
    done.append(f"cameras from {args.xcp}, brim {args.brim or args.brim_svg}")
    if args.labels:
        process.import_labels(args.labels)
        done.append(f"{len(process.project.labels)} labels")
    process.detect_blobs()
    done.append("blobs detected on every frame")
    if args.seeds:
        frame = process.initialize_from_seeds(args.seeds)
        faces = sum(1 for _ in process.project.face_points())
        done.append(f"brim solved and {faces} face points initialised on frame {frame}")
    return process, done


def main(argv=None) -> int:
    args = parse_args(argv)
    process, done = set_up(args)
    out = Path(args.output) if args.output else Path(args.pico).with_name(f"{process.project.name}.cara")
    process.save(out)
    for line in done:
        print(line)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    run_script(main)
