"""Headless pipeline steps (the CLI's ``carapost process`` and the scripting API use them)."""
from __future__ import annotations

from typing import Callable

from .brim import Brim
from .commands import Command
from .edits import SetBrim


def process_to_init3d(project, seeds: dict, brim: Brim | None = None, log: Callable[[str], None] = print,
                      stack=None) -> list[Command]:
    """Brim seeds, Solve Calibration Brim, face seeds, Bundle Current Frame, Initialize 3D.

    Parameters
    ----------
    project : Project
        With detections and cameras (an imported XCP).
    seeds : dict
        A seeds.json dict (CONTRACT section 3); its ``frame`` is the frame solved.
    brim : Brim, optional
        Set first when given (else the project's brim is used).
    log : callable
        Receives one line per step.
    stack : UndoStack, optional
        When given, each step is pushed on it; otherwise each step's command is
        applied with ``do`` (so later steps see earlier results).

    Returns
    -------
    list of Command
        The applied commands in order; undo them in reverse to restore the project.
    """
    from .calib.brim_solve import solve_calibration_brim
    from .calib.bundle import bundle_current_frame
    from .calib.init3d import initialize_3d
    from .calib.seeds import apply_seeds

    frame = int(seeds.get("frame", 0))
    done: list[Command] = []

    def run(cmd: Command):
        if stack is not None:
            stack.push(cmd)
        else:
            cmd.do(project)
        done.append(cmd)
        log(getattr(cmd, "summary", cmd.name))

    try:
        if brim is not None:
            run(SetBrim(brim))
        run(apply_seeds(project, seeds, parts=("brim",)))
        run(solve_calibration_brim(project, frame))
        run(apply_seeds(project, seeds, parts=("face",)))
        run(bundle_current_frame(project, frame)[0])
        run(initialize_3d(project, frame)[0])
    except BaseException:
        # A failed step leaves the project as it was before the pipeline.
        if stack is None:
            for c in reversed(done):
                c.undo(project)
        else:
            for _ in done:
                stack.undo()
        raise
    return done
