"""Write a sample take with its ground truth (``carapost sample``).

The four channels are rendered and encoded in parallel, one worker process
per camera (each streams its frames straight into ``write_pico``); the truth
files are written once every channel is done.  The output is a function of the
parameters and the seed only (the pico headers carry a wall-clock time stamp).
"""
from __future__ import annotations

import json
import logging
import os
import time
from pathlib import Path

import numpy as np

from carapost.core.errors import CaraError

from .face import EXPRESSIONS
from .markers import SURF_FACE
from .rig import BRIM_MARKERS, BRIM_RADIUS, CHANNEL_NAMES, brim_svg
from .scene import Scene, build_scene, calibration_cameras, frame_geometry, rng_for, true_cameras

__all__ = ["write_sample", "render_channel", "choose_seeds", "seeds_of_take", "SAMPLE_FILES"]

log = logging.getLogger("carapost")

#: Files a sample take consists of, besides ``<take>_<channel>.pico``.
SAMPLE_FILES = ("calibration.xcp", "truth_cameras.xcp", "brim.svg", "labels.txt", "seeds.json", "truth.c3d",
                "truth.npz")
_HAND_SIGMA_PX = 0.5       # how far a careful click lands from a marker's centre
_SEED_CLEAR_PX = 14.0      # a seeded marker has no other marker this close at 1280 px (clicks snap within 6 px)

# Worker process state (set by _init_worker).
_W: dict = {}


def _truth_arrays(frames: int, points: int) -> dict:
    return {"uv": np.full((frames, points, 2), np.nan), "centre": np.full((frames, points, 2), np.nan),
            "visible": np.zeros((frames, points), bool),
            "drawn": np.zeros((frames, points), bool), "cos": np.zeros((frames, points)),
            "axes": np.zeros((frames, points, 2)), "points": np.zeros((frames, points, 3))}


def render_channel(scene: Scene, c: int, path=None, *, lossless: bool = True, metadata=None, tick=None) -> dict:
    """Render every frame of channel ``c``; encode it to ``path`` if given.

    Parameters
    ----------
    scene : Scene
    c : int
        Channel (camera) 0-3.
    path : path-like, optional
        ``.pico`` to write (else the images are only rendered, e.g. for timing).
    lossless : bool
        Pixel-exact H.264.
    metadata : dict, optional
        Extra pico metadata.
    tick : callable, optional
        Called with no argument after each frame.

    Returns
    -------
    dict
        The channel's truth: ``uv`` (F, P, 2), the image centres ``centre`` (F, P, 2), ``visible``, ``drawn``, ``cos`` (F, P), ``axes`` (F, P, 2),
        and the 3D marker centres ``points`` (F, P, 3) (the same in every channel).
    """
    from .render import leds_of, render_view

    P = len(scene.markers) + scene.n_brim
    out = _truth_arrays(scene.frames, P)

    def frames():
        for f in range(scene.frames):
            g = frame_geometry(scene, f)
            cams = true_cameras(scene, f)
            img, tr = render_view(scene, g, cams[c], c, f, leds=leds_of(cams))
            out["uv"][f], out["centre"][f], out["visible"][f], out["drawn"][f] = tr.uv, tr.centre, tr.visible, tr.drawn
            out["cos"][f], out["axes"][f] = tr.cos, tr.axes
            out["points"][f] = g.points
            if tick is not None:
                tick()
            yield img

    if path is None:
        for _ in frames():
            pass
    else:
        from carapost.io.pico import write_pico

        # ultrafast: lossless x264 of noisy images is ~6x faster than veryfast for
        # files ~2 % larger, and it is most of the take's time otherwise.
        write_pico(path, frames(), frame_rate=scene.rate, metadata=metadata, channel=c, gop=24,
                   lossless=lossless, preset="ultrafast")
    return out


def _init_worker(params: dict, queue) -> None:
    # The scene is rebuilt from its parameters (it is a function of them): cheaper
    # than sending megabytes through the start-up pipe of every worker.
    _W["scene"] = build_scene(**params)
    _W["queue"] = queue


def _worker(c: int, path: str, lossless: bool, metadata: dict) -> dict:
    q = _W["queue"]
    return render_channel(_W["scene"], c, path, lossless=lossless, metadata=metadata,
                          tick=(lambda: q.put(c)) if q is not None else None)


