#!/usr/bin/env python3
"""Query a ``.cara`` file for its point data and plot the points' 2D tracks to a PNG file.

The guide's ``export_general.py``.  It prints what the project holds (take,
frames, sensors, labels) and one row per point: how many frames it is
reconstructed in, seen by a single sensor only, interpolated, or missing.
Then it draws every point's 2D track in one sensor's image (raw pixels) into
a PNG: with matplotlib when it is installed (the guide's PyLab), else with
OpenCV::

    python export_general.py Example.cara -o tracks.png
    python export_general.py Example.cara -o tracks_cam2.png --sensor 2 --brim
"""
import argparse
import importlib.util

import numpy as np

from carapost.api import CaraError, CaraExport, run_script

STATUS = {1: "reconstructed", 2: "single_sensor", 3: "interpolated"}


def parse_args(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("project", help="a .cara project")
    ap.add_argument("-o", "--output", required=True, help="PNG file for the plot of the 2D tracks")
    ap.add_argument("--sensor", type=int, default=0, help="sensor (channel) whose 2D tracks are drawn (default 0)")
    ap.add_argument("--brim", action="store_true", help="also list and draw the brim points")
    ap.add_argument("--backend", choices=["auto", "matplotlib", "opencv"], default="auto",
                    help="how to draw (default: matplotlib if installed, else OpenCV)")
    return ap.parse_args(argv)


def point_table(cara: CaraExport, ids: list[int]) -> list[dict]:
    """Per point: id, name, and the count of frames of each status."""
    rows = []
    for pid in ids:
        status = cara.point_status(pid)
        row = {"id": pid, "name": cara.point_label(pid) or f"Point_{pid}"}
        row.update({name: int(np.count_nonzero(status == code)) for code, name in STATUS.items()})
        row["missing"] = int(np.count_nonzero(status == 0))
        rows.append(row)
    return rows


def plot_matplotlib(tracks: dict, size: tuple[int, int], title: str, path: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    w, h = size
    fig, ax = plt.subplots(figsize=(w / 100, h / 100), dpi=100)
    for name, uv in tracks.items():
        ax.plot(uv[:, 0], uv[:, 1], lw=1)
        ok = np.flatnonzero(np.isfinite(uv[:, 0]))
        if len(ok):
            ax.annotate(name, uv[ok[0]], fontsize=6)
    ax.set_xlim(0, w)
    ax.set_ylim(h, 0)                     # image rows grow downwards
    ax.set_title(title)
    fig.savefig(path)
    plt.close(fig)


def plot_opencv(tracks: dict, size: tuple[int, int], title: str, path: str) -> None:
    import cv2

    w, h = size
    img = np.full((h, w, 3), 255, np.uint8)
    rng = np.random.default_rng(0)
    for name, uv in tracks.items():
        colour = tuple(int(c) for c in rng.integers(0, 200, 3))
        ok = np.isfinite(uv[:, 0])
        # one polyline per run of consecutive frames: gaps stay gaps
        edges = np.flatnonzero(np.diff(np.r_[0, ok.astype(int), 0]))
        for a, b in zip(edges[::2], edges[1::2]):
            pts = np.round(uv[a:b]).astype(np.int32).reshape(-1, 1, 2)
            cv2.polylines(img, [pts], False, colour, 1, cv2.LINE_AA)
            cv2.circle(img, tuple(int(v) for v in pts[0, 0]), 2, colour, -1)
        if ok.any():
            x, y = np.round(uv[np.argmax(ok)]).astype(int)
            cv2.putText(img, name, (int(x) + 4, int(y) - 4), cv2.FONT_HERSHEY_SIMPLEX, 0.35, colour, 1, cv2.LINE_AA)
    cv2.putText(img, title, (10, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1, cv2.LINE_AA)
    if not cv2.imwrite(path, img):
        raise CaraError("cannot write the PNG file", path)


def main(argv=None) -> int:
    args = parse_args(argv)
    cara = CaraExport(args.project)
    if not 0 <= args.sensor < cara.sensor_count:
        raise CaraError(f"--sensor must be 0-{cara.sensor_count - 1}")
    ids = cara.point_ids(None if args.brim else "face")
    print(f"take {cara.take_name}: {cara.frame_count} frames at {cara.frame_rate:g} fps, {cara.sensor_count} sensors, "
          f"{len(cara.point_ids('face'))} face points, {len(cara.point_ids('brim'))} brim points, "
          f"{len(cara.labels())} labels")
    print(f"{'id':>5} {'point':<24} {'reconstructed':>13} {'single_sensor':>13} {'interpolated':>12} {'missing':>8}")
    for r in point_table(cara, ids):
        print(f"{r['id']:>5} {r['name']:<24} {r['reconstructed']:>13} {r['single_sensor']:>13} "
              f"{r['interpolated']:>12} {r['missing']:>8}")
    tracks = {cara.point_label(pid) or f"Point_{pid}": cara.point_2d(pid, args.sensor) for pid in ids}
    title = f"{cara.take_name}: 2D tracks in sensor {args.sensor}"
    backend = args.backend
    if backend == "auto":
        backend = "matplotlib" if importlib.util.find_spec("matplotlib") else "opencv"
    (plot_matplotlib if backend == "matplotlib" else plot_opencv)(tracks, cara.image_size(args.sensor), title,
                                                                   args.output)
    drawn = sum(bool(np.isfinite(uv[:, 0]).any()) for uv in tracks.values())
    print(f"{drawn} 2D tracks drawn with {backend} -> {args.output}")
    return 0


if __name__ == "__main__":
    run_script(main)
