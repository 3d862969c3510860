"""Batch processing: one pipeline over many takes, locally or on a Dask cluster (``carapost batch``).

A *pipeline file* (JSON, see ``docs/batch.md``) names the steps to run on each
take, the properties to set and the files to write.  :mod:`carapost.api.batch_plan`
validates it and makes one self-contained :class:`Job` per take (its names are
re-exported here); :func:`run_batch` runs them on worker processes of this machine or, given a
scheduler address, on a Dask distributed cluster.  Each take runs in
:func:`run_take`, which never raises: a failed take comes back as a result with
a one-line reason and the others go on.

Resumable: a take whose outputs exist, are newer than every input, and whose
manifest (``<take>.batch.json`` beside its outputs) records a successful run of
the same pipeline is skipped.  Outputs are written under temporary names and
renamed, so an interrupted run never leaves a file that looks finished.

This module never imports Qt.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import socket
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

from ..core.errors import CaraError
from .batch_plan import (MANIFEST_SUFFIX, OUTPUT_KINDS, STEP_NAMES, Job, Pipeline, Take, find_takes, is_up_to_date,
                         load_pipeline, parse_pipeline, plan_batch)

__all__ = ["Pipeline", "Take", "Job", "TakeResult", "BatchSummary", "load_pipeline", "parse_pipeline", "find_takes",
           "plan_batch", "is_up_to_date", "run_batch", "run_take", "STEP_NAMES", "OUTPUT_KINDS", "MANIFEST_SUFFIX"]

_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


# --------------------------------------------------------------------------- one take
@dataclass
class TakeResult:
    """What became of one take.

    Attributes
    ----------
    take : str
    input : str
        The take's file, as reported on failure.
    status : str
        ``"ok"``, ``"skipped"`` (up to date) or ``"failed"``.
    error : str
        The one-line reason of a failure (``""`` otherwise).
    seconds : float
    outputs : dict
        Output kind -> path.
    warnings : int
        Log warnings during the run (the manifest lists them).
    """

    take: str
    input: str
    status: str
    error: str = ""
    seconds: float = 0.0
    outputs: dict = field(default_factory=dict)
    warnings: int = 0

    @classmethod
    def from_dict(cls, d: dict) -> "TakeResult":
        return cls(d["take"], d["input"], d["status"], d.get("error", ""), float(d.get("seconds", 0.0)),
                   dict(d.get("outputs", {})), int(d.get("warnings", 0)))


def run_take(job: dict, single_threaded: bool = False) -> dict:
    """Run one take's pipeline and write its outputs and manifest; never raises.

    The function a worker process (or a Dask worker) runs.  Log messages go to
    the manifest, not to the terminal, where several workers would interleave
    them.

    Parameters
    ----------
    job : dict
        :meth:`Job.to_dict`.
    single_threaded : bool
        Limit OpenCV (and BLAS, where not yet loaded) to one thread in this
        process first, as a batch worker should.

    Returns
    -------
    dict
        :class:`TakeResult` fields; a failure is ``status="failed"`` with a
        one-line ``error`` (the manifest also keeps the traceback).
    """
    t0 = time.perf_counter()
    started = time.strftime("%Y-%m-%dT%H:%M:%S")
    status, error, tb = "ok", "", ""
    at = ["open"]
    if single_threaded:
        _limit_threads()
    with _captured_log() as messages:
        try:
            _run_steps(job, at)
        except Exception as e:  # noqa: BLE001 - a take's failure must not stop the batch
            status, error, tb = "failed", _one_line(e, at[0], job["input"]), traceback.format_exc()
    seconds = round(time.perf_counter() - t0, 3)
    warnings = sum(not m.startswith("info:") for m in messages)
    result = {"take": job["take"], "input": job["input"], "status": status, "error": error, "seconds": seconds,
              "outputs": job["outputs"], "warnings": warnings}
    manifest = dict(result, fingerprint=job["fingerprint"], inputs=job["inputs"], started=started,
                    finished=time.strftime("%Y-%m-%dT%H:%M:%S"), host=socket.gethostname(), pid=os.getpid(),
                    steps=[s["step"] for s in job["steps"]], properties=job["properties"], log=messages)
    if tb:
        manifest["traceback"] = tb
    try:
        _write_json_atomic(Path(job["manifest"]), manifest)
    except OSError as e:
        if status == "ok":
            result.update(status="failed", error=f"{job['manifest']}: cannot write the manifest ({e.strerror})")
    return result


def _run_steps(job: dict, at: list[str]) -> None:
    """The take's steps, then its outputs; ``at[0]`` names the step running (for the error line)."""
    from ..core.edits import SetProperties
    from . import CaraProcess

    proc = CaraProcess(job["input"])
    if job["properties"]:
        proc.document.run(SetProperties(job["properties"], name="Set Properties (batch)"))
    state: dict = {}
    for s in job["steps"]:
        at[0] = f"{s['step']} (steps[{s['index']}])"
        _STEPS[s["step"]](proc, s, state)
    at[0] = "write outputs"
    _write_outputs(proc, job["outputs"])