def _progress_fn(progress):
    """A ``fn(done, total)`` from a :class:`~carapost.core.progress.Progress` or a plain callable."""
    if progress is None:
        return lambda done, total: None
    if hasattr(progress, "step") and hasattr(progress, "start"):
        state = {"started": False, "done": 0}

        def fn(done, total):
            if not state["started"]:
                progress.start(total, "Rendering the sample take")
                state["started"] = True
            if done > state["done"]:
                progress.step(done - state["done"])
                state["done"] = done
        return fn

    def call(done, total):
        try:
            progress(done, total, "Rendering the sample take")
        except TypeError:
            progress(done, total)
    return call


def _render_all(scene: Scene, paths: list[Path], lossless: bool, metadata: list[dict], workers: int,
                report, meanwhile) -> list[dict]:
    """Render the four channels; ``meanwhile()`` runs while the workers render (first, without workers)."""
    total = 4 * scene.frames
    report(0, total)
    if workers <= 1:
        meanwhile()
        count = [0]

        def tick():
            count[0] += 1
            report(count[0], total)
        return [render_channel(scene, c, paths[c], lossless=lossless, metadata=metadata[c], tick=tick)
                for c in range(4)]
    from concurrent.futures.process import BrokenProcessPool

    ran = []

    def once():
        if not ran:
            ran.append(True)
            meanwhile()
    try:
        return _render_pool(scene, paths, lossless, metadata, workers, report, once)
    except BrokenProcessPool:
        # A worker died before rendering: typically a script calling write_sample
        # at import time without an ``if __name__ == "__main__"`` guard, which
        # spawned workers re-run.  Render here instead.
        log.warning("sample take: worker processes failed to start; rendering in this process")
        return _render_all(scene, paths, lossless, metadata, 1, report, once)


def _render_pool(scene: Scene, paths: list[Path], lossless: bool, metadata: list[dict], workers: int,
                 report, meanwhile) -> list[dict]:
    import multiprocessing as mp
    import queue as queue_mod
    from concurrent.futures import ProcessPoolExecutor, wait

    total = 4 * scene.frames

    # spawn, not fork: the caller may be a GUI with threads of its own.
    ctx = mp.get_context("spawn")
    q = ctx.Queue()
    done = 0
    params = dict(markers=len(scene.markers), frames=scene.frames, seed=scene.seed, white=scene.white,
                  width=scene.width, height=scene.height, rate=scene.rate, noise=scene.noise, blur=scene.blur,
                  motion_seed=scene.motion_seed, rig_move=scene.rig_move, camera_move=scene.camera_move,
                  perspective_dots=scene.perspective_dots)
    with ProcessPoolExecutor(max_workers=workers, mp_context=ctx, initializer=_init_worker,
                             initargs=(params, q)) as ex:
        futs = [ex.submit(_worker, c, str(paths[c]), lossless, metadata[c]) for c in range(4)]
        try:
            meanwhile()
            while True:
                finished, pending = wait(futs, timeout=0.2)
                while True:
                    try:
                        q.get_nowait()
                    except queue_mod.Empty:
                        break
                    done += 1
                report(min(done, total), total)
                if not pending:
                    break
            return [f.result() for f in futs]
        except BaseException:
            for f in futs:
                f.cancel()
            raise


def _farthest(points: np.ndarray, n: int, first: int = 0) -> list[int]:
    """Indices of ``n`` points spread out by farthest-point sampling, starting at ``first``."""
    chosen = [first]
    d = np.linalg.norm(points - points[first], axis=1)
    while len(chosen) < min(n, len(points)):
        i = int(np.argmax(d))
        if d[i] <= 0:
            break
        chosen.append(i)
        d = np.minimum(d, np.linalg.norm(points - points[i], axis=1))
    return chosen


