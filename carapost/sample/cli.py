"""``carapost sample OUT_DIR [--markers N] [--frames N] [--seed N]`` (CONTRACT section 2).

``carapost/cli.py`` wires it with ``add_parser(sub)``; ``python -m carapost.sample``
runs it on its own.
"""
from __future__ import annotations

import argparse
import sys

__all__ = ["add_parser", "run", "main"]


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Add the ``sample`` subcommand to an ``argparse`` subparsers object; returns its parser."""
    p = subparsers.add_parser("sample", help="write a synthetic take with ground truth",
                              description="Render a four-camera sample take (pico files) with its ground truth: "
                                          "calibration.xcp, truth_cameras.xcp, brim.svg, labels.txt, seeds.json, "
                                          "truth.c3d, truth.npz.")
    _arguments(p)
    p.set_defaults(func=run)
    return p


def _arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("out_dir", metavar="OUT_DIR", help="folder to write the take into (created if missing)")
    p.add_argument("--markers", type=int, default=100, help="painted face markers, 35-160 (default 100)")
    p.add_argument("--frames", type=int, default=120, help="frames at 60 fps (default 120)")
    p.add_argument("--seed", type=int, default=0, help="random seed; the same seed gives the same take (default 0)")
    p.add_argument("--white", action="store_true", help="white markers on a black brim (default: black on white)")
    p.add_argument("--size", default="1280x720", help="image size WxH (default 1280x720)")
    p.add_argument("--take", default="Sample", help="take name: <take>_<channel>.pico (default Sample)")
    p.add_argument("--workers", type=int, default=None, help="worker processes (default: one per CPU, at most 4)")
    p.add_argument("--seeds-frame", type=int, default=0, metavar="N",
                   help="frame the seeds.json clicks are made on; negative counts from the end, -1 the last "
                        "frame (default 0)")
    p.add_argument("--linear-dots", action="store_true",
                   help="draw each dot centred on the projection of its centre, as carapost did before session 24 "
                        "(default: as through a real lens, its image a few hundredths of a pixel off that)")
    p.add_argument("--quiet", action="store_true", help="no progress on stderr")
    g = p.add_argument_group("a second take of the same face (for Initialize from ROM)")
    g.add_argument("--motion-seed", type=int, default=None,
                   help="seed of the motion only: the same face, markers, rig and brim as --seed, another take")
    g.add_argument("--rig-move", default=None, metavar="MM,DEG",
                   help="the helmet (cameras and brim) put on again shifted MM mm and turned DEG degrees")
    g.add_argument("--camera-move", default=None, metavar="CHANNEL,MM,DEG",
                   help="one camera moved MM mm and turned DEG degrees relative to the rest of the rig")


def run(args) -> int:
    """Run the subcommand from parsed arguments; prints the files written."""
    from carapost.core.errors import CaraError

    from .take import write_sample

    try:
        w, h = (int(v) for v in str(args.size).lower().split("x"))
    except ValueError:
        raise CaraError(f"--size must be WIDTHxHEIGHT, not {args.size!r}") from None
    rig_move = _numbers(args.rig_move, 2, "--rig-move", "MM,DEG") if args.rig_move else (0.0, 0.0)
    camera_move = _numbers(args.camera_move, 3, "--camera-move", "CHANNEL,MM,DEG") if args.camera_move else None
    last = [-1]

    def progress(done, total, message=""):
        pct = int(100 * done / max(total, 1))
        if not args.quiet and pct != last[0] and sys.stderr.isatty():
            print(f"\r{message}: {pct:3d}%", end="", file=sys.stderr, flush=True)
            last[0] = pct

    info = write_sample(args.out_dir, markers=args.markers, frames=args.frames, seed=args.seed, white=args.white,
                        width=w, height=h, take=args.take, workers=args.workers, progress=progress,
                        motion_seed=args.motion_seed, rig_move=rig_move, camera_move=camera_move,
                        seeds_frame=args.seeds_frame, perspective_dots=not args.linear_dots)
    if not args.quiet and sys.stderr.isatty():
        print(file=sys.stderr)
    print(f"sample take: {info['frames']} frames, {info['markers']} face markers, {info['brim_markers']} brim "
          f"markers, seed {info['seed']}, {info['seconds']:.1f} s")
    for p in info["pico"]:
        print(f"  {p}")
    for key in ("calibration", "truth_cameras", "brim_svg", "labels", "seeds", "truth_c3d", "truth_npz"):
        print(f"  {info[key]}")
    return 0


def _numbers(text: str, n: int, flag: str, form: str) -> tuple:
    from carapost.core.errors import CaraError

    try:
        values = tuple(float(v) for v in str(text).split(","))
    except ValueError:
        values = ()
    if len(values) != n:
        raise CaraError(f"{flag} must be {form}, not {text!r}")
    return values


def main(argv=None) -> int:
    """``python -m carapost.sample OUT_DIR ...``."""
    from carapost.core.errors import CaraError

    p = argparse.ArgumentParser(prog="python -m carapost.sample", description="Write a synthetic sample take.")
    _arguments(p)
    args = p.parse_args(argv)
    try:
        return run(args)
    except CaraError as e:
        print(f"carapost: error: {e}", file=sys.stderr)
        return 2
