"""``carapost process``: the whole pipeline headless (CONTRACT section 2).

detect blobs, brim correspondences and Solve Calibration Brim, face seeds
merged, Bundle Current Frame, Initialize 3D, Track Forwards [Sequence],
Interpolate Gaps, save, export.  Every step is a command on one undo stack, as
in the GUI; a failing step stops the run with exit status 2 and writes nothing.
"""
from __future__ import annotations

import json
import logging
import sys
import time
from pathlib import Path

from .core.errors import CaraError

log = logging.getLogger("carapost")


def add_process_command(subparsers) -> None:
    """Add ``process`` to the CLI."""
    p = subparsers.add_parser("process", help="the whole pipeline headless: blobs to a tracked, gap-filled project")
    p.add_argument("input", nargs="?", help="a .pico of the take (all channels are loaded) or a .cara")
    p.add_argument("--sources", nargs="+", metavar="S", help="one video file or image folder per channel")
    p.add_argument("--xcp", required=True, help="camera calibration")
    brim = p.add_mutually_exclusive_group(required=True)
    brim.add_argument("--brim-svg", help="a custom calibration brim")
    brim.add_argument("--brim", choices=["v2.0", "v1.1", "v1.0"], help="a default calibration brim")
    p.add_argument("--seeds", required=True, help="seeds.json: the clicks of CONTRACT section 3")
    p.add_argument("-o", "--out", required=True, help="the .cara project to write")
    p.add_argument("--c3d", help="also export a C3D file")
    p.add_argument("--fbx", help="also export an FBX file")
    p.add_argument("--set", action="append", metavar="K=V", help="property for this run, e.g. tracking.patch_match_threshold=0.7")
    p.add_argument("--no-track", action="store_true", help="stop after Initialize 3D")
    p.set_defaults(func=process_main)


def _step(name: str):
    t = time.perf_counter()
    print(f"{name} ...", file=sys.stderr, flush=True)
    return lambda extra="": print(f"{name}: done in {time.perf_counter() - t:.1f} s {extra}".rstrip(),
                                  file=sys.stderr, flush=True)


def process_main(args) -> int:
    """Run the pipeline; see :func:`add_process_command`."""
    from .core.blob_ops import detect_blobs_range
    from .core.brim import default_brim
    from .core.document import Document
    from .core.edits import SetProperties
    from .core.pipeline import process_to_init3d
    from .core.properties import parse_set_options
    from .io.brim_svg import read_brim_svg
    from .io.cara import save_project
    from .io.imports import import_xcp
    from .io.take import project_from_input

    out = Path(args.out)
    if not out.absolute().parent.is_dir():
        raise CaraError("the output folder does not exist", out.absolute().parent)
    overrides = parse_set_options(args.set)
    try:
        seeds = json.loads(Path(args.seeds).read_text())
    except FileNotFoundError:
        raise CaraError("no such file", args.seeds) from None
    except json.JSONDecodeError as e:
        raise CaraError(f"not valid JSON: {e}", args.seeds) from None
    brim = read_brim_svg(args.brim_svg) if args.brim_svg else default_brim(args.brim)

    project = project_from_input(args.input, args.sources)
    doc = Document(project)
    if overrides:
        doc.run(SetProperties(overrides, name="Set Properties (--set)"))
    doc.run(import_xcp(project, args.xcp, log))

    start, end = project.active_range
    done = _step(f"Detect Blobs [Active Range] {start}-{end}")
    doc.run(detect_blobs_range(project, start, end))
    done(f"({sum(d.total() for d in project.detections)} detections)")

    done = _step("Brim seeds, Solve Calibration Brim, face seeds, Bundle Current Frame, Initialize 3D")
    process_to_init3d(project, seeds, brim, log=lambda s: print(f"  {s}", file=sys.stderr), stack=doc.stack)
    done(f"({sum(1 for p in project.face_points())} face points)")

    frame = int(seeds.get("frame", 0))
    if not args.no_track:
        from .core.gapfill_ops import interpolate_gaps
        from .core.tracking import track
        from .io.frames import TakeFrames

        images = TakeFrames(project)
        try:
            for way, stop in ((+1, end), (-1, start)):
                if (stop - frame) * way > 0:
                    done = _step(f"Track {'Forwards' if way > 0 else 'Backwards'} [Sequence] {frame}-{stop}")
                    cmd = track(project, frame, way, images=images)
                    doc.run(cmd)
                    done()
                    print(f"  {cmd.summary}", file=sys.stderr)
        finally:
            images.close()
        done = _step("Interpolate Gaps")
        try:
            doc.run(interpolate_gaps(project))
        except CaraError as e:  # nothing to fill is not a failure of the run
            print(f"  {e}", file=sys.stderr)
        done()

    save_project(project, out)
    print(f"wrote {out}")
    if args.c3d:
        from .io.export_c3d import export_c3d

        export_c3d(project, args.c3d)
        print(f"wrote {args.c3d}")
    if args.fbx:
        from .io.export_fbx import write_fbx

        write_fbx(project, args.fbx)
        print(f"wrote {args.fbx}")
    return 0
