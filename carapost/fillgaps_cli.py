"""``carapost fill-gaps IN.c3d OUT.c3d``: Interpolate Gaps on any C3D file.

Wired into :mod:`carapost.cli` by :func:`add_fill_gaps_command`.  Measured
samples are written back exactly (coordinates, residuals, camera masks);
filled samples get residual 0 and camera mask 0, which the C3D format reads as
"modelled / interpolated" (the C3D.org camera-mask note: contribution bits are
cleared when a point has been interpolated).  Errors are
:class:`~carapost.core.errors.CaraError`: exit status 2, one line on stderr.
"""
from __future__ import annotations

import sys
from pathlib import Path

from .core.errors import CaraError


def add_fill_gaps_command(subparsers) -> None:
    """Add ``fill-gaps`` to the ``carapost`` subcommands."""
    p = subparsers.add_parser("fill-gaps", help="Interpolate Gaps on a C3D file")
    p.add_argument("input", help="C3D file to fill")
    p.add_argument("output", help="C3D file to write")
    p.add_argument("--max-gap", type=int, default=None, help="leave gaps longer than N frames unfilled")
    p.add_argument("--set", action="append", default=[], metavar="gap_filling.NAME=VALUE",
                   help="a Gap-Filling Parameter (use_forwards_prediction, use_backwards_prediction)")
    p.set_defaults(func=fill_gaps_main)


def fill_gaps_main(args) -> int:
    """Read ``args.input``, fill its gaps, write ``args.output``; print a one-line summary."""
    import numpy as np

    from .core.gapfill import fill_gaps
    from .core.properties import Properties, parse_set_options
    from .io.c3d import read_c3d, write_c3d

    values = parse_set_options(args.set)           # validate before reading anything
    props = Properties()
    for k, v in values.items():
        props.set(k, v)
    if args.max_gap is not None and args.max_gap < 1:
        raise CaraError("--max-gap must be at least 1")
    src = Path(args.input)
    if not src.is_file():
        raise CaraError("no such file", src)
    data = read_c3d(src)
    for w in data.warnings:
        print(f"fill-gaps: warning: {src.name}: {w}", file=sys.stderr)
    filled, mask = fill_gaps(data.positions,
                             forwards=bool(props["gap_filling.use_forwards_prediction"]),
                             backwards=bool(props["gap_filling.use_backwards_prediction"]),
                             max_gap=args.max_gap)
    valid = data.valid
    residuals = np.where(valid, data.residuals, -1.0)   # negative: invalid
    residuals[mask] = 0.0                                # 0: modelled sample
    masks = np.where(valid, data.camera_masks, 0).astype(np.uint8)
    masks[mask] = 0
    pos = np.where(valid[..., None], data.positions, filled)
    # Same format and POINT:SCALE as the input, so that measured coordinates
    # and residual bytes are written back exactly.
    scale = abs(float(data.scale)) or None
    kw = dict(residuals=residuals, camera_masks=masks, first_frame=data.first_frame, units=data.units or "mm")
    try:
        write_c3d(args.output, pos, data.labels, data.rate, float_format=data.is_float, point_scale=scale, **kw)
    except ValueError:
        # A filled sample outside the integer range of POINT:SCALE: store floats.
        write_c3d(args.output, pos, data.labels, data.rate, float_format=True, point_scale=scale, **kw)
    left = int(np.count_nonzero(~np.isfinite(pos[..., 0])))
    print(f"{int(mask.sum())} samples filled in {data.points} points x {data.frames} frames, "
          f"{left} left empty -> {args.output}")
    return 0
