"""Project exports at the size of a one-minute facial take: C3D and FBX.

3,600 frames x 200 points (10 % of the samples missing, in runs, as tracking
leaves them), exported from a project as File > Export C3D / Export FBX do.
Baseline in the same run: ezc3d writing the same C3D file (positions,
residuals, camera masks), including the conversion to its layouts.
"""
from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

import numpy as np

from carapost.core.points import SRC_DETECTION, ST_NONE, ST_RECONSTRUCTED
from carapost.core.project import Project
from carapost.io.export_c3d import export_c3d, project_c3d_arrays
from carapost.io.export_fbx import write_fbx

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_c3d import _best, _ezc3d_write  # noqa: E402

FRAMES, POINTS = 3600, 200
TARGET_C3D_S = 2.0
TARGET_FBX_S = 5.0


def build_take(frames: int = FRAMES, points: int = POINTS, seed: int = 0) -> Project:
    """A tracked take: smooth trajectories, a tenth of the samples missing in gaps of 1-30 frames."""
    rng = np.random.default_rng(seed)
    p = Project(frames, 4, 60.0, name="bench")
    t = np.arange(frames)[:, None]
    for i in range(points):
        pt = p.new_point(label=f"M{i:03d}")
        pt.pos[:] = rng.normal(0, 40, 3) + 5 * np.sin(t / 30.0 + rng.uniform(0, 6, 3))
        pt.status[:] = ST_RECONSTRUCTED
        pt.residual[:] = 0.2
        pt.src[:] = SRC_DETECTION
        missing = 0
        while missing < frames // 10:
            a, n = int(rng.integers(0, frames)), int(rng.integers(1, 31))
            pt.status[a:a + n] = ST_NONE
            pt.pos[a:a + n] = np.nan
            missing += n
        p.add_point(pt)
    return p


def _ezc3d_export(path: Path, project: Project) -> None:
    """The same C3D export with ezc3d writing the file: our arrays, its writer."""
    pos, res, masks, labels = project_c3d_arrays(project)
    _ezc3d_write(path, pos, res, masks, labels, project.frame_rate)


def run(quick: bool = False) -> list[dict]:
    """Time the C3D and FBX exports of one project, beside ezc3d; figures, not assertions."""
    frames = 600 if quick else FRAMES
    repeats = 1 if quick else 3
    project = build_take(frames)
    tag = f"{frames}f x {POINTS}p"
    out: list[dict] = []
    with tempfile.TemporaryDirectory(dir=os.environ.get("CARAPOST_BENCH_DIR")) as d:
        c3d, fbx, ez = Path(d) / "t.c3d", Path(d) / "t.fbx", Path(d) / "ez.c3d"
        c3d_s = _best(lambda: export_c3d(project, c3d), repeats)
        fbx_s = _best(lambda: write_fbx(project, fbx), repeats)
        try:
            ez_s = _best(lambda: _ezc3d_export(ez, project), repeats)
        except ImportError:
            ez_s = None
        c3d_mb, fbx_mb = c3d.stat().st_size / 1e6, fbx.stat().st_size / 1e6
    out.append({"benchmark": f"export c3d {tag}", "value": round(c3d_s, 4), "unit": "s", "target": TARGET_C3D_S,
                "pass": c3d_s < TARGET_C3D_S, "file_mb": round(c3d_mb, 2),
                "baseline_ezc3d_s": None if ez_s is None else round(ez_s, 4)})
    out.append({"benchmark": f"export fbx {tag}", "value": round(fbx_s, 4), "unit": "s", "target": TARGET_FBX_S,
                "pass": fbx_s < TARGET_FBX_S, "file_mb": round(fbx_mb, 2),
                "baseline_ezc3d_c3d_s": None if ez_s is None else round(ez_s, 4)})
    return out


if __name__ == "__main__":
    import json

    for r in run():
        print(json.dumps(r))