@contextlib.contextmanager
def _captured_log():
    """Collect the ``carapost`` logger's messages (info and up) in a list instead of printing them."""
    import logging

    messages: list[str] = []

    class ToList(logging.Handler):
        def emit(self, record):
            messages.append(f"{record.levelname.lower()}: {record.getMessage()}")

    logger = logging.getLogger("carapost")
    saved = logger.propagate, logger.level
    handler = ToList(logging.INFO)
    logger.addHandler(handler)
    logger.propagate = False
    logger.setLevel(min(logger.getEffectiveLevel(), logging.INFO))
    try:
        yield messages
    finally:
        logger.removeHandler(handler)
        logger.propagate, level = saved
        logger.setLevel(level)


def _one_line(e: BaseException, step: str, input_path: str = "") -> str:
    """``step: reason`` on one line; the take's own file is not repeated (the report names it)."""
    msg = str(e).strip() if isinstance(e, CaraError) else (f"{type(e).__name__}: {e}" if str(e) else "")
    msg = msg.splitlines()[0] if msg else type(e).__name__
    if input_path and msg.startswith(input_path + ": "):
        msg = msg[len(input_path) + 2:]
    return f"{step}: {msg}" if step else msg


def _limit_threads() -> None:
    """One thread per library in a batch worker: the batch already runs a take per core."""
    for var in _THREAD_VARS:
        os.environ.setdefault(var, "1")
    try:
        import cv2

        cv2.setNumThreads(1)
    except ImportError:  # pragma: no cover - OpenCV is a dependency
        pass


def _step_set(proc, s, state) -> None:
    from ..core.edits import SetProperties

    proc.document.run(SetProperties(s["values"], name="Set Properties (batch)"))


def _step_detect_blobs(proc, s, state) -> None:
    proc.detect_blobs(s.get("sensors"), s.get("start"), s.get("end"), workers=1)


def _step_initialize(proc, s, state) -> None:
    state["frame"] = proc.initialize_from_seeds(s["seeds"])


def _step_initialize_from_rom(proc, s, state) -> None:
    proc.load_rom(s["rom"])
    frame = proc.document.current_frame if s.get("frame") is None else int(s["frame"])
    proc.initialize_from_rom(frame, brim_only=bool(s.get("brim_only", False)))
    state["frame"] = frame


def _step_track(proc, s, state) -> None:
    start, end = proc.project.active_range
    frame = s.get("frame", state.get("frame", start))
    direction = s.get("direction", "both")
    if direction in ("forwards", "both") and frame < end:
        proc.track(frame)
    if direction in ("backwards", "both") and frame > start:
        proc.track(frame, backwards=True)


def _step_interpolate_gaps(proc, s, state) -> None:
    import logging

    try:
        proc.interpolate_gaps()
    except CaraError as e:
        # Nothing to fill (no gaps, no points) is not a failure of the take.
        logging.getLogger("carapost").info(f"Interpolate Gaps: {e}")


