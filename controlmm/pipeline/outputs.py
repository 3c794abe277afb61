"""The files of a plan, written all at once: a complete directory or none.

``write_plan(result, "out/plan")`` builds the directory beside its destination and renames it into
place when every file is written (``controlmm.atomic.atomic_dir``), so an interrupted or failed run
never leaves a half-written ``out/plan``:

======================  =======================================================================
file                    content
======================  =======================================================================
motion.npz              the human motion (HumanML3D joints and features, 20 fps, Y up) with the
                        control targets and errors (``controlmm.motion.load_motion``)
robot.csv               one row per frame: root xyz, root quaternion xyzw, joint angles (rad)
                        (``PlanConfig.formats``: lafan1, the default; also robot_qpos.csv,
                        robot_beyondmimic.npz, robot.pkl: ``retarget.exports``)
robot.npz               qpos (wxyz), qvel, body poses, fps, joint names (``retarget`` format)
robot.json              the trajectory's sidecar: robot, scale, placement, CSV columns, metrics
report.json             the chosen round's simulation report (``passed``, penetrations, failures...)
                        plus ``plan`` (inputs, chosen round), ``rounds`` (every round's figures) and
                        ``timing`` (wall seconds per stage, :mod:`controlmm.pipeline.timing`)
render.mp4              the robot in the scene (MuJoCo; a matplotlib stick figure without OpenGL)
plots/top_view.png      obstacles, paths, control targets and achieved positions from above
plots/clearance.png     per-frame obstacle clearance and floor height of every round
plots/report.png        the per-frame simulation report of the chosen round
plots/motion.png        snapshots of the human motion
plots/displacement.png  (a recorded clip) per frame: mean and largest joint distance to the clip
source_motion.npz       (a recorded clip) the clip as imported (HumanML3D joints and features)
plan.json               the settings of the run (to reproduce it)
physics.npz             with the physics check (``CheckConfig(physics=True)``): the executed
                        states at every simulation step and the ctrl of every mj_step
physics_model.xml       the robot + scene + actuators the physics check simulated (one MJCF file)
robot_physics.csv       the executed motion at 50 fps (Unitree LAFAN1-G1 / BeyondMimic rows)
.controlmm-output.json  the files above: marks a plan output, which the next plan may replace
======================  =======================================================================

``plots/`` is left out with ``PlanConfig(plots=False)`` and ``render.mp4`` with ``render=False``.
Writing them is the ``outputs`` stage of ``result.timing`` (``report.json``'s ``timing``, written last).
"""

from __future__ import annotations

import json
import multiprocessing
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

from controlmm.atomic import atomic_dir, write_text
from controlmm.errors import ControlMMError
from controlmm.motion.io import save_motion
from controlmm.motion.plot import plot_motion
from controlmm.pipeline.clip import plot_displacement
from controlmm.pipeline.plan import PlanResult
from controlmm.pipeline.plots import plot_clearance, plot_top_view
from retarget.exports import save_trajectory
from retarget.render import render_trajectory
from sim import plot_report, save_certificate

PLAN_OUTPUT = "plan"
"""The output kind of a plan directory (:data:`controlmm.atomic.OUTPUT_MARKER`)."""


def plot_jobs(result: PlanResult, plots: Path) -> list[Callable[[], None]]:
    """The plots of ``plots/``, one call each (slowest first: the top view draws the scene)."""
    title = f"{result.scene.name}: {result.text[:80]}"
    jobs: list[Callable[[], None]] = [
        partial(plot_top_view, result, plots / "top_view.png"),
        partial(plot_report, result.report, plots / "report.png", title=title),
        partial(plot_clearance, result, plots / "clearance.png"),
        partial(plot_motion, result.motion, plots / "motion.png"),
    ]
    if result.clip is not None:
        jobs.append(
            partial(
                plot_displacement,
                result.displacements(),
                result.best,
                str(plots / "displacement.png"),
                result.reconstructed,
            )
        )
    return jobs


