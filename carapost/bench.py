"""``carapost bench``: run every benchmark in ``benchmarks/`` and print its results.

Each ``benchmarks/bench_*.py`` has ``run(quick=False) -> list[dict]``; every dict
is one measurement (``benchmark``, ``value``, ``unit``, ``target``, ``pass`` and
any baseline figures measured in the same run).
"""
from __future__ import annotations

import importlib.util
import json
import sys
import time
from pathlib import Path

from .core.errors import CaraError


def benchmark_dir() -> Path:
    """The repository's ``benchmarks/`` folder."""
    d = Path(__file__).resolve().parent.parent / "benchmarks"
    if not d.is_dir():
        raise CaraError("benchmarks/ not found: run from a source checkout", d)
    return d


def run_benchmarks(json_lines: bool = True, only: list[str] | None = None, quick: bool = False) -> int:
    """Run the benchmarks; return 0 (figures are reported, never asserted)."""
    files = sorted(benchmark_dir().glob("bench_*.py"))
    if only:
        files = [f for f in files if any(o in f.stem for o in only)]
    for f in files:
        spec = importlib.util.spec_from_file_location(f.stem, f)
        mod = importlib.util.module_from_spec(spec)
        t0 = time.perf_counter()
        try:
            spec.loader.exec_module(mod)
            try:
                results = mod.run(quick=quick)
            except TypeError:
                results = mod.run()
        except CaraError as e:
            results = [{"benchmark": f.stem, "error": str(e)}]
        for r in results:
            r.setdefault("module", f.stem)
            if json_lines:
                print(json.dumps(r, default=float))
            else:
                print(f"{r.get('benchmark')}: {r.get('value')} {r.get('unit', '')} (target {r.get('target')})")
            sys.stdout.flush()
        if not json_lines:
            print(f"  [{f.stem}: {time.perf_counter() - t0:.1f} s]")
    return 0
