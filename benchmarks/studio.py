"""Studio latency: the bundled example planned through the warm service vs the cold ``controlmm plan``.

    python benchmarks/studio.py                 # the embedded default model
    python benchmarks/studio.py --model DIR --repeats 2

Both are measured in this one run, each as a user meets it:

* cold: ``controlmm plan --out TMP`` in a fresh process (imports, model and text encoder loading, the
  plan, the files with ``render.mp4`` and ``plots/``), wall time of the command; and the same with
  ``--no-render --no-plots``;
* warm: ``controlmm studio --port 0`` started once and ready (model loaded); then ``POST /api/plans {}``
  (the bundled example, the service's defaults: no video, no PNG plots) polled every 0.1 s until
  ``done``, wall time from the POST to ``done`` as the client sees it; ``--repeats`` requests.

The warm plan is checked to be the cold plan: the same ``robot.csv`` (max joint difference printed).
Target: warm <= 50 % of the cold command.
"""

from __future__ import annotations

import argparse
import csv
import io
import json
import os
import re
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1"}


def cold(out: Path, model: str | None, extra: list[str]) -> tuple[float, np.ndarray]:
    cmd = [sys.executable, "-m", "controlmm", "plan", "--out", str(out), "--no-progress", *extra]
    cmd += ["--model", model] if model else []
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=ENV, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if done.returncode not in (0, 1):
        raise SystemExit(f"controlmm plan failed: {done.stderr.strip()[-500:]}")
    return wall, np.loadtxt(out / "robot.csv", delimiter=",", ndmin=2)


def _get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=60) as res:
        return json.loads(res.read())


def warm(model: str | None, repeats: int, log: Path) -> tuple[float, list[float], np.ndarray]:
    cmd = [sys.executable, "-m", "controlmm", "studio", "--port", "0"] + (["--model", model] if model else [])
    t0 = time.perf_counter()
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd, env=ENV, stdout=out, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    try:
        while not (match := re.search(r"serving (http://\S+/)", log.read_text())):
            if proc.poll() is not None:
                raise SystemExit(f"controlmm studio did not start: {log.read_text()[-500:]}")
            time.sleep(0.1)
        url = match.group(1)
        while _get(url + "api/info")["model"] == "loading":
            time.sleep(0.1)
        ready = time.perf_counter() - t0
        walls, rows = [], np.zeros((0, 0))
        for _ in range(repeats):
            t1 = time.perf_counter()
            request = urllib.request.Request(url + "api/plans", data=b"{}", method="POST")
            with urllib.request.urlopen(request, timeout=60) as res:
                plan_id = json.loads(res.read())["id"]
            while (job := _get(url + f"api/plans/{plan_id}"))["status"] not in ("done", "failed"):
                time.sleep(0.1)
            walls.append(time.perf_counter() - t1)
            if job["status"] == "failed":
                raise SystemExit(f"the warm plan failed: {job['error']}")
            with urllib.request.urlopen(url + f"api/plans/{plan_id}/files/robot.csv", timeout=60) as res:
                text = res.read().decode()
            rows = np.array([[float(v) for v in r] for r in csv.reader(io.StringIO(text))])
        return ready, walls, rows
    finally:
        proc.terminate()
        proc.wait(30)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", default=None, help="model directory (default: the embedded default)")
    parser.add_argument("--repeats", type=int, default=2, help="warm requests after the start (default 2)")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="controlmm-studio-bench-") as tmp:
        root = Path(tmp)
        load = os.getloadavg()[0]
        cold_full, rows_cold = cold(root / "cold", args.model, [])
        cold_lean, _ = cold(root / "lean", args.model, ["--no-render", "--no-plots"])
        ready, walls, rows_warm = warm(args.model, args.repeats, root / "studio.log")
        load = max(load, os.getloadavg()[0])
    same = rows_cold.shape == rows_warm.shape
    diff = float(np.abs(rows_cold - rows_warm).max()) if same else float("nan")
    print(
        "studio benchmark: the bundled example (table, seed 0), 1 torch thread, "
        f"load average up to {load:.1f}"
    )
    print()
    print("| run | wall s | warm / cold |")
    print("|---|---|---|")
    print(f"| cold `controlmm plan --out DIR` (video + plots) | {cold_full:.1f} | |")
    print(f"| cold `controlmm plan --out DIR --no-render --no-plots` | {cold_lean:.1f} | |")
    print(f"| `controlmm studio` start until the model is ready | {ready:.1f} | |")
    for k, w in enumerate(walls):
        print(
            f"| warm `POST /api/plans {{}}` -> done, request {k + 1} | {w:.1f} | "
            f"{100 * w / cold_full:.0f} % of cold, {100 * w / cold_lean:.0f} % of cold lean |"
        )
    print()
    verdict = "met" if walls[0] <= 0.5 * cold_full else "NOT met"
    print(
        f"target warm <= 50 % of the cold command: {verdict} "
        f"(first request {100 * walls[0] / cold_full:.0f} %)"
    )
    print(f"warm plan = cold plan: same robot.csv shape {same}, max |difference| {diff:.3g}")


if __name__ == "__main__":
    main()