def can_fork() -> bool:
    """Whether :func:`draw_in_child` can fork this process (Linux; elsewhere fork is unsafe)."""
    return sys.platform == "linux" and "fork" in multiprocessing.get_all_start_methods()


def draw_in_child(jobs: list[Callable[[], None]]) -> Callable[[bool], None]:
    """Run ``jobs`` in a forked child (it shares what this process has loaded: nothing to import
    or pickle); returns ``wait(cancel)``: wait for it and raise its error as one line, or, with
    ``cancel`` (this process failed first), stop it."""
    context = multiprocessing.get_context("fork")
    receive, send = context.Pipe(duplex=False)

    def target() -> None:
        try:
            for job in jobs:
                job()
            send.send("")
        except BaseException as error:  # reported by the parent, one line, no traceback
            send.send(" ".join(f"{type(error).__name__}: {error}".split()))

    child = context.Process(target=target, daemon=True)
    child.start()
    send.close()

    def wait(cancel: bool = False) -> None:
        if cancel:
            child.terminate()
            child.join()
            receive.close()
            return
        try:
            message = receive.recv()
        except EOFError:  # died without a word (killed, out of memory)
            message = "the plotting process ended without writing its plots"
        child.join()
        receive.close()
        if message or child.exitcode != 0:
            raise ControlMMError(f"drawing the plots failed: {message or f'exit code {child.exitcode}'}")

    return wait


def write_plan(
    result: PlanResult,
    out: str | Path,
    *,
    render: bool | None = None,
    progress: bool = True,
    force: bool = False,
    parallel: bool = False,
) -> str | None:
    """Write every output of ``result`` into the directory ``out`` (replaced atomically).

    ``out`` may be new, empty or a previous plan output; anything else needs ``force``
    (:func:`controlmm.atomic.check_output_dir`).

    ``parallel``: without a video, draw half of the plots in a forked process beside the other
    half, on Linux; for a single-threaded caller such as the CLI (forking a process that runs
    other threads, a server's, may copy a lock another thread holds).

    Returns the render backend used (``"mujoco"`` or ``"stick"``), or None without a video.
    """
    config = result.config
    render = config.render if render is None else render
    backend = None
    started = time.perf_counter()
    with atomic_dir(out, kind=PLAN_OUTPUT, force=force, make_parents=True) as tmp:
        save_motion(result.motion, tmp / "motion.npz")
        save_trajectory(result.trajectory, tmp / "robot", config.formats)
        if result.clip is not None:
            save_motion(result.clip, tmp / "source_motion.npz")
        write_text(tmp / "plan.json", json.dumps(config.to_dict(), indent=1, default=str) + "\n")
        if result.report.physics is not None:
            save_certificate(result.report.physics, tmp)
        jobs = plot_jobs(result, tmp / "plots") if config.plots else []
        if jobs:
            (tmp / "plots").mkdir()
        # Both cores: without a video, a forked child draws half of the plots (see
        # :func:`draw_in_child`). Not beside the video: its encoder already runs in a second
        # process, and a fork beside the renderer's GL context is not safe.
        fork = parallel and not render and len(jobs) > 1 and can_fork()
        child = draw_in_child(jobs[1::2]) if fork else None
        try:
            for job in jobs[::2] if child is not None else jobs:
                job()
        except BaseException:
            if child is not None:
                child(True)
            raise
        if child is not None:
            child(False)
        if render:
            width, height = config.render_size
            backend = render_trajectory(
                result.trajectory,
                tmp / "render.mp4",
                width=width,
                height=height,
                fps=config.render_fps,
                progress=progress,
                scene=result.scene,
            )
        # last, so that its timing holds the outputs above
        result.timing.seconds["outputs"] = time.perf_counter() - started
        result.timing.stop()
        write_text(tmp / "report.json", json.dumps(result.to_dict(), indent=1, allow_nan=False) + "\n")
    return backend
