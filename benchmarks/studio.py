"""Studio latency: the bundled example planned through the warm service vs the cold ``controlmm plan``.

    python benchmarks/studio.py                 # the embedded default model
    python benchmarks/studio.py --model DIR --repeats 2

Both are measured in this one run, each as a user meets it:

* cold: ``controlmm plan --out TMP`` in a fresh process (imports, model and text encoder loading, the
  plan, the files with ``render.mp4`` and ``plots/``), wall time of the command; and the same with
  ``--no-render --no-plots``;
* warm: ``controlmm studio --port 0`` started once and ready (model loaded); then ``POST /api/plans {}``
  (the bundled example, the service's defaults: no video, no PNG plots) polled every 0.1 s until
  ``done``, wall time from the POST to ``done`` as the client sees it.

The three are interleaved ``--repeats`` times (medians reported), and CPU seconds are measured beside
wall seconds (the command's own, the studio process's during its plan): on a shared machine the CPU
time moves much less with the load than the wall time.

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
import resource
import shutil
import subprocess
import sys
import tempfile
import time
import urllib.request
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1", "HF_HUB_OFFLINE": "1"}


def _children_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def _process_cpu(pid: int) -> float:
    """CPU seconds (user + system, every thread) a running process has used so far."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cold(out: Path, model: str | None, extra: list[str]) -> tuple[float, float, np.ndarray]:
    """Wall and CPU seconds of one ``controlmm plan`` command, and its robot.csv rows."""
    shutil.rmtree(out, ignore_errors=True)
    cmd = [sys.executable, "-m", "controlmm", "plan", "--out", str(out), "--no-progress", *extra]
    cmd += ["--model", model] if model else []
    cpu, t0 = _children_cpu(), time.perf_counter()
    done = subprocess.run(cmd, env=ENV, capture_output=True, text=True, cwd=ROOT)
    wall, cpu = time.perf_counter() - t0, _children_cpu() - cpu
    if done.returncode not in (0, 1):
        raise SystemExit(f"controlmm plan failed: {done.stderr.strip()[-500:]}")
    return wall, cpu, np.loadtxt(out / "robot.csv", delimiter=",", ndmin=2)


def _get(url: str) -> dict:
    with urllib.request.urlopen(url, timeout=60) as res:
        return json.loads(res.read())


def start_studio(model: str | None, log: Path) -> tuple[subprocess.Popen, str, float]:
    """``controlmm studio --port 0`` started and ready: (process, URL, seconds until the model is ready)."""
    cmd = [sys.executable, "-m", "controlmm", "studio", "--port", "0"] + (["--model", model] if model else [])
    t0 = time.perf_counter()
    with open(log, "w") as out:
        proc = subprocess.Popen(cmd, env=ENV, stdout=out, stderr=subprocess.STDOUT, text=True, cwd=ROOT)
    while not (match := re.search(r"serving (http://\S+/)", log.read_text())):
        if proc.poll() is not None:
            raise SystemExit(f"controlmm studio did not start: {log.read_text()[-500:]}")
        time.sleep(0.1)
    url = match.group(1)
    while _get(url + "api/info")["model"] == "loading":
        time.sleep(0.1)
    return proc, url, time.perf_counter() - t0


def warm(proc: subprocess.Popen, url: str) -> tuple[float, float, np.ndarray]:
    """Wall and CPU seconds of one ``POST /api/plans {}`` until ``done``, and its robot.csv rows."""
    cpu, t0 = _process_cpu(proc.pid), time.perf_counter()
    request = urllib.request.Request(url + "api/plans", data=b"{}", method="POST")
    with urllib.request.urlopen(request, timeout=60) as res:
        plan_id = json.loads(res.read())["id"]
    while (job := _get(url + f"api/plans/{plan_id}"))["status"] not in ("done", "failed"):
        time.sleep(0.1)
    wall, cpu = time.perf_counter() - t0, _process_cpu(proc.pid) - cpu
    if job["status"] == "failed":
        raise SystemExit(f"the warm plan failed: {job['error']}")
    with urllib.request.urlopen(url + f"api/plans/{plan_id}/files/robot.csv", timeout=60) as res:
        text = res.read().decode()
    return wall, cpu, np.array([[float(v) for v in r] for r in csv.reader(io.StringIO(text))])


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--model", default=None, help="model directory (default: the embedded default)")
    parser.add_argument("--repeats", type=int, default=2, help="rounds of (cold, cold lean, warm); default 2")
    args = parser.parse_args()
    runs: dict[str, list[tuple[float, float]]] = {"cold": [], "lean": [], "warm": []}
    loads = [os.getloadavg()[0]]
    with tempfile.TemporaryDirectory(prefix="controlmm-studio-bench-") as tmp:
        root = Path(tmp)
        proc, url, ready = start_studio(args.model, root / "studio.log")
        try:
            for _ in range(args.repeats):  # interleaved, so a change of machine load hits all three
                wall, cpu, rows_cold = cold(root / "cold", args.model, [])
                runs["cold"].append((wall, cpu))
                wall, cpu, _ = cold(root / "lean", args.model, ["--no-render", "--no-plots"])
                runs["lean"].append((wall, cpu))
                wall, cpu, rows_warm = warm(proc, url)
                runs["warm"].append((wall, cpu))
                loads.append(os.getloadavg()[0])
        finally:
            proc.terminate()
            proc.wait(30)
    same = rows_cold.shape == rows_warm.shape
    diff = float(np.abs(rows_cold - rows_warm).max()) if same else float("nan")
    med = {
        k: (float(np.median([w for w, _ in v])), float(np.median([c for _, c in v]))) for k, v in runs.items()
    }
    print(
        f"studio benchmark: the bundled example (table, seed 0), 1 torch thread, {args.repeats} interleaved "
        f"repeats, load average {min(loads):.1f}-{max(loads):.1f}; "
        f"the studio was ready {ready:.1f} s after its start"
    )
    print()
    print("| run | wall s (median) | CPU s (median) | warm / this, wall | warm / this, CPU |")
    print("|---|---|---|---|---|")
    names = {
        "cold": "cold `controlmm plan --out DIR` (video + plots)",
        "lean": "cold `controlmm plan --out DIR --no-render --no-plots`",
        "warm": "warm `POST /api/plans {}` -> done (no video, no plots)",
    }
    for key, name in names.items():
        wall, cpu = med[key]
        ratios = f"{100 * med['warm'][0] / wall:.0f} % | {100 * med['warm'][1] / cpu:.0f} %"
        print(f"| {name} | {wall:.1f} | {cpu:.1f} | {ratios if key != 'warm' else '|'} |")
    print()
    share = med["warm"][0] / med["cold"][0]
    print(
        f"target warm <= 50 % of the cold command (wall): {'met' if share <= 0.5 else 'NOT met'} "
        f"({100 * share:.0f} %)"
    )
    print(f"warm plan = cold plan: same robot.csv shape {same}, max |difference| {diff:.3g}")
    print(
        "runs (wall s / CPU s): "
        + "; ".join(f"{k} " + ", ".join(f"{w:.1f}/{c:.1f}" for w, c in v) for k, v in runs.items())
    )


if __name__ == "__main__":
    main()
