"""The plan of a batch: the pipeline file, the takes named on the command line, one job per take.

:func:`load_pipeline` validates a pipeline file (``docs/batch.md``),
:func:`find_takes` turns TAKE arguments (``.pico`` files, ``.cara`` projects,
folders, wildcards) into takes, :func:`plan_batch` makes one self-contained
:class:`Job` per take with every path resolved, and :func:`is_up_to_date`
decides whether a take can be skipped.  :mod:`carapost.api.batch` runs the jobs.
"""
from __future__ import annotations

import glob
import hashlib
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

from ..core.errors import CaraError, read_bytes

__all__ = ["Pipeline", "Take", "Job", "load_pipeline", "parse_pipeline", "find_takes", "plan_batch",
           "is_up_to_date", "STEP_NAMES", "OUTPUT_KINDS", "MANIFEST_SUFFIX"]

#: Steps a pipeline may list, in the order a typical pipeline uses them.
STEP_NAMES = ("set", "import_xcp", "import_labels", "set_brim", "detect_blobs", "initialize",
              "initialize_from_rom", "bundle_sequence", "track", "interpolate_gaps")
#: Files a pipeline may write per take.
OUTPUT_KINDS = ("cara", "c3d", "fbx", "xcp")
#: Steps whose argument is a file the take reads (an input of the take for the resume test).
_PATH_STEPS = {"import_xcp": "path", "import_labels": "path", "set_brim": "brim", "initialize": "seeds",
               "initialize_from_rom": "rom"}
_STEP_OPTIONS = {
    "set": set(), "import_xcp": {"path"}, "import_labels": {"path"}, "set_brim": {"brim"},
    "detect_blobs": {"start", "end", "sensors"}, "initialize": {"seeds"},
    "initialize_from_rom": {"rom", "frame", "brim_only"}, "bundle_sequence": {"start", "end"},
    "track": {"frame", "direction"}, "interpolate_gaps": set(),
}
_DEFAULT_BRIMS = ("v2.0", "v1.1", "v1.0")
MANIFEST_SUFFIX = ".batch.json"


# --------------------------------------------------------------------------- pipeline file
@dataclass
class Pipeline:
    """A validated pipeline file.

    Attributes
    ----------
    path : Path or None
        The file (relative paths inside it may resolve against its folder).
    steps : list of dict
        ``{"step": NAME, ...options}`` in order.
    properties : dict
        ``group.name -> value`` set before the first step.
    outputs : dict
        Output kind (``cara``, ``c3d``, ``fbx``, ``xcp``) -> file name template.
    output_dir : str or None
        Folder for every take's outputs (default: each take's own folder).
    """

    path: Path | None
    steps: list[dict]
    properties: dict[str, Any]
    outputs: dict[str, str]
    output_dir: str | None = None


def load_pipeline(path: str | Path) -> Pipeline:
    """Read and validate a pipeline file; :class:`CaraError` names the file and the problem."""
    path = Path(path)
    try:
        data = json.loads(read_bytes(path))
    except json.JSONDecodeError as e:
        raise CaraError(f"not valid JSON: {e}", path) from None
    return parse_pipeline(data, path)


