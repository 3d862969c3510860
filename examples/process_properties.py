#!/usr/bin/env python3
"""List every property of every property group, with its value, default and range.

The guide's ``process_properties.py``: the Blob, Tracking, Initialize 3D, Gap
Filling... parameters a script can set with ``CaraProcess.set_property(key,
value)``.  Without an argument it shows the defaults; with a ``.cara`` or a
``.pico`` it shows that project's values and marks with ``*`` those that
differ from the default::

    python process_properties.py
    python process_properties.py Example.cara --group blob
    python process_properties.py --json > properties.json
"""
import argparse
import json

from carapost.api import CaraExport, CaraProcess, property_table, run_script


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("project", nargs="?", help="a .cara project or a .pico take (default: the defaults)")
    ap.add_argument("--group", action="append", help="only this group (e.g. blob, tracking); repeatable")
    ap.add_argument("--json", action="store_true", help="one JSON list of every property")
    return ap.parse_args(argv)


def project_values(path: str) -> dict:
    """The properties of a ``.cara`` (read only) or of a new project of a ``.pico`` take."""
    if path.lower().endswith(".cara"):
        return CaraExport(path).properties()
    return CaraProcess(path).properties()


def text(value) -> str:
    if value is None:
        return ""
    if isinstance(value, bool):
        return "true" if value else "false"
    return f"{value:g}" if isinstance(value, float) else str(value)


def describe(row: dict) -> str:
    """``key  value [*]  (default D, MIN..MAX UNIT)  title``."""
    mark = " *" if row["value"] != row["default"] else ""
    limits = f", {text(row['minimum'])}..{text(row['maximum'])}" if row["minimum"] is not None else ""
    unit = f" {row['unit']}" if row["unit"] else ""
    return f"  {row['key']:<52} {text(row['value']) + mark:<10} (default {text(row['default'])}{limits}{unit})  " \
           f"{row['title']}"


def main(argv=None) -> int:
    args = parse_args(argv)
    values = project_values(args.project) if args.project else {}
    rows = [dict(r, value=values.get(r["key"], r["default"])) for r in property_table()
            if not args.group or r["group"] in args.group]
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    groups: dict[str, list[dict]] = {}
    for r in rows:
        groups.setdefault(r["group"], []).append(r)
    for group, members in groups.items():
        print(f"== {members[0]['group_title']} ({group}): {len(members)} properties")
        print("\n".join(describe(r) for r in members))
    print(f"{len(rows)} properties in {len(groups)} groups")
    return 0


if __name__ == "__main__":
    run_script(main)