def choose_seeds(scene: Scene, truth: dict, frame: int = 0, n_brim: int = 6, n_face: int = 8) -> dict:
    """The clicks a person makes on ``frame`` (CONTRACT section 3), with hand error.

    Brim entries: ``n_brim`` brim markers spread along the brim, each clicked in
    every channel that sees it.  Face entries: ``n_face`` labelled markers on
    plain skin spread over the face, each seen (and clicked) in at least two
    channels, including both channels of one caddy (fewer than ``n_face`` only
    when the face has fewer such markers).  Only markers with no other marker
    within ``_SEED_CLEAR_PX`` of them in a clicked channel are chosen, so that
    the nearest detection to each click is the marker.  Each click is the true
    centre plus Gaussian error of ``_HAND_SIGMA_PX`` (at most 3 sigma).
    """
    vis = truth["visible"][frame]            # (4, P)
    uv = truth["uv"][frame]                  # (4, P, 2)
    drawn = truth["drawn"][frame]
    nf = len(scene.markers)
    rng = rng_for(scene.seed, 6)

    clear_px = max(8.0, _SEED_CLEAR_PX * scene.width / 1280.0)

    def clear(c, i):
        others = np.flatnonzero(drawn[c])
        others = others[others != i]
        if others.size == 0:
            return True
        return float(np.min(np.linalg.norm(uv[c, others] - uv[c, i], axis=1))) >= clear_px

    def click(c, i):
        e = rng.normal(0.0, _HAND_SIGMA_PX, 2)
        e *= min(1.0, 3 * _HAND_SIGMA_PX / max(np.linalg.norm(e), 1e-12))
        return [round(float(uv[c, i, 0] + e[0]), 3), round(float(uv[c, i, 1] + e[1]), 3)]

    g = frame_geometry(scene, frame)
    # Brim: markers every channel sees, spread along the brim.
    ok = [b for b in range(scene.n_brim) if all(vis[c, nf + b] and clear(c, nf + b) for c in range(4))]
    if len(ok) < n_brim:
        ok = [b for b in range(scene.n_brim) if sum(vis[c, nf + b] and clear(c, nf + b) for c in range(4)) >= 2]
    pick = [ok[i] for i in _farthest(BRIM_MARKERS[ok], n_brim, int(np.argmin(BRIM_MARKERS[ok, 0])))]
    brim = [{"index": int(b), "uv": {str(c): click(c, nf + b) for c in range(4)
                                     if vis[c, nf + b] and clear(c, nf + b)}} for b in sorted(pick)]
    # Face: labelled markers on plain, well-lit skin (not on a brow, a lid, a lip or
    # a nostril rim, where a dot is harder to find), facing the cameras that click
    # them, and seen by both channels of a caddy.
    hard = ("Brow", "Eyelid", "Lip", "Mouth", "Nostril", "Temple")
    if scene.white:
        # A white nose tip is lit to saturation and merges with the nose's highlight: no blob to click
        # (a 100-marker white take's seeds had none within 6 px, and `carapost process` stopped there).
        hard += ("Nose_Tip",)
    easy, rest = [], []
    for i in range(nf):
        u, v = scene.markers.p[i]
        if scene.markers.surface[i] != SURF_FACE:
            continue
        chans = [c for c in range(4) if vis[c, i] and clear(c, i) and truth["cos"][frame, c, i] > 0.5]
        if not ((0 in chans and 1 in chans) or (2 in chans and 3 in chans)):
            continue
        plain = (not scene.markers.labels[i].startswith(hard)
                 and (u / 75.0) ** 2 + ((v + 3.0) / 103.0) ** 2 <= 0.8 ** 2)
        (easy if plain else rest).append((i, chans))
    # A face with very few markers may not have n_face plain ones: take what there is.
    cand = easy if len(easy) >= n_face else easy + rest
    face = []
    if cand:
        pts = g.points[[i for i, _ in cand]]
        # From the nose tip where it is plain (``easy`` comes first in ``cand``): never from a hard one.
        start = next((k for k, (i, _) in enumerate(easy) if scene.markers.labels[i] == "Nose_Tip"), 0)
        for k in _farthest(pts, n_face, start):
            i, chans = cand[k]
            face.append({"label": scene.markers.labels[i], "uv": {str(c): click(c, i) for c in chans}})
    return {"frame": int(frame), "brim": brim, "face": face}


