#!/usr/bin/env python3
"""Write a solved ``.cara`` as an FBX file of animated Nulls, built node by node.

The guide's ``cara_fbx_export.py``: the same output as File > Export FBX, made
with the FBX scene API (:class:`carapost.io.fbx.FbxScene`, no Autodesk SDK
needed) so that it can be changed to suit a pipeline.  The tree is ``Face``
with one Null per face point and ``Brim`` with one per brim point; each Null is
named by the point's label (``Point_<id>`` when unlabelled) and keyed on every
frame that has a 3D position, in millimetres in the brim's frame::

    python cara_fbx_export.py Example.cara -o Example.fbx
    python cara_fbx_export.py Example.cara -o Example.fbx --group-by-prefix

``--group-by-prefix`` shows a customisation: face points go under one sub-node
per label prefix (``Lip_Upper`` and ``Lip_Corner_L`` under ``Face/Lip``).
"""
import argparse
from pathlib import Path

import numpy as np

from carapost.api import CaraExport, run_script
from carapost.io.fbx import FbxScene


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("project", help="a solved .cara project")
    ap.add_argument("-o", "--output", required=True, help="the .fbx file to write")
    ap.add_argument("--group-by-prefix", action="store_true",
                    help="face points under one sub-node per label prefix (the text before the first '_')")
    ap.add_argument("--no-brim", action="store_true", help="leave the brim points out")
    return ap.parse_args(argv)


def point_name(cara: CaraExport, pid: int) -> str:
    return cara.point_label(pid) or f"Point_{pid}"


def build_scene(cara: CaraExport, group_by_prefix: bool = False, brim: bool = True) -> tuple[FbxScene, int]:
    """The scene of every point of ``cara``; returns it and the number of animated Nulls."""
    scene = FbxScene(cara.frame_rate, take_name=cara.take_name or "Take 001")
    scene.set_time_span(0, cara.frame_count - 1)
    frames = np.arange(cara.frame_count)
    groups = {"Face": scene.add_null("Face")}
    brim_ids = set(cara.point_ids("brim"))
    if brim and brim_ids:
        groups["Brim"] = scene.add_null("Brim")
    count = 0
    for pid in cara.point_ids(None):          # project order, as File > Export FBX
        kind = "Brim" if pid in brim_ids else "Face"
        if kind == "Brim" and not brim:
            continue
        name = point_name(cara, pid)
        parent = groups[kind]
        if group_by_prefix and kind == "Face" and "_" in name:
            prefix = name.split("_", 1)[0]
            if prefix not in groups:
                groups[prefix] = scene.add_null(prefix, parent=groups["Face"])
            parent = groups[prefix]
        node = scene.add_null(name, parent=parent)
        xyz = cara.point_3d(pid)
        keep = np.isfinite(xyz).all(axis=1)
        scene.set_translation_keys(node, frames[keep], xyz[keep])
        count += 1
    return scene, count


def main(argv=None) -> int:
    args = parse_args(argv)
    cara = CaraExport(args.project)
    scene, count = build_scene(cara, args.group_by_prefix, brim=not args.no_brim)
    scene.write(args.output)
    print(f"{count} animated Nulls, {cara.frame_count} frames at {cara.frame_rate:g} fps -> {Path(args.output)}")
    return 0


if __name__ == "__main__":
    run_script(main)
