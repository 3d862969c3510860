#!/usr/bin/env python3
"""Detect blobs on every take of a folder or wildcard that has no blob ``.cara`` yet.

The guide's ``process_batch_detect_blobs.py``, an example of a batch script
built on the scripting API.  It finds every take the argument names (a folder,
searched recursively, or a file name with wildcards, quoted so the shell
leaves it alone) and, for each take without a ``<take>_b.cara`` beside it,
detects blobs and writes one::

    python process_batch_detect_blobs.py C:/Data/Jobs
    python process_batch_detect_blobs.py "C:/Data/ROM*.pico"

Takes run one after another, each using every core for detection; ``carapost
batch`` runs whole pipelines over many takes in parallel, resumably, and on a
Dask cluster.
"""
import argparse
import sys
import time

from carapost.api import CaraError, CaraProcess, run_script
from carapost.api.batch import find_takes


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("where", nargs="+", help="a folder of takes, a .pico, or a quoted wildcard such as 'ROM*.pico'")
    ap.add_argument("--set", action="append", default=[], metavar="GROUP.NAME=VALUE",
                    help="a Blob Parameter for every take, e.g. blob.black_threshold=0.3")
    ap.add_argument("--force", action="store_true", help="detect again even where a blob .cara exists")
    return ap.parse_args(argv)


def main(argv=None) -> int:
    args = parse_args(argv)
    takes = find_takes(args.where)
    done = skipped = failed = 0
    for take in takes:
        out = take.folder / f"{take.name}_b.cara"
        if out.exists() and not args.force:
            print(f"skip   {take.name}: {out} exists")
            skipped += 1
            continue
        t0 = time.perf_counter()
        try:
            process = CaraProcess(take.input)
            for item in args.set:
                key, _, value = item.partition("=")
                process.set_property(key.strip(), value)
            process.detect_blobs()
            process.save(out)
        except CaraError as e:           # one bad take does not stop the others
            print(f"FAILED {take.name}: {e}", file=sys.stderr)
            failed += 1
            continue
        print(f"wrote  {take.name}: {out} ({time.perf_counter() - t0:.1f} s)")
        done += 1
    print(f"{len(takes)} takes: {done} detected, {skipped} skipped, {failed} failed")
    return 1 if failed else 0


if __name__ == "__main__":
    run_script(main)
