#!/usr/bin/env python3
"""Detect blobs on every frame of a take and write ``<take>_b.cara``.

The guide's ``process_detect_blobs.py``: give it one ``.pico`` file of a take;
all the take's channel files (``<take>_0.pico`` ... ``<take>_3.pico``) are
loaded, blobs are detected on every frame of every channel with the Blob
Parameters (the take's own, changed with ``--set``), and the project is written
beside the input as ``<take>_b.cara``::

    python process_detect_blobs.py Example_0.pico
    python process_detect_blobs.py Example_0.pico --set blob.black_threshold=0.3 --start 0 --end 99
"""
import argparse
from pathlib import Path

from carapost.api import CaraExport, CaraProcess, run_script


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("pico", help="one .pico file of the take (every channel of the take is loaded)")
    ap.add_argument("-o", "--output", help="project to write (default: <take>_b.cara beside the input)")
    ap.add_argument("--start", type=int, help="first frame (default: start of the active range)")
    ap.add_argument("--end", type=int, help="last frame, inclusive (default: end of the active range)")
    ap.add_argument("--set", action="append", default=[], metavar="GROUP.NAME=VALUE",
                    help="a Blob Parameter, e.g. blob.find_white_blobs=true (see process_properties.py)")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    process = CaraProcess(args.pico)
    for item in args.set:
        key, _, value = item.partition("=")
        process.set_property(key.strip(), value)
    process.detect_blobs(start=args.start, end=args.end)
    out = Path(args.output) if args.output else Path(args.pico).with_name(f"{process.project.name}_b.cara")
    process.save(out)
    result = CaraExport(out)
    per_sensor = [sum(len(result.detections(s, f)) for f in range(result.frame_count))
                  for s in range(result.sensor_count)]
    print(f"{sum(per_sensor)} blobs ({', '.join(map(str, per_sensor))} per channel) in "
          f"{result.frame_count} frames -> {out}")
    return 0


if __name__ == "__main__":
    run_script(main)
