"""``carapost batch TAKE… --pipeline FILE [--workers N] [--scheduler tcp://HOST:PORT]`` (CONTRACT section 2).

Wired into :mod:`carapost.cli` by :func:`add_batch_command`; the engine is
:mod:`carapost.api.batch`.  Exit status: 0 when every take succeeded or was
already up to date, 1 when any take failed (each is named on stderr with a
one-line reason), 2 for bad arguments (a bad pipeline file, a TAKE that does
not exist, an unreachable scheduler).
"""
from __future__ import annotations

import sys
import time

from .core.errors import CaraError


def add_batch_command(subparsers) -> None:
    """Add ``batch`` to the ``carapost`` subcommands."""
    p = subparsers.add_parser(
        "batch", help="run a pipeline over many takes in parallel, locally or on a Dask cluster; resumable",
        description="Run the steps of a pipeline file on every take, one take per worker process (or per Dask "
                    "worker with --scheduler). Takes already up to date are skipped; a failed take is reported "
                    "and the others go on. See docs/batch.md for the pipeline file.")
    p.add_argument("takes", nargs="+", metavar="TAKE",
                   help="a .pico of a take (its whole take), a .cara project, a folder (every take beneath it) "
                        "or a quoted wildcard such as 'C:/Data/ROM*.pico'")
    p.add_argument("--pipeline", required=True, metavar="FILE", help="the pipeline file (JSON; docs/batch.md)")
    p.add_argument("--workers", type=int, metavar="N", help="local worker processes (default: every core)")
    p.add_argument("--scheduler", metavar="tcp://HOST:PORT",
                   help="run on this Dask distributed scheduler instead (its workers must see the same paths)")
    p.add_argument("--set", action="append", metavar="K=V",
                   help="a property for every take, after the pipeline's \"set\", e.g. blob.black_threshold=0.2")
    p.add_argument("--force", action="store_true", help="run every take, even those up to date")
    p.add_argument("--dry-run", action="store_true", help="list each take with its outputs and whether it would run")
    p.set_defaults(func=batch_main)


def batch_main(args) -> int:
    """Run ``carapost batch``; see :func:`add_batch_command`."""
    from .api.batch import find_takes, is_up_to_date, load_pipeline, plan_batch, run_batch
    from .core.properties import parse_set_options

    if args.workers is not None and args.workers < 1:
        raise CaraError("--workers must be at least 1")
    if args.scheduler and args.workers is not None:
        raise CaraError("--workers is for local runs; a Dask cluster has its own workers")
    overrides = parse_set_options(args.set)
    pipeline = load_pipeline(args.pipeline)
    takes = find_takes(args.takes)
    jobs = plan_batch(takes, pipeline, overrides)
    if args.dry_run:
        for job in jobs:
            state = "up to date" if not args.force and is_up_to_date(job) else "to run"
            print(f"{job.take}: {state}: {job.input} -> {', '.join(job.outputs.values())}")
        return 0
    bar = ProgressBar(sys.stderr)
    try:
        summary = run_batch(jobs, workers=args.workers, scheduler=args.scheduler, force=args.force,
                            on_result=bar.update, on_start=bar.start)
    finally:
        bar.finish()
    done, skipped, failed = summary.count("ok"), summary.count("skipped"), summary.failed
    print(f"batch: {_plural(len(jobs), 'take')} in {summary.seconds:.1f} s: {done} done, {skipped} up to date, "
          f"{len(failed)} failed", file=sys.stderr)
    for r in failed:
        print(f"carapost: batch: failed: {r.input}: {r.error}", file=sys.stderr)
    return 0 if summary.ok else 1


class ProgressBar:
    """A batch's progress on a stream: a redrawn bar on a terminal, one line per take otherwise.

    Parameters
    ----------
    stream : text stream
        Usually ``sys.stderr``.
    tty : bool, optional
        Force the terminal (bar) or plain mode; default: ``stream.isatty()``.
    """

    def __init__(self, stream=None, tty: bool | None = None, width: int = 30):
        self.stream = stream if stream is not None else sys.stderr
        self.tty = self.stream.isatty() if tty is None else tty
        self.width = width
        self.t0 = time.monotonic()
        self.failed = 0

    def start(self, to_run: int, total: int) -> None:
        skipped = total - to_run
        extra = f", {skipped} up to date" if skipped else ""
        self._line(f"batch: {_plural(total, 'take')}, {to_run} to run{extra}")

    def update(self, res, done: int, total: int) -> None:
        if res.status == "failed":
            self.failed += 1
        if res.status == "skipped" and self.tty:
            return  # the start line counts them; keep the terminal quiet
        if res.status == "failed":
            line = f"[{done}/{total}] FAILED {res.input}: {res.error}"
        elif res.status == "skipped":
            line = f"[{done}/{total}] up to date {res.take}"
        else:
            warned = f", {_plural(res.warnings, 'warning')} in its manifest" if res.warnings else ""
            line = f"[{done}/{total}] done {res.take} ({res.seconds:.1f} s{warned})"
        self._line(line)
        if self.tty:
            self._bar(done, total)

    def _bar(self, done: int, total: int) -> None:
        frac = done / max(total, 1)
        fill = int(round(self.width * frac))
        elapsed = time.monotonic() - self.t0
        eta = f", ~{elapsed / frac - elapsed:.0f} s left" if 0 < frac < 1 else ""
        failed = f", {self.failed} failed" if self.failed else ""
        self.stream.write(f"\r[{'#' * fill}{'.' * (self.width - fill)}] {done}/{total} takes{failed}, "
                          f"{elapsed:.0f} s{eta}\x1b[K")
        self.stream.flush()

    def _line(self, text: str) -> None:
        self.stream.write(("\r\x1b[K" if self.tty else "") + text + "\n")
        self.stream.flush()

    def finish(self) -> None:
        if self.tty:
            self.stream.write("\r\x1b[K")
            self.stream.flush()


def _plural(n: int, word: str) -> str:
    return f"{n} {word}{'' if n == 1 else 's'}"
