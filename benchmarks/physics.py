"""The physics execution check (``sim.track``): executability, discrimination and speed on G1.

    python benchmarks/physics.py                              # all three parts, 2 clips per family
    python benchmarks/physics.py --per-family 1 --parts speed,discrimination
    python benchmarks/physics.py --data data/corpus-1280 --json out/physics.json
    python benchmarks/physics.py --parts executability --samples 32 --config '{"retries": 0}'

(a) *Executability*: the first ``--per-family`` clips of every family of the corpus ``test``
split (default ``data/corpus-default``; docs/corpus.md) are retargeted to G1 at 50 fps and
checked in the ``empty`` scene; those that pass the kinematic and dynamic checks are executed
in physics. Per family: how many stayed up, how many also kept the mean root error within
10 cm (the target: >= 90 %), how many passed the physics verdict (no fall, no tracking-error
span), the mean root error.

(b) *Discrimination*: motions made infeasible on purpose from the first walk clips of the
split: the root lifted 0.4 m for 2 s without a jump (legs unchanged), the walk played 3x faster,
the whole robot (feet included) teleported 0.5 m sideways. Each must fail (target: 100 %).

(c) *Speed*: seconds of motion per second of wall time on a 6 s G1 walk (a corpus walk clip
cut or held to 6 s) for the physics check (``PhysicsConfig()`` defaults: 2 rollout threads; once
with an empty model cache, as the first run of G1 + floor on a machine, once with the saved model
cached: ``sim.physics.model_cache``), the
open-loop PD replay (``CheckConfig(tracking=True)``) and, when the optional ``peers`` extra is
installed (``pip install -e ".[peers]"``, or lighter: ``pip install --no-deps holosoma-inference``
plus ``pip install onnxruntime onnx``), holosoma's G1 whole-body tracking policy (ONNX) on its
own dance clip (``benchmarks/holosoma_peer.py``). Required >= 0.25x real time, goal 0.5x.

Wall time depends on what else runs on the machine: the load average is printed.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from collections import defaultdict
from multiprocessing import Pool
from pathlib import Path

import numpy as np
from data_dirs import ROOT, corpus_dir

sys.path.insert(0, str(ROOT))

from controlmm.errors import ControlMMError  # noqa: E402
from controlmm.motion import Motion  # noqa: E402
from controlmm.user_cache import CACHE_ENV  # noqa: E402
from retarget import retarget_motion  # noqa: E402
from scenes import load_scene  # noqa: E402
from sim import CheckConfig, PhysicsConfig, check_trajectory, make_world, track  # noqa: E402

FPS = 50.0
PARTS = ("executability", "discrimination", "speed")
SPEED_SECONDS = 6.0
ROOT_TARGET_M = 0.10

_WORLD: dict = {}


def _world():
    if "g1" not in _WORLD:
        _WORLD["g1"] = make_world(load_scene("empty", robot="g1"))
    return _WORLD["g1"]


def _clips(corpus: Path, per_family: int, families: list[str] | None, skip: int = 0) -> list[tuple[str, str]]:
    """(family, id) of ``per_family`` test clips of each family after its first ``skip``, in id order."""
    chosen: dict[str, list[str]] = defaultdict(list)
    for cid in sorted((corpus / "test.txt").read_text().split()):
        family = json.loads((corpus / "meta" / f"{cid}.json").read_text())["family"]
        if (not families or family in families) and len(chosen[family]) < skip + per_family:
            chosen[family].append(cid)
    return [(f, c) for f in sorted(chosen) for c in chosen[f][skip:]]


def _retarget(corpus: Path, cid: str) -> np.ndarray:
    joints = np.load(corpus / "new_joints" / f"{cid}.npy").astype(np.float32)
    return retarget_motion(Motion(joints=joints, fps=20.0), "g1", fps=FPS, metrics=False).qpos


def _physics(q: np.ndarray, threads: int, options: dict, world=None) -> dict:
    config = PhysicsConfig(threads=threads, **options)
    if world is None:
        world = _world()  # built once per process, outside the timing (``sim.track`` takes it as input)
    start = time.perf_counter()
    r = track(q, world, config, fps=FPS)
    s = r.stats
    return {
        "passed": r.passed,
        "fell": r.fell,
        "time_up_s": s["time_up_s"],
        "mean_root_error_m": s["mean_root_error_m"],
        "max_root_error_m": s["max_root_error_m"],
        "kinds": sorted({f.kind for f in r.failures}),
        "realtime_factor": s["realtime_factor"],
        "realtime_factor_cpu": s["realtime_factor_cpu"],
        "wall_s": time.perf_counter() - start,
        "seconds": (q.shape[0] - 1) / FPS,
        "simulated_s": s["simulated_s"],
        "retries": s["retries"],
    }


def _executability_job(job: tuple[str, str, str, int, dict]) -> dict:
    family, cid, corpus, threads, options = job
    q = _retarget(Path(corpus), cid)
    report = check_trajectory(_world(), q, FPS)
    out = {"family": family, "id": cid, "kinematic_passed": report.passed}
    if report.passed:
        out.update(_physics(q, threads, options))
    return out


def executability(
    corpus: Path, per_family: int, families, workers: int, options: dict, skip: int = 0
) -> list[dict]:
    threads = max(1, 2 // workers)
    clips = _clips(corpus, per_family, families, skip)
    jobs = [(f, c, str(corpus), threads, options) for f, c in clips]
    if workers > 1:
        with Pool(workers) as pool:
            rows = pool.map(_executability_job, jobs, chunksize=1)
    else:
        rows = [_executability_job(j) for j in jobs]
    by_family: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        by_family[r["family"]].append(r)
    print("\n(a) executability of kinematically passing test clips (G1, empty scene)")
    header = (
        "| family | clips | kin. pass | stayed up | up and root <= 10 cm | physics passed | root err cm "
        "| retries |"
    )
    print(header)
    print("|" + "|".join("-" * (len(c)) for c in header.split("|")[1:-1]) + "|")
    totals = np.zeros(6)
    for family in sorted(by_family):
        fam = by_family[family]
        run = [r for r in fam if r["kinematic_passed"]]
        up = [r for r in run if not r["fell"]]
        good = [r for r in up if r["mean_root_error_m"] <= ROOT_TARGET_M]
        ok = [r for r in run if r["passed"]]
        err = np.mean([r["mean_root_error_m"] for r in run]) * 100 if run else float("nan")
        retries = sum(r["retries"] for r in run)
        totals += (len(fam), len(run), len(up), len(good), len(ok), retries)
        print(
            f"| {family} | {len(fam)} | {len(run)} | {_pct(len(up), len(run))} | "
            f"{_pct(len(good), len(run))} | {_pct(len(ok), len(run))} | {err:.1f} | {retries} |"
        )
    n, k, u, g, p, tries = totals.astype(int)
    print(f"| **all** | {n} | {k} | {_pct(u, k)} | {_pct(g, k)} | {_pct(p, k)} | | {tries} |")
    return rows


def _pct(a: int, b: int) -> str:
    return f"{a}/{b} ({100.0 * a / b:.0f} %)" if b else "-"


def _infeasible(q: np.ndarray) -> dict[str, np.ndarray]:
    """The three infeasible versions of a walk (qpos at 50 fps)."""
    lifted = q.copy()
    t = np.arange(q.shape[0]) / FPS
    start = min(1.0, t[-1] / 4)
    ramp = np.clip((t - start) / 0.2, 0, 1) * np.clip((start + 2.0 - t) / 0.2, 0, 1)
    lifted[:, 2] += 0.4 * ramp  # floats up over 0.2 s, stays 2 s, comes down: no jump, legs unchanged
    fast = q[::3].copy()  # the same walk in a third of the time
    teleport = q.copy()
    teleport[q.shape[0] // 3 :, 1] += 0.5  # the whole robot, feet included, jumps 0.5 m sideways
    return {"root lifted 0.4 m for 2 s": lifted, "walk 3x faster": fast, "feet teleported 0.5 m": teleport}


def discrimination(corpus: Path, bases: int, options: dict) -> list[dict]:
    walks = [c for f, c in _clips(corpus, bases, ["walk"])]
    rows = []
    for cid in walks:
        base = _retarget(corpus, cid)
        for what, q in _infeasible(base).items():
            kin = check_trajectory(_world(), q, FPS)
            phys = _physics(q, 2, options)
            rows.append({"base": cid, "what": what, "kinematic_failed": not kin.passed, **phys})
    print("\n(b) discrimination: motions made infeasible on purpose must fail the physics check")
    print("| base clip | infeasible motion | physics verdict | failure kinds | fell at s | kinematic check |")
    print("|---|---|---|---|---|---|")
    for r in rows:
        fell = f"{r['time_up_s']:.2f}" if r["fell"] else "-"
        print(
            f"| {r['base']} | {r['what']} | {'FAILED' if not r['passed'] else 'passed'} | "
            f"{', '.join(r['kinds']) or '-'} | {fell} | {'failed' if r['kinematic_failed'] else 'passed'} |"
        )
    caught = sum(not r["passed"] for r in rows)
    print(f"caught: {_pct(caught, len(rows))}")
    return rows


def _six_seconds(corpus: Path) -> tuple[str, np.ndarray]:
    """A corpus walk cut (or its last frame held) to 6 s."""
    cid = _clips(corpus, 1, ["walk"])[0][1]
    q = _retarget(corpus, cid)
    n = int(SPEED_SECONDS * FPS) + 1
    if q.shape[0] < n:
        q = np.concatenate([q, np.repeat(q[-1:], n - q.shape[0], axis=0)])
    return cid, q[:n]


def speed(corpus: Path, options: dict) -> list[dict]:
    cid, q = _six_seconds(corpus)
    rows = []
    # Twice, each on a new world (built before the timing): first with an empty model cache (the
    # first run of this robot + scene on a machine saves its 12 MB MJCF), then with it cached.
    previous = os.environ.get(CACHE_ENV)
    with tempfile.TemporaryDirectory() as cache:
        os.environ[CACHE_ENV] = cache
        try:
            runs = [_physics(q, 2, options, make_world(load_scene("empty", robot="g1"))) for _ in range(2)]
        finally:
            if previous is None:
                os.environ.pop(CACHE_ENV, None)
            else:
                os.environ[CACHE_ENV] = previous
    if runs[0]["mean_root_error_m"] != runs[1]["mean_root_error_m"]:
        print("# warning: the cached model gave another run than the saved one", file=sys.stderr)
    for phys, when in zip(runs, ("first run of the model (cache empty)", "model cached"), strict=True):
        rows.append(
            {
                "method": f"physics check (predictive sampling, 2 threads), {when}",
                "clip": f"walk {cid}",
                "seconds": phys["simulated_s"],
                "time_up_s": phys["time_up_s"],
                "controller_rt": phys["realtime_factor"],
                "call_rt": phys["simulated_s"] / phys["wall_s"],
                "cpu_rt": phys["realtime_factor_cpu"],
                "stayed_up": not phys["fell"],
            }
        )
    report = check_trajectory(_world(), q, FPS, CheckConfig(dynamics=False, tracking=True))
    t, t_cpu = report.extra["timings_s"]["tracking_s"], report.extra["cpu_s"]["tracking_s"]
    tr = report.stats["tracking"]
    rows.append(
        {
            "method": "open-loop PD replay (CheckConfig(tracking=True))",
            "clip": f"walk {cid}",
            "seconds": SPEED_SECONDS,
            "time_up_s": tr["time_up_s"],
            "controller_rt": SPEED_SECONDS / t,
            "call_rt": SPEED_SECONDS / t,
            "cpu_rt": SPEED_SECONDS / t_cpu,
            "stayed_up": not tr["fell"],
        }
    )
    try:
        from holosoma_peer import run_dance_policy

        peer = run_dance_policy(SPEED_SECONDS)
    except ImportError as exc:  # the optional peer: only with the whole ``peers`` extra installed
        print(f"# holosoma peer skipped: {exc}", file=sys.stderr)
    else:
        rows.append(
            {
                "method": "holosoma G1 WBT policy (ONNX, PPO)",
                "clip": "its own dance clip",
                "seconds": peer["simulated_s"],
                "time_up_s": peer["time_up_s"],
                "controller_rt": peer["realtime_factor"],
                "call_rt": peer["realtime_factor"],
                "cpu_rt": peer["realtime_factor_cpu"],
                "stayed_up": not peer["fell"],
            }
        )
    print(f"\n(c) speed on {os.cpu_count()} CPU cores: seconds of motion per wall second (G1, 6 s clip)")
    print(
        "| method | clip | motion s simulated | x real time: control loop | whole call | "
        "per dedicated core-s (CPU) | up |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['method']} | {r['clip']} | {r['seconds']:.2f} | {r['controller_rt']:.2f} | "
            f"{r['call_rt']:.2f} | {r['cpu_rt']:.2f} | "
            f"{'yes' if r['stayed_up'] else 'fell at ' + format(r['time_up_s'], '.2f') + ' s'} |"
        )
    return rows


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--data", default=None, help="corpus directory (default data/corpus-default)")
    parser.add_argument("--per-family", type=int, default=2, help="test clips per family for (a) (default 2)")
    parser.add_argument("--families", default=None, help="comma-separated families for (a) (default: all)")
    parser.add_argument(
        "--skip",
        type=int,
        default=0,
        help="for (a), leave out the first N test clips of each family (default 0)",
    )
    parser.add_argument("--bases", type=int, default=2, help="walk clips made infeasible for (b) (default 2)")
    parser.add_argument(
        "--parts", default=",".join(PARTS), help=f"comma-separated parts (default {','.join(PARTS)})"
    )
    parser.add_argument(
        "--workers", type=int, default=1, help="processes for (a) (default 1: 2 rollout threads)"
    )
    parser.add_argument(
        "--samples", type=int, default=None, help="rollouts per planning step (default: PhysicsConfig)"
    )
    parser.add_argument(
        "--config",
        default="{}",
        help='other PhysicsConfig fields as JSON, e.g. \'{"retries": 0, "retry_lost": false}\'',
    )
    parser.add_argument("--json", default=None, help="also write every row to this JSON file")
    args = parser.parse_args()
    try:
        options = dict(json.loads(args.config))
    except (ValueError, TypeError) as exc:
        sys.exit(f"--config must be a JSON object of PhysicsConfig fields; got {args.config!r} ({exc})")
    if args.samples is not None:
        options["samples"] = args.samples
    try:
        PhysicsConfig(**options)
    except (ControlMMError, TypeError) as exc:
        sys.exit(f"bad PhysicsConfig options {options}: {exc}")
    parts = [p.strip() for p in args.parts.split(",") if p.strip()]
    unknown = sorted(set(parts) - set(PARTS))
    if unknown:
        sys.exit(f"unknown part(s) {', '.join(unknown)}; allowed: {', '.join(PARTS)}")
    corpus = corpus_dir(args.data)
    families = args.families.split(",") if args.families else None
    load = os.getloadavg()[0]
    start = time.perf_counter()
    print(
        f"machine: {platform.machine()}, {os.cpu_count()} CPU cores, Python {platform.python_version()}, "
        f"MuJoCo {__import__('mujoco').__version__}; load average at start {load:.1f}; corpus {corpus}"
    )
    out: dict = {}
    if "executability" in parts:
        out["executability"] = executability(
            corpus, args.per_family, families, args.workers, options, args.skip
        )
    if "discrimination" in parts:
        out["discrimination"] = discrimination(corpus, args.bases, options)
    if "speed" in parts:
        out["speed"] = speed(corpus, options)
    print(f"\ntotal {time.perf_counter() - start:.0f} s; load average now {os.getloadavg()[0]:.1f}")
    if args.json:
        Path(args.json).parent.mkdir(parents=True, exist_ok=True)
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