def parse_pipeline(data: Any, path: str | Path | None = None) -> Pipeline:
    """Validate a pipeline's dict (the JSON of a pipeline file).

    Parameters
    ----------
    data : dict
        ``{"set": {...}, "steps": [...], "outputs": {...}, "output_dir": ...}``.
    path : path-like, optional
        The file it came from: named in errors, and the base of relative paths.

    Raises
    ------
    CaraError
        On an unknown key, step, option, property or output kind.
    """
    from ..core.properties import Properties

    where = None if path is None else Path(path)

    def bad(msg: str):
        return CaraError(msg, where)

    if not isinstance(data, dict):
        raise bad("a pipeline is a JSON object with \"steps\" and \"outputs\"")
    unknown = set(data) - {"set", "steps", "outputs", "output_dir", "comment"}
    if unknown:
        raise bad(f"unknown key {sorted(unknown)[0]!r} (keys: set, steps, outputs, output_dir)")
    props = _check_properties(data.get("set", {}), "set", bad, Properties())
    raw_steps = data.get("steps")
    if not isinstance(raw_steps, list) or not raw_steps:
        raise bad("\"steps\" must be a non-empty list, e.g. [\"detect_blobs\"]")
    steps = [_parse_step(s, i, bad) for i, s in enumerate(raw_steps)]
    for s in steps:
        if s["step"] == "set":
            s["values"] = _check_properties(s["values"], f"steps[{s['index']}].set", bad, Properties())
    outputs = data.get("outputs", {"cara": "{take}.cara"})
    if not isinstance(outputs, dict) or not outputs:
        raise bad("\"outputs\" must be an object such as {\"cara\": \"{take}.cara\", \"c3d\": \"{take}.c3d\"}")
    for kind, name in outputs.items():
        if kind not in OUTPUT_KINDS:
            raise bad(f"outputs: unknown kind {kind!r} (choose {', '.join(OUTPUT_KINDS)})")
        if not isinstance(name, str) or not name.strip():
            raise bad(f"outputs.{kind} must be a file name such as \"{{take}}.{kind}\"")
        try:
            name.format(take="t", take_dir="d", pipeline_dir="p")
        except (KeyError, IndexError, ValueError) as e:
            raise bad(f"outputs.{kind}: bad placeholder in {name!r} ({e}); use {{take}}") from None
    out_dir = data.get("output_dir")
    if out_dir is not None and not isinstance(out_dir, str):
        raise bad("\"output_dir\" must be a folder name")
    return Pipeline(where, steps, props, dict(outputs), out_dir)


def _check_properties(values, what: str, bad, props) -> dict:
    if not isinstance(values, dict):
        raise bad(f"{what} must be an object of \"group.property\": value")
    out = {}
    for k, v in values.items():
        try:
            props.set(k, v)
        except (CaraError, KeyError, ValueError, TypeError) as e:
            raise bad(f"{what}: {k}: {e}") from None
        out[k] = props[k]
    return out


def _parse_step(raw, i: int, bad) -> dict:
    """``"track"`` or ``{"track": {...}}`` or ``{"import_xcp": "file.xcp"}`` -> ``{"step": ..., options}``."""
    if isinstance(raw, str):
        name, arg = raw, None
    elif isinstance(raw, dict) and len(raw) == 1:
        (name, arg), = raw.items()
    else:
        raise bad(f"steps[{i}] must be a step name or an object with one key, e.g. {{\"import_xcp\": \"cal.xcp\"}}")
    if name not in _STEP_OPTIONS:
        raise bad(f"steps[{i}]: unknown step {name!r} (steps: {', '.join(STEP_NAMES)})")
    step: dict = {"step": name, "index": i}
    if name == "set":
        step["values"] = arg if arg is not None else {}
        return step
    if isinstance(arg, str) and name in _PATH_STEPS:
        arg = {_PATH_STEPS[name]: arg}
    if arg is None:
        arg = {}
    if not isinstance(arg, dict):
        raise bad(f"steps[{i}] ({name}): expected an object of options, not {arg!r}")
    unknown = set(arg) - _STEP_OPTIONS[name]
    if unknown:
        allowed = ", ".join(sorted(_STEP_OPTIONS[name])) or "none"
        raise bad(f"steps[{i}] ({name}): unknown option {sorted(unknown)[0]!r} (options: {allowed})")
    need = _PATH_STEPS.get(name)
    if need and not isinstance(arg.get(need), str):
        raise bad(f"steps[{i}] ({name}) needs a file: {{\"{name}\": \"FILE\"}}")
    for key in ("start", "end", "frame"):
        if key in arg and not (isinstance(arg[key], int) and not isinstance(arg[key], bool)):
            raise bad(f"steps[{i}] ({name}): {key} must be a whole frame number")
    if "sensors" in arg and not (isinstance(arg["sensors"], list)
                                 and all(isinstance(x, int) for x in arg["sensors"])):
        raise bad(f"steps[{i}] ({name}): sensors must be a list of sensor numbers")
    if name == "track" and arg.get("direction", "both") not in ("forwards", "backwards", "both"):
        raise bad(f"steps[{i}] (track): direction must be forwards, backwards or both")
    if "brim_only" in arg and not isinstance(arg["brim_only"], bool):
        raise bad(f"steps[{i}] ({name}): brim_only must be true or false")
    step.update(arg)
    return step


