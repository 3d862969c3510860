"""``carapost detect-blobs`` and ``carapost detections`` (CONTRACT section 2).

Wired into :mod:`carapost.cli` by :func:`add_blob_commands`.  Errors are
:class:`~carapost.core.errors.CaraError`, which the CLI turns into exit status 2
and one line on stderr.
"""
from __future__ import annotations

import csv
import sys
import time
from pathlib import Path

from .core.errors import CaraError

CSV_COLUMNS = ("frame", "sensor", "x", "y", "major", "minor", "angle", "color", "score")


def detect_blobs_main(args) -> int:
    """Detect blobs over ``--start..--end`` (default: the active range) and save a project."""
    from .core.blob_ops import detect_blobs_range
    from .core.edits import SetProperties
    from .core.progress import Progress
    from .core.properties import parse_set_options
    from .io.cara import save_project
    from .io.take import project_from_input

    values = parse_set_options(args.set)           # validate before reading any media
    project = project_from_input(args.input, args.sources)
    if values:
        SetProperties(values).do(project)
    a0, a1 = project.active_range
    start = a0 if args.start is None else args.start
    end = a1 if args.end is None else args.end
    project.check_range(start, end)
    out = _output_path(args, project)
    last = [0.0]

    def report(done, total, _msg):
        if args.verbose and time.monotonic() - last[0] > 1.0:
            last[0] = time.monotonic()
            print(f"detect-blobs: {done}/{total} frames", file=sys.stderr)

    t = time.perf_counter()
    cmd = detect_blobs_range(project, start, end, progress=Progress(callback=report), workers=args.workers)
    cmd.do(project)
    dt = time.perf_counter() - t
    n = sum(len(r) for r in cmd.cells.values())
    save_project(project, out)
    print(f"{n} detections on {len(cmd.cells)} sensor-frames in {dt:.1f} s -> {out}")
    return 0


def _output_path(args, project) -> Path:
    if args.output:
        return Path(args.output)
    if args.input and Path(args.input).suffix.lower() == ".cara":
        return Path(args.input)
    base = Path(args.input) if args.input else Path(args.sources[0])
    return base.parent / f"{project.name or 'take'}.cara"


def detections_main(args) -> int:
    """Write every detection of a project as CSV: ``frame,sensor,x,y,major,minor,angle,color,score``."""
    from .io.cara import load_project

    project = load_project(args.project)
    out = Path(args.output)
    tmp = out.with_name(out.name + ".tmp")
    try:
        with open(tmp, "w", newline="") as fh:
            w = csv.writer(fh)
            w.writerow(CSV_COLUMNS)
            for s, table in enumerate(project.detections):
                for f in range(project.frame_count):
                    rec = table.frame(f)
                    for r in rec:
                        w.writerow((f, s, f"{r['x']:.4f}", f"{r['y']:.4f}", f"{float(r['major']):.3f}",
                                    f"{float(r['minor']):.3f}", f"{float(r['angle']):.2f}", int(r["color"]),
                                    f"{float(r['score']):.4f}"))
        tmp.replace(out)
    except OSError as e:
        tmp.unlink(missing_ok=True)
        raise CaraError(f"cannot write ({e.strerror})", out) from None
    return 0


def add_blob_commands(subparsers) -> None:
    """Add ``detect-blobs`` and ``detections`` to the ``carapost`` subparsers."""
    p = subparsers.add_parser("detect-blobs", help="blob detection over a frame range; writes a project")
    p.add_argument("input", nargs="?", help="a .pico of the take, a .cara project, or a video/image folder")
    p.add_argument("--sources", nargs="+", metavar="S", help="one video file or image folder per channel")
    p.add_argument("-o", "--output", help="project to write (default: <take>.cara beside the input)")
    p.add_argument("--start", type=int, help="first frame (default: start of the active range)")
    p.add_argument("--end", type=int, help="last frame, inclusive (default: end of the active range)")
    p.add_argument("--set", action="append", metavar="K=V", help="set a property, e.g. blob.find_white_blobs=true")
    p.add_argument("--workers", type=int, help="detection threads (default: every core)")
    p.add_argument("-v", "--verbose", action="store_true", help="progress on stderr")
    p.set_defaults(func=detect_blobs_main)

    p = subparsers.add_parser("detections", help="every detection of a project as CSV")
    p.add_argument("project", help="a .cara project")
    p.add_argument("-o", "--output", required=True, help="CSV file to write")
    p.set_defaults(func=detections_main)
