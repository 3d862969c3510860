"""Writes resources/brims/<version>.json: the project's own default brim layouts.

Vicon's brim geometry is not public; these are our designs (docs/brims.md).  Each
is a planar strip, markers in two staggered rows with a few off-row markers so
that no mirror or shift of the pattern maps it onto itself (a correspondence
search cannot confuse two markers).
"""
import json
from pathlib import Path

import numpy as np

DESIGNS = {
    # version: (width mm, height mm, markers per row, extra off-row markers)
    "v2.0": (160.0, 36.0, 8, [(-52.0, 0.0), (14.0, 3.0), (61.0, -4.0), (-11.0, -2.0)]),
    "v1.1": (150.0, 30.0, 7, [(-40.0, 1.0), (25.0, -2.5)]),
    "v1.0": (140.0, 30.0, 6, [(-33.0, 0.0), (48.0, 2.0)]),
}


def layout(width, height, per_row, extra):
    xs = np.linspace(-width / 2 + 8, width / 2 - 8, per_row)
    step = xs[1] - xs[0]
    top = np.stack([xs, np.full(per_row, -height / 2 + 6)], 1)
    bottom = np.stack([xs[:-1] + step / 2, np.full(per_row - 1, height / 2 - 6)], 1)
    pts = np.concatenate([top, bottom, np.asarray(extra, float)])
    return np.round(pts, 3)


def main():
    out = Path(__file__).resolve().parents[1] / "resources" / "brims"
    out.mkdir(parents=True, exist_ok=True)
    for version, (w, h, n, extra) in DESIGNS.items():
        xy = layout(w, h, n, extra)
        markers = [[float(x), float(y), 0.0] for x, y in xy]
        (out / f"{version}.json").write_text(json.dumps({"name": version, "markers": markers}, indent=1) + "\n")
        print(version, len(markers))


if __name__ == "__main__":
    main()