# --------------------------------------------------------------------------- takes
@dataclass(frozen=True)
class Take:
    """One take: its name, folder and the files it is read from (every channel's ``.pico``, or one ``.cara``)."""

    name: str
    folder: Path
    files: tuple[Path, ...]

    @property
    def input(self) -> Path:
        """The file a project is created from (its whole take is loaded)."""
        return self.files[0]


def find_takes(args: Iterable[str | Path]) -> list[Take]:
    """The takes named by TAKE arguments: ``.pico`` files, ``.cara`` projects, folders or wildcards.

    A ``.pico`` stands for its whole take (``Example_2.pico`` -> ``Example_0..3.pico``);
    a folder stands for every take beneath it (recursively); a wildcard
    (``C:/Data/ROM*.pico``, quoted so the shell leaves it alone) for every
    take it matches.  Each take appears once, in the order first named.

    Raises
    ------
    CaraError
        When an argument names nothing that exists, or a folder or wildcard holds no take.
    """
    from ..io.media import take_files
    from ..io.pico import take_and_channel

    found: dict[tuple[Path, str], Take] = {}

    def add_pico(p: Path) -> None:
        tc = take_and_channel(p)
        name = tc[0] if tc else p.stem
        key = (p.parent.resolve(), name)
        if key not in found:
            found[key] = Take(name, p.parent, tuple(take_files(p)))

    for arg in args:
        p = Path(arg)
        if p.is_dir():
            picos = sorted(q for q in p.rglob("*") if q.suffix.lower() == ".pico" and q.is_file())
            if not picos:
                raise CaraError("no .pico takes in this folder", p)
            for q in picos:
                add_pico(q)
        elif p.is_file():
            if p.suffix.lower() == ".cara":
                found.setdefault((p.parent.resolve(), p.stem + ".cara"), Take(p.stem, p.parent, (p,)))
            elif p.suffix.lower() == ".pico":
                add_pico(p)
            else:
                raise CaraError("not a take: give a .pico file, a .cara project, a folder or a wildcard", p)
        elif glob.has_magic(str(arg)):
            hits = sorted(Path(h) for h in glob.glob(str(arg), recursive=True))
            picos = [h for h in hits if h.suffix.lower() == ".pico" and h.is_file()]
            if not picos:
                raise CaraError(f"no .pico file matches {arg}")
            for q in picos:
                add_pico(q)
        else:
            raise CaraError("no such file or folder", p)
    return list(found.values())


# --------------------------------------------------------------------------- jobs
@dataclass
class Job:
    """Everything one take's run needs, as plain data (it is pickled to a worker process or a Dask worker).

    Attributes
    ----------
    take : str
        Take name.
    input : str
        The ``.pico`` (its whole take) or ``.cara`` the project is created from.
    inputs : list of str
        Every file the outputs depend on (the take's media and the files the steps read).
    steps : list of dict
        The pipeline's steps with every file resolved to an absolute path.
    properties : dict
        Properties set before the first step (the pipeline's ``set``, then ``--set``).
    outputs : dict
        Output kind -> absolute path.
    manifest : str
        This take's status file.
    fingerprint : str
        A hash of the steps, properties and outputs: a changed pipeline reruns the take.
    """

    take: str
    input: str
    inputs: list[str]
    steps: list[dict]
    properties: dict[str, Any]
    outputs: dict[str, str]
    manifest: str
    fingerprint: str

    def to_dict(self) -> dict:
        return dict(self.__dict__)


