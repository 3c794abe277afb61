"""Cold start: the wall time of whole ``controlmm`` commands, each a new process, side by side.

    python benchmarks/cold_start.py                          # this checkout
    python benchmarks/cold_start.py --baseline ../other      # and another checkout, in the same run

For each checkout (its packages first on ``PYTHONPATH``; the process runs in an empty folder, so
nothing else shadows them) it times, with one torch thread as ``controlmm plan`` uses by default:

* ``controlmm plan --help`` (median of ``--repeats``);
* the README example without the video, ``controlmm plan --no-render --out DIR`` (the ``table``
  scene, seed 0, plots written): once with an empty text-embedding cache (the first plan of a
  machine) and ``--repeats`` times with the cache the first run filled (every later plan; median).

Each checkout gets its own empty ``CONTROLMM_CACHE_DIR``. The plan's own verdict and, where the code
prints one, its ``timing:`` line (:mod:`controlmm.pipeline.timing`) are shown. Load average printed:
the wall time grows with it.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _run(code: Path, args: list[str], cwd: Path, cache: Path) -> tuple[float, int, str]:
    """Wall seconds, exit code and stdout of ``python -m controlmm ARGS`` with ``code`` first."""
    env = dict(os.environ, PYTHONPATH=str(code), CONTROLMM_CACHE_DIR=str(cache), HF_HUB_OFFLINE="1")
    started = time.perf_counter()
    done = subprocess.run(
        [sys.executable, "-m", "controlmm", *args], cwd=cwd, env=env, capture_output=True, text=True
    )
    seconds = time.perf_counter() - started
    if done.returncode not in (0, 1):  # 1: the plan ran and failed its checks
        raise SystemExit(f"controlmm {' '.join(args)} exited {done.returncode}: {done.stderr.strip()[-400:]}")
    return seconds, done.returncode, done.stdout


def _timing_line(stdout: str) -> str:
    return next((line for line in stdout.splitlines() if line.startswith("timing:")), "")


def measure(code: Path, repeats: int) -> dict:
    """The figures of one checkout (module docstring)."""
    with tempfile.TemporaryDirectory(prefix="controlmm-cold-") as tmp:
        work, cache = Path(tmp) / "work", Path(tmp) / "cache"
        work.mkdir()
        helps = [_run(code, ["plan", "--help"], work, cache)[0] for _ in range(repeats)]
        plan = ["plan", "--no-render", "--no-progress", "--force", "--out", str(work / "plan")]
        first, rc, out = _run(code, plan, work, cache)
        again = [_run(code, plan, work, cache) for _ in range(repeats)]
    return {
        "code": str(code),
        "help_s": statistics.median(helps),
        "plan_first_s": first,
        "plan_first_passed": rc == 0,
        "plan_s": statistics.median(s for s, _, _ in again),
        "plan_all_s": [round(s, 2) for s, _, _ in again],
        "plan_passed": all(r == 0 for _, r, _ in again),
        "timing_first": _timing_line(out),
        "timing": _timing_line(again[-1][2]),
    }


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--baseline", default=None, help="another checkout to time in the same run, first")
    parser.add_argument("--repeats", type=int, default=3, help="runs of --help and of the cached plan")
    args = parser.parse_args()
    codes = ([Path(args.baseline).resolve()] if args.baseline else []) + [ROOT]
    load = ", ".join(f"{x:.2f}" for x in os.getloadavg())
    print(f"cold start: {len(codes)} checkout(s), {args.repeats} repeats; load average {load}\n")
    rows = [measure(code, args.repeats) for code in codes]
    print(
        "| checkout | plan --help s | plan --no-render s, empty cache | plan --no-render s (median) "
        "| passed |"
    )
    print("|---|---|---|---|---|")
    for r in rows:
        print(
            f"| {r['code']} | {r['help_s']:.2f} | {r['plan_first_s']:.1f} | {r['plan_s']:.1f} "
            f"({', '.join(f'{s:.1f}' for s in r['plan_all_s'])}) | "
            f"{'yes' if r['plan_first_passed'] and r['plan_passed'] else 'no'} |"
        )
    for r in rows:
        for key in ("timing_first", "timing"):
            if r[key]:
                print(
                    f"{Path(r['code']).name} "
                    f"({'empty cache' if key == 'timing_first' else 'cached'}): {r[key]}"
                )
    print(f"\nload average at the end {', '.join(f'{x:.2f}' for x in os.getloadavg())}")


if __name__ == "__main__":
    main()