_STEPS: dict[str, Callable] = {
    "set": _step_set,
    "import_xcp": lambda proc, s, state: proc.import_xcp(s["path"]),
    "import_labels": lambda proc, s, state: proc.import_labels(s["path"]),
    "set_brim": lambda proc, s, state: proc.set_brim(s["brim"]),
    "detect_blobs": _step_detect_blobs,
    "initialize": _step_initialize,
    "initialize_from_rom": _step_initialize_from_rom,
    "bundle_sequence": lambda proc, s, state: proc.bundle_sequence(s.get("start"), s.get("end")),
    "track": _step_track,
    "interpolate_gaps": _step_interpolate_gaps,
}


def _write_outputs(proc, outputs: dict[str, str]) -> None:
    """Each output under a temporary name beside it, then renamed: a crash leaves no finished-looking file."""
    writers = {"cara": proc.save, "c3d": proc.export_c3d, "xcp": proc.export_xcp, "fbx": proc.export_fbx}
    for kind, path in outputs.items():
        out = Path(path)
        try:
            out.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise CaraError(f"cannot create the output folder ({e.strerror})", out.parent) from None
        tmp = out.with_name(f".{out.stem}.{os.getpid()}.tmp{out.suffix}")
        try:
            writers[kind](tmp)
            os.replace(tmp, out)
        finally:
            if tmp.exists():
                tmp.unlink()


def _write_json_atomic(path: Path, data: dict) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(json.dumps(data, indent=1, default=str) + "\n", encoding="utf-8")
    os.replace(tmp, path)


# --------------------------------------------------------------------------- the batch
@dataclass
class BatchSummary:
    """The results of a batch, in the order the takes finished."""

    results: list[TakeResult]
    seconds: float

    def count(self, status: str) -> int:
        return sum(r.status == status for r in self.results)

    @property
    def failed(self) -> list[TakeResult]:
        return [r for r in self.results if r.status == "failed"]

    @property
    def ok(self) -> bool:
        """True when no take failed (skipped takes are up to date, not failures)."""
        return not self.failed


def run_batch(jobs: list[Job], workers: int | None = None, scheduler: str | None = None, force: bool = False,
              on_result: Callable[[TakeResult, int, int], None] | None = None,
              on_start: Callable[[int, int], None] | None = None) -> BatchSummary:
    """Run every job: skip those up to date, the rest on local processes or a Dask cluster.

    Parameters
    ----------
    jobs : list of Job
    workers : int, optional
        Local worker processes (default: every core).  Ignored with ``scheduler``.
    scheduler : str, optional
        A Dask distributed scheduler address (``tcp://HOST:PORT``); every worker
        must see the takes' files at the same paths.
    force : bool
        Run every take, even those up to date.
    on_result : callable, optional
        ``fn(result, done, total)`` after each take (skipped ones included).
    on_start : callable, optional
        ``fn(to_run, total)`` once the up-to-date takes are known.

    Returns
    -------
    BatchSummary

    Raises
    ------
    CaraError
        When the scheduler cannot be reached.
    """
    t0 = time.perf_counter()
    results: list[TakeResult] = []
    total = len(jobs)

    def report(res: TakeResult) -> None:
        results.append(res)
        if on_result is not None:
            on_result(res, len(results), total)

    fresh = [not force and is_up_to_date(job) for job in jobs]
    todo = [job for job, skip in zip(jobs, fresh) if not skip]
    if on_start is not None:
        on_start(len(todo), total)
    for job, skip in zip(jobs, fresh):
        if skip:
            report(TakeResult(job.take, job.input, "skipped", outputs=job.outputs))
    if todo:
        if scheduler:
            _run_dask(todo, scheduler, report)
        else:
            _run_local(todo, workers or os.cpu_count() or 1, report)
    return BatchSummary(results, round(time.perf_counter() - t0, 3))