def plan_batch(takes: list[Take], pipeline: Pipeline, overrides: dict[str, Any] | None = None) -> list[Job]:
    """One :class:`Job` per take, with every path resolved.

    An input file named relatively in the pipeline is looked for in the take's
    folder first, then beside the pipeline file (so a per-take ``seeds.json``
    and a shared ``calibration.xcp`` can both be written as plain names);
    ``{take_dir}`` and ``{pipeline_dir}`` say which explicitly.  Output names
    are formatted with ``{take}`` and placed in ``output_dir`` (relative to
    the pipeline file) or else in the take's folder.

    Raises
    ------
    CaraError
        When a step's file exists in neither place, or two takes (or a take and
        its own input) would share an output file.
    """
    props = dict(pipeline.properties)
    props.update(overrides or {})
    base = pipeline.path.resolve().parent if pipeline.path is not None else Path.cwd()
    jobs: list[Job] = []
    owners: dict[Path, str] = {}
    for take in takes:
        folder = take.folder.resolve()
        fields = {"take": take.name, "take_dir": str(folder), "pipeline_dir": str(base)}
        steps, inputs = [], [str(f.resolve()) for f in take.files]
        for s in pipeline.steps:
            s = dict(s)
            key = _PATH_STEPS.get(s["step"])
            if key and not (s["step"] == "set_brim" and s[key] in _DEFAULT_BRIMS):
                s[key] = str(_resolve_input(s[key], fields, folder, base, pipeline.path, s["index"]))
                inputs.append(s[key])
            steps.append(s)
        out_dir = base / _format(pipeline.output_dir, fields) if pipeline.output_dir else folder
        outputs = {}
        for kind, name in pipeline.outputs.items():
            out = (out_dir / _format(name, fields)).resolve()
            if str(out) in inputs:
                raise CaraError(f"outputs.{kind}: {out} is an input of take {take.name!r}; "
                                f"write the results elsewhere", pipeline.path)
            if out in owners:
                raise CaraError(f"outputs.{kind}: {out} would be written by take {owners[out]!r} and take "
                                f"{take.name!r}; use output_dir or a name with {{take}}", pipeline.path)
            owners[out] = take.name
            outputs[kind] = str(out)
        first = Path(outputs.get("cara") or next(iter(outputs.values())))
        manifest = first.with_name(take.name + MANIFEST_SUFFIX)
        payload = json.dumps({"steps": steps, "set": props, "outputs": outputs}, sort_keys=True, default=str)
        jobs.append(Job(take.name, str(take.input.resolve()), inputs, steps, props, outputs, str(manifest),
                        hashlib.sha1(payload.encode()).hexdigest()[:16]))
    return jobs


def _format(template: str, fields: dict) -> str:
    return template.format(**fields)


def _resolve_input(name: str, fields: dict, take_dir: Path, base: Path, pipeline_path, index: int) -> Path:
    p = Path(_format(name, fields)).expanduser()
    candidates = [p] if p.is_absolute() else [take_dir / p, base / p]
    for c in candidates:
        if c.is_file():
            return c.resolve()
    where = " or ".join(str(c) for c in candidates)
    raise CaraError(f"steps[{index}]: no such file {where}", pipeline_path)


def is_up_to_date(job: Job | dict) -> bool:
    """Whether a take's outputs exist, are newer than its inputs, and its manifest records this pipeline's success."""
    j = job if isinstance(job, dict) else job.to_dict()
    try:
        manifest = json.loads(Path(j["manifest"]).read_text())
        oldest_out = min(Path(p).stat().st_mtime for p in j["outputs"].values())
        newest_in = max(Path(p).stat().st_mtime for p in j["inputs"])
    except (OSError, ValueError):
        return False
    return (manifest.get("status") == "ok" and manifest.get("fingerprint") == j["fingerprint"]
            and oldest_out >= newest_in)
