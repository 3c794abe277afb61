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
import time
from pathlib import Path

from controlmm.atomic import atomic_dir, write_text
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


def write_plan(
    result: PlanResult,
    out: str | Path,
    *,
    render: bool | None = None,
    progress: bool = True,
    force: bool = False,
) -> str | None:
    """Write every output of ``result`` into the directory ``out`` (replaced atomically).

    ``out`` may be new, empty or a previous plan output; anything else needs ``force``
    (:func:`controlmm.atomic.check_output_dir`).

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
        if config.plots:
            plots = tmp / "plots"
            plots.mkdir()
            plot_top_view(result, plots / "top_view.png")
            plot_clearance(result, plots / "clearance.png")
            title = f"{result.scene.name}: {result.text[:80]}"
            plot_report(result.report, plots / "report.png", title=title)
            plot_motion(result.motion, plots / "motion.png")
            if result.clip is not None:
                plot_displacement(
                    result.displacements(), result.best, str(plots / "displacement.png"), result.reconstructed
                )
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
