"""The ``carapost`` command line (CONTRACT section 2).

Each subcommand imports what it needs when it runs, so headless commands never
load Qt.  A bad or missing input exits with status 2 and one line on stderr
naming the file and the problem; tracebacks are for bugs only.
"""
from __future__ import annotations

import argparse
import json
import sys

from . import __version__
from .core.errors import CaraError


def _cmd_properties(args) -> int:
    from .core.properties import GROUPS, PROPERTY_TABLE, Properties

    props = Properties()
    if args.project:
        from .io.cara import load_project

        props = load_project(args.project).properties
    rows = [{"group": p.group, "group_title": GROUPS[p.group], "property": p.name, "title": p.title,
             "key": p.key, "type": p.type.__name__, "value": props[p.key], "default": p.default,
             "minimum": p.minimum, "maximum": p.maximum, "unit": p.unit, "help": p.help}
            for p in PROPERTY_TABLE]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    group = None
    for r in rows:
        if r["group"] != group:
            group = r["group"]
            print(f"[{r['group_title']}]  ({group})")
        unit = f" {r['unit']}" if r["unit"] else ""
        mark = "" if r["value"] == r["default"] else "   (default " + _fmt(r["default"]) + ")"
        print(f"  {r['key']:<58} = {_fmt(r['value'])}{unit}{mark}")
    return 0


def _fmt(v) -> str:
    return str(v).lower() if isinstance(v, bool) else f"{v:g}" if isinstance(v, float) else str(v)


def _cmd_info(args) -> int:
    from .info import describe

    info = describe(args.file)
    if args.json:
        print(json.dumps(info, indent=1, default=str))
    else:
        _print_tree(info)
    return 0


def _print_tree(d, indent: int = 0) -> None:
    pad = "  " * indent
    for k, v in d.items():
        if isinstance(v, dict):
            print(f"{pad}{k}:")
            _print_tree(v, indent + 1)
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            print(f"{pad}{k}:")
            for i, item in enumerate(v):
                print(f"{pad}  [{i}]")
                _print_tree(item, indent + 2)
        else:
            print(f"{pad}{k}: {v}")


def _cmd_export(args) -> int:
    from .io.cara import load_project

    project = load_project(args.project)
    if args.format == "c3d":
        from .io.export_c3d import export_c3d

        export_c3d(project, args.out)
    elif args.format == "fbx":
        from .io.export_fbx import write_fbx

        write_fbx(project, args.out)
    elif args.format == "xcp":
        from .io.export_xcp import export_xcp

        export_xcp(project, args.out, project.active_range[0] if args.frame is None else args.frame)
    print(f"wrote {args.out}")
    return 0


def _cmd_bench(args) -> int:
    from .bench import run_benchmarks

    return run_benchmarks(json_lines=args.json, only=args.only, quick=args.quick)


def build_parser() -> argparse.ArgumentParser:
    """The argument parser of every subcommand."""
    ap = argparse.ArgumentParser(prog="carapost", description="Facial capture clean-up: blobs to labelled 3D markers.")
    ap.add_argument("--version", action="version", version=f"carapost {__version__}")
    sub = ap.add_subparsers(dest="command")

    p = sub.add_parser("properties", help="every property group, property, value and default")
    p.add_argument("project", nargs="?", help="a .cara project (default: the defaults)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_properties)

    p = sub.add_parser("info", help="what a .pico, .xcp, .cara or .c3d file holds")
    p.add_argument("file")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=_cmd_info)

    p = sub.add_parser("export", help="the File menu's exports")
    p.add_argument("format", choices=["c3d", "fbx", "xcp"])
    p.add_argument("project", help="a .cara project")
    p.add_argument("out")
    p.add_argument("--frame", type=int, help="frame of the cameras for xcp (default: start of the active range)")
    p.set_defaults(func=_cmd_export)

    p = sub.add_parser("bench", help="run the benchmarks (one JSON object per line with --json)")
    p.add_argument("--json", action="store_true")
    p.add_argument("--quick", action="store_true", help="small sizes, for a smoke test")
    p.add_argument("--only", action="append", help="run only benchmarks whose module name contains this")
    p.set_defaults(func=_cmd_bench)

    from .batch_cli import add_batch_command
    from .blob_cli import add_blob_commands
    from .fillgaps_cli import add_fill_gaps_command
    from .process_cli import add_process_command
    from .sample.cli import add_parser as add_sample_command
    from .gui.cli_entry import add_gui_commands  # loads no Qt until `gui` or `shortcuts` runs

    add_batch_command(sub)
    add_blob_commands(sub)
    add_fill_gaps_command(sub)
    add_process_command(sub)
    add_sample_command(sub)

    add_gui_commands(sub)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Entry point of the ``carapost`` console script."""
    ap = build_parser()
    args = ap.parse_args(argv)
    if not getattr(args, "func", None):  # bare `carapost` opens the GUI (CONTRACT section 2)
        args = ap.parse_args(["gui"])
    try:
        return int(args.func(args) or 0)
    except CaraError as e:
        print(f"carapost: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("carapost: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