@contextlib.contextmanager
def _single_threaded_children():
    """Worker processes start with one BLAS/OpenMP thread (set before they import numpy)."""
    saved = {v: os.environ.get(v) for v in _THREAD_VARS}
    os.environ.update({v: "1" for v in _THREAD_VARS})
    try:
        yield
    finally:
        for v, old in saved.items():
            if old is None:
                os.environ.pop(v, None)
            else:
                os.environ[v] = old


def _run_local(jobs: list[Job], workers: int, report: Callable[[TakeResult], None]) -> None:
    """Jobs on a pool of spawned processes; a take that kills its worker is retried alone to find the culprit."""
    crashed = _run_pool(jobs, max(1, min(workers, len(jobs))), report)
    if len(crashed) == 1:
        report(_crash_result(crashed[0]))
        return
    # The pool broke with several takes in flight or queued; run each alone so only the culprit fails.
    for job in crashed:
        if _run_pool([job], 1, report):
            report(_crash_result(job))


def _crash_result(job: Job) -> TakeResult:
    return TakeResult(job.take, job.input, "failed", "the worker process died (out of memory or a crash)")


def _run_pool(jobs: list[Job], workers: int, report: Callable[[TakeResult], None]) -> list[Job]:
    """Run ``jobs`` on a fresh pool; returns those whose worker died."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    crashed: list[Job] = []
    with _single_threaded_children():
        pool = ProcessPoolExecutor(workers, mp_context=multiprocessing.get_context("spawn"), initializer=_limit_threads)
        try:
            pending = {pool.submit(run_take, job.to_dict()): job for job in jobs}
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for fut in done:
                    job = pending.pop(fut)
                    try:
                        report(TakeResult.from_dict(fut.result()))
                    except BrokenProcessPool:
                        crashed.append(job)
                    except Exception as e:  # noqa: BLE001 - e.g. a result that failed to unpickle
                        report(TakeResult(job.take, job.input, "failed", _one_line(e, "")))
        finally:
            pool.shutdown(wait=True, cancel_futures=True)
    return crashed


def _run_dask(jobs: list[Job], address: str, report: Callable[[TakeResult], None]) -> None:
    """Jobs on a Dask distributed cluster; a worker lost mid-take fails only that take."""
    try:
        from dask.distributed import Client, as_completed
    except ImportError:  # pragma: no cover - dask[distributed] is a dependency
        raise CaraError("--scheduler needs dask.distributed (pip install 'dask[distributed]')") from None
    _probe(address)
    try:
        client = Client(address, timeout="15s", set_as_default=False)
    except (OSError, TimeoutError, ValueError) as e:
        raise CaraError(f"cannot connect to the Dask scheduler {address}: {e}") from None
    try:
        token = hashlib.sha1(f"{time.time()}{os.getpid()}".encode()).hexdigest()[:8]
        futures, by_key = [], {}
        for i, job in enumerate(jobs):
            fut = client.submit(run_take, job.to_dict(), True, key=f"carapost-batch-{token}-{i}-{job.take}",
                                pure=False, retries=0)
            futures.append(fut)
            by_key[fut.key] = job
        for fut in as_completed(futures, loop=client.loop):
            job = by_key[fut.key]
            try:
                report(TakeResult.from_dict(fut.result()))
            except Exception as e:  # noqa: BLE001 - KilledWorker, a lost connection...
                report(TakeResult(job.take, job.input, "failed", f"on the Dask cluster: {_one_line(e, '')}"))
            fut.release()
    finally:
        client.close()


def _probe(address: str) -> None:
    """Fail at once, not after Dask's connect timeout, when nothing listens at a ``tcp://`` address."""
    from urllib.parse import urlsplit

    if not address.startswith("tcp://"):
        return  # other protocols (tls://, inproc://) are left to Dask
    try:
        url = urlsplit(address)
        host, port = url.hostname, url.port
    except ValueError:
        host = port = None
    if not host or not port:
        raise CaraError(f"bad scheduler address {address!r} (expected tcp://HOST:PORT)")
    try:
        socket.create_connection((host, port), timeout=5).close()
    except OSError as e:
        raise CaraError(f"cannot connect to the Dask scheduler {address}: {e.strerror or e}") from None