def _refuse_in_worker_start() -> None:
    """Stop at once inside a worker process that is still importing the caller's script.

    A script that calls :func:`write_sample` without an ``if __name__ ==
    "__main__"`` guard is re-run by every spawned worker; failing fast there
    lets the parent see its workers die and render in its own process.
    """
    import multiprocessing as mp

    if getattr(mp.current_process(), "_inheriting", False):
        raise RuntimeError("write_sample() was called while a worker process was starting: "
                           "put the calling script's code under  if __name__ == '__main__':")


def _seeds_json(seeds: dict) -> str:
    """``seeds.json`` text: one entry per line (readable, and diffs well)."""
    lines = [f'{{"frame": {seeds["frame"]},']
    for key in ("brim", "face"):
        entries = [json.dumps(e, separators=(", ", ": ")) for e in seeds[key]]
        body = ",\n  ".join(entries)
        end = "]," if key == "brim" else "]}"
        lines.append(f' "{key}": [\n  {body}\n {end}')
    return "\n".join(lines) + "\n"


def _write_text(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def write_sample(out_dir, *, markers: int = 100, frames: int = 120, seed: int = 0, white: bool = False,
                 width: int = 1280, height: int = 720, take: str = "Sample", lossless: bool = True,
                 progress=None, workers: int | None = None, noise: float = 2.0, blur: float = 0.8,
                 motion_seed: int | None = None, rig_move=(0.0, 0.0), camera_move=None,
                 seeds_frame: int = 0, perspective_dots: bool = True) -> dict:
    """Render a synthetic four-camera take with its ground truth into ``out_dir``.

    Parameters
    ----------
    out_dir : path-like
        Created if missing.
    markers : int
        Painted face markers (35-160 intended).
    frames : int
    seed : int
        Everything (face layout, rig, motion, texture, noise) follows from it.
    white : bool
        White markers on a black brim instead of black markers on a white brim.
    width, height : int
        Image size (even).
    take : str
        Take name: the channels are ``<take>_0.pico`` ... ``<take>_3.pico``.
    lossless : bool
        Pixel-exact H.264 (else rate-controlled).
    progress : Progress or callable, optional
        A :class:`~carapost.core.progress.Progress`, or ``fn(done, total[, message])``;
        counts rendered images (4 per frame).
    workers : int, optional
        Worker processes (default: one per CPU, at most 4); 1 renders in this process.
    noise, blur : float
        Sensor noise (grey levels) and optical blur (px).
    motion_seed : int, optional
        Another take of the same face, markers, rig and brim (a ROM workflow's second take): the
        motion comes from this seed instead of ``seed``.
    rig_move : (float, float)
        ``(mm, degrees)``: the helmet put on again, cameras and brim shifted and turned together
        relative to the face.
    camera_move : (int, float, float), optional
        ``(channel, mm, degrees)``: one camera moved relative to the rest of the rig and the brim
        (``calibration.xcp`` and ``truth_cameras.xcp`` show it where it is).
    seeds_frame : int
        The frame ``seeds.json``'s clicks are made on (negative: from the end, -1 the last
        frame), for starting Initialize 3D and tracking elsewhere than on frame 0.
    perspective_dots : bool
        Dots drawn under perspective, their images' centres off their centres' projections
        (:func:`.scene.build_scene`); False (``--linear-dots``) draws them as before session 24.

    Returns
    -------
    dict
        Paths of every file written (``pico`` is a list), and figures: ``frames``,
        ``markers``, ``brim_markers``, ``seconds``, ``visible_fraction`` (face
        markers visible per image, averaged), ``seed``.

    Raises
    ------
    CaraError
        If ``out_dir`` cannot be written or the parameters are unusable.
    """
    _refuse_in_worker_start()
    t0 = time.perf_counter()
    out = Path(out_dir)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CaraError(f"cannot create the output folder: {e.strerror or e}", out) from None
    if not 1 <= int(markers) <= 400:
        raise CaraError(f"--markers must be between 1 and 400, not {markers}")
    if int(frames) < 1:
        raise CaraError(f"--frames must be at least 1, not {frames}")
    seeds_frame = _frame_index(seeds_frame, int(frames))
    try:
        scene = build_scene(markers=markers, frames=frames, seed=seed, white=white, width=width, height=height,
                            noise=noise, blur=blur, motion_seed=motion_seed, rig_move=rig_move,
                            camera_move=camera_move, perspective_dots=perspective_dots)
    except ValueError as e:
        raise CaraError(str(e)) from None
    if workers is None:
        workers = min(4, os.cpu_count() or 1)
    paths = [out / f"{take}_{c}.pico" for c in range(4)]
    # The blob keys tell an importer which marker colour to look for (io.take.PICO_BLOB_KEYS).
    meta = [{"carapost.sample.seed": str(seed), "carapost.sample.markers": str(len(scene.markers)),
             "this_capture.camera_name": CHANNEL_NAMES[c],
             "this_capture.device_id": scene.rig.intrinsics[c]["device_id"],
             "blob.find_black_blobs": "false" if white else "true",
             "blob.find_white_blobs": "true" if white else "false"}
            for c in range(4)]
    files = {"dir": str(out)}
    chans = _render_all(scene, paths, lossless, meta, int(workers), _progress_fn(progress),
                        lambda: files.update(_write_scene_files(scene, out)))
    points = chans[0].pop("points")
    for ch in chans[1:]:
        ch.pop("points")
    truth = {k: np.stack([ch[k] for ch in chans], axis=1) for k in chans[0]}     # (F, 4, P, ...)
    files.update(_write_truth(scene, truth, points, out, seeds_frame))
    files["pico"] = [str(p) for p in paths]
    nf = len(scene.markers)
    files.update(frames=scene.frames, markers=nf, brim_markers=scene.n_brim, seed=int(seed),
                 visible_fraction=float(truth["visible"][:, :, :nf].mean()),
                 seconds=round(time.perf_counter() - t0, 3))
    return files


def _write_scene_files(scene: Scene, out: Path) -> dict:
    """The files that need no rendering: cameras, brim, labels."""
    from carapost.io.xcp import write_xcp, xcp_from_cameras

    F = scene.frames
    files = {}
    cams = [true_cameras(scene, f) for f in range(F)]
    p = out / "truth_cameras.xcp"
    write_xcp(p, xcp_from_cameras([[(f, cams[f][c]) for f in range(F)] for c in range(4)],
                                  name="carapost sample: true cameras"))
    files["truth_cameras"] = str(p)
    p = out / "calibration.xcp"
    write_xcp(p, xcp_from_cameras([[(0, cam)] for cam in calibration_cameras(scene)], name="carapost sample"))
    files["calibration"] = str(p)
    p = out / "brim.svg"
    _write_text(p, brim_svg())
    files["brim_svg"] = str(p)
    p = out / "labels.txt"
    _write_text(p, "\n".join(scene.markers.labels) + "\n")
    files["labels"] = str(p)
    return files


def _write_truth(scene: Scene, truth: dict, points: np.ndarray, out: Path, seeds_frame: int = 0) -> dict:
    """The files made from the rendering's truth: seeds (clicked on ``seeds_frame``), C3D, npz."""
    F, nf, nb = scene.frames, len(scene.markers), scene.n_brim
    labels = list(scene.markers.labels)
    brim_labels = [f"Brim_{i}" for i in range(nb)]
    files = {}
    p = out / "seeds.json"
    seeds = choose_seeds(scene, truth, frame=seeds_frame)
    _write_text(p, _seeds_json(seeds))
    files["seeds"] = str(p)
    # 3D truth, world (brim) frame, mm.
    face_xyz = points[:, :nf]
    brim_xyz = np.column_stack([BRIM_MARKERS, np.zeros(nb)])
    pos = np.concatenate([face_xyz, np.broadcast_to(brim_xyz, (F, nb, 3))], axis=1)
    masks = np.zeros((F, nf + nb), np.uint8)
    for c in range(4):
        masks |= (truth["visible"][:, c].astype(np.uint8) << c)
    p = out / "truth.c3d"
    _write_c3d(p, pos, labels + brim_labels, scene.rate, masks)
    files["truth_c3d"] = str(p)
    p = out / "truth.npz"
    cams = [true_cameras(scene, f) for f in range(F)]
    R = np.array([[c.rotation for c in cs] for cs in cams])
    t = np.array([[c.position for c in cs] for cs in cams])
    tmp = out / f".truth.{os.getpid()}.npz"
    np.savez_compressed(
        tmp, labels=np.array(labels), brim_labels=np.array(brim_labels), face_xyz=face_xyz, brim_xyz=brim_xyz,
        uv=truth["uv"], centre=truth["centre"], visible=truth["visible"], drawn=truth["drawn"], cos=truth["cos"],
        axes=truth["axes"],
        radius=np.concatenate([scene.markers.radius, np.full(nb, BRIM_RADIUS)]), surface=scene.markers.surface,
        param=scene.markers.p, weights=scene.motion.weights, expressions=np.array(EXPRESSIONS),
        gaze=scene.motion.gaze, head_R=scene.motion.head_R, head_t=scene.motion.head_t,
        cam_R=R, cam_t=t, calib_dR=scene.calib_dR, calib_dt=scene.calib_dt,
        rate=scene.rate, seed=scene.seed, white=scene.white, size=np.array([scene.width, scene.height]),
        **_second_take_keys(scene))
    os.replace(tmp, p)
    files["truth_npz"] = str(p)
    return files


def _frame_index(frame: int, frames: int) -> int:
    """``frame`` of a take of ``frames`` frames (negative: from the end); CaraError outside it."""
    f = int(frame) + (int(frames) if int(frame) < 0 else 0)
    if not 0 <= f < frames:
        raise CaraError(f"--seeds-frame {frame} is outside the take's {frames} frames")
    return f


def seeds_of_take(folder, frame: int) -> dict:
    """The ``seeds.json`` clicks of an already written sample take, made on another ``frame``.

    The scene is drawn again from the parameters ``truth.npz`` keeps (drawing it is
    cheap; only rendering is not), so a take rendered once can be initialised on any
    frame, e.g. its last one for Track Backwards.  The same as writing the take with
    ``seeds_frame=frame``.

    Parameters
    ----------
    folder : path-like
        A folder :func:`write_sample` wrote.
    frame : int
        Negative: from the end (-1 the last frame).

    Returns
    -------
    dict
        As ``seeds.json`` (CONTRACT section 3).

    Raises
    ------
    CaraError
        If the folder has no readable ``truth.npz`` or ``frame`` is outside the take.
    """
    path = Path(folder) / "truth.npz"
    try:
        t = dict(np.load(path))
    except (OSError, ValueError) as e:
        raise CaraError(f"cannot read the sample's truth: {e}", path) from None
    frames = int(t["face_xyz"].shape[0])
    size = [int(v) for v in t["size"]]
    scene = build_scene(markers=len(t["labels"]), frames=frames, seed=int(t["seed"]), white=bool(t["white"]),
                        width=size[0], height=size[1],
                        motion_seed=int(t["motion_seed"]) if "motion_seed" in t else None,
                        rig_move=tuple(t["rig_move"]) if "rig_move" in t else (0.0, 0.0),
                        camera_move=tuple(t["camera_move"]) if "camera_move" in t else None,
                        perspective_dots=bool(t["perspective_dots"]) if "perspective_dots" in t else True)
    return choose_seeds(scene, t, frame=_frame_index(frame, frames))


def _second_take_keys(scene: Scene) -> dict:
    """truth.npz entries of a second take's options and of perspective dots (none for a default take of the
    seed's own: files stay as they were)."""
    out = {}
    if scene.motion_seed is not None:
        out["motion_seed"] = scene.motion_seed
    if any(scene.rig_move):
        out["rig_move"] = np.array(scene.rig_move)
    if scene.camera_move is not None:
        out["camera_move"] = np.array(scene.camera_move)
    if not scene.perspective_dots:
        out["perspective_dots"] = np.array(False)
    return out


def _write_c3d(path: Path, pos: np.ndarray, labels: list[str], rate: float, masks: np.ndarray) -> None:
    """True markers as C3D: every sample present (residual 0), camera mask = channels that see it."""
    from carapost.io.c3d import write_c3d

    nb = len(BRIM_MARKERS)
    write_c3d(path, pos, labels, rate, residuals=np.zeros(pos.shape[:2]), camera_masks=masks,
              descriptions=["face marker"] * (len(labels) - nb) + ["brim marker"] * nb)
