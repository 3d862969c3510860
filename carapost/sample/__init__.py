"""The synthetic sample take: a head-mounted four-camera capture with known ground truth.

``write_sample(out_dir, ...)`` (what ``carapost sample`` runs) renders a face
with painted markers moving through expressions, seen by the four cameras of
a Cara-like rig with a calibration brim, and writes the channels as ``.pico``
files with the truth beside them (see ``docs/sample.md``).

Modules: :mod:`.face` (skin surface, eyelids, expressions), :mod:`.markers`
(marker layout and labels), :mod:`.rig` (cameras, brim), :mod:`.motion`
(per-frame tracks), :mod:`.texture` (albedo), :mod:`.scene` (a take as data,
per-frame geometry), :mod:`.raster` and :mod:`.coverage` (rasterisers),
:mod:`.render` (one image), :mod:`.take` (the files).
"""
from __future__ import annotations

from .take import SAMPLE_FILES, write_sample

__all__ = ["write_sample", "SAMPLE_FILES", "add_sample_parser"]


def add_sample_parser(subparsers):
    """Add the ``sample`` subcommand to the ``carapost`` argument parser (see :mod:`.cli`)."""
    from .cli import add_parser

    return add_parser(subparsers)
