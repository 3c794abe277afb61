"""`controlmm batch` for real: worker processes and a local Ray, resumes, crashes, timeouts, bad input.

Every exported trajectory is checked again here, independently, in MuJoCo, and the summary's
verdicts and counts must agree with those checks.
"""

import csv
import json
import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from cli_helpers import one_line_error, run_cli

from controlmm.atomic import OUTPUT_MARKER
from controlmm.batch import BatchConfig, load_jobs, run_batch
from controlmm.motion import Motion, save_motion
from scenes import load_scene
from sim import check_trajectory
from sim.files import load_qpos

RAY_MISSING = "the ray extra is not installed (pip install -e '.[ray]')"
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def motions(tmp_path_factory, sample_joints):
    """Two short motions (2 s at 20 fps) from the HumanML3D sample, as .npz and .bvh."""
    folder = tmp_path_factory.mktemp("motions")
    save_motion(Motion(joints=sample_joints[:40], fps=20), folder / "a.npz")
    save_motion(Motion(joints=sample_joints[40:80], fps=20), folder / "b.bvh")
    return folder


def _jsonl(path: Path, lines: list) -> Path:
    path.write_text("".join((x if isinstance(x, str) else json.dumps(x)) + "\n" for x in lines))
    return path


RETARGETS = [
    {"kind": "retarget", "motion": "a.npz", "id": "a-g1"},
    {"kind": "retarget", "motion": "b.bvh", "scene": "table", "id": "b-table", "family": "bvh"},
]
PLAN = {
    "kind": "variations",
    "id": "table-walk",
    "scene": "table",
    "count": 1,
    "text": "a person walks forward",
    "seconds": 2,
    "rounds": 0,
    "preset": "fast",
}


@pytest.fixture(scope="module")
def pool_batch(motions):
    """Two retargets, a malformed line and one plan in a jittered table scene, on 2 local workers."""
    jobs = _jsonl(motions / "jobs.jsonl", [*RETARGETS, '{"kind": "plan", "seed": ', PLAN])
    out = motions.parent / "batch"
    code = run_cli(["batch", str(jobs), "--out", str(out), "--workers", "2", "--no-progress"])
    return jobs, out, code


def _summary(out: Path) -> dict:
    return json.loads((out / "summary.json").read_text())


def _recheck(out: Path, row: dict) -> bool:
    """The verdict of an independent MuJoCo check of a job's exported trajectory."""
    folder = out / "jobs" / row["id"]
    record = json.loads((folder / "result.json").read_text())
    scene = folder / record["scene_file"] if "scene_file" in record else row["scene"]
    qpos, fps, robot = load_qpos(folder / "robot.npz")
    csv_qpos, _, _ = load_qpos(folder / "robot.csv", fps=fps)
    assert np.array_equal(qpos, csv_qpos)  # the CSV holds the same trajectory, digit for digit
    return check_trajectory(load_scene(scene, robot=robot), qpos, fps).passed


def test_a_batch_writes_every_job_and_its_summary_agrees_with_mujoco(pool_batch, capsys):
    jobs, out, code = pool_batch
    assert code == 1  # the malformed line is a failed job; the batch went on
    summary = _summary(out)
    rows = {r["id"]: r for r in summary["jobs"]}
    assert list(rows) == ["a-g1", "b-table", "line-3", "table-walk-v0"]
    bad = rows["line-3"]
    assert bad["status"] == "error" and bad["error"].startswith("jobs.jsonl:3: not valid JSON")
    ran = [r for r in summary["jobs"] if r["kind"] != "invalid"]
    assert all(r["status"] in ("passed", "failed") for r in ran), ran
    for row in ran:  # every exported trajectory, checked again independently
        assert _recheck(out, row) == (row["status"] == "passed"), row["id"]
    counts = summary["counts"]
    assert counts["passed"] == sum(r["status"] == "passed" for r in ran)
    assert counts["failed"] == sum(r["status"] == "failed" for r in ran) and counts["error"] == 1
    assert counts["jobs"] == 4 and counts["pending"] == 0
    plan = json.loads((out / "jobs" / "table-walk-v0" / "result.json").read_text())
    assert plan["files"] == ["motion.npz", "plan.json", "report.json", "robot.csv", "robot.json", "robot.npz",
                             "table-v0.xml"]  # fmt: skip
    assert set(plan["obstacle_offsets_m"]) == {"table"} and plan["rounds_run"] == 1
    assert rows["b-table"]["scene"] == "table" and rows["b-table"]["family"] == "bvh"
    assert rows["a-g1"]["frames"] == 98 and rows["a-g1"]["seconds"] > 0  # 2 s at 20 fps -> 50 fps
    report = json.loads((out / "jobs" / "a-g1" / "report.json").read_text())
    assert report["passed"] == (rows["a-g1"]["status"] == "passed")
    assert json.loads((out / OUTPUT_MARKER).read_text()) == {"kind": "batch", "files": None}
    with (out / "summary.csv").open() as fh:
        assert [r["id"] for r in csv.DictReader(fh)] == list(rows)
    assert "## Pass rate by scene" in (out / "summary.md").read_text()
    assert not [p for p in (out / "jobs").iterdir() if p.name.startswith(".")]  # no temporaries left


def test_a_rerun_skips_finished_jobs_and_runs_new_ones(pool_batch, capsys):
    jobs, out, _ = pool_batch
    before = {p: p.stat().st_mtime_ns for p in (out / "jobs").glob("*/result.json")}
    start = time.perf_counter()
    assert run_cli(["batch", str(jobs), "--out", str(out), "--no-progress"]) == 1
    assert "(0 run, 4 already finished)" in capsys.readouterr().out
    assert time.perf_counter() - start < 10  # no worker was started
    # the exported CSV validated as a job of its own gives the retarget job's verdict
    check = {"kind": "validate", "trajectory": str(out / "jobs" / "a-g1" / "robot.csv"), "fps": 50, "id": "v"}
    _jsonl(jobs, [*jobs.read_text().splitlines(), check])
    run_cli(["batch", str(jobs), "--out", str(out), "--no-progress", "--workers", "1"])
    assert "(1 run, 4 already finished)" in capsys.readouterr().out
    assert {p: p.stat().st_mtime_ns for p in before} == before
    rows = {r["id"]: r for r in _summary(out)["jobs"]}
    assert rows["v"]["status"] == rows["a-g1"]["status"]
    assert rows["v"]["foot_sliding_m"] == rows["a-g1"]["foot_sliding_m"]


def test_ray_gives_the_same_results_as_the_local_pool(pool_batch, motions, capsys):
    pytest.importorskip("ray", reason=RAY_MISSING)
    _, pool_out, _ = pool_batch
    jobs = _jsonl(motions / "ray.jsonl", RETARGETS)
    out = motions.parent / "batch-ray"
    code = run_cli(
        ["batch", str(jobs), "--out", str(out), "--ray", "auto", "--workers", "2", "--no-progress"]
    )
    assert "on ray with 2 workers" in capsys.readouterr().out
    pool_rows = {r["id"]: r for r in _summary(pool_out)["jobs"]}
    skip = {"seconds", "worker", "source"}
    for row in _summary(out)["jobs"]:
        assert {k: v for k, v in row.items() if k not in skip} == {
            k: v for k, v in pool_rows[row["id"]].items() if k not in skip
        }
        for name in ("robot.npz", "report.json"):
            ours, theirs = out / "jobs" / row["id"] / name, pool_out / "jobs" / row["id"] / name
            if name.endswith(".npz"):
                assert np.array_equal(np.load(ours)["qpos"], np.load(theirs)["qpos"])
            else:  # the same report, apart from the time the checks took
                ours, theirs = (json.loads(p.read_text()) for p in (ours, theirs))
                assert ours.pop("extra")["nq"] == theirs.pop("extra")["nq"] and ours == theirs
    assert code == (0 if all(r["status"] == "passed" for r in _summary(out)["jobs"]) else 1)


def test_a_crashed_worker_is_recorded_ctrl_c_stops_and_a_rerun_retries(motions, tmp_path):
    jobs = load_jobs(motions)  # a.npz, b.bvh -> g1
    third = {**RETARGETS[0], "motion": str(motions / "a.npz"), "id": "c"}
    jobs = [*jobs, *load_jobs(_jsonl(tmp_path / "c.jsonl", [third]))]
    out = tmp_path / "batch"

    def on_event(event, job, info):
        if event == "started" and job.id == jobs[0].id:
            os.kill(info["pid"], signal.SIGKILL)  # the worker dies in the middle of the job
        if event == "finished" and job.id == jobs[1].id:
            raise KeyboardInterrupt  # as Ctrl-C would, between two jobs

    with pytest.raises(KeyboardInterrupt):
        run_batch(jobs, out, BatchConfig(workers=1, progress=False), on_event=on_event)
    summary = _summary(out)
    statuses = [r["status"] for r in summary["jobs"]]
    assert statuses[0] == "crashed" and statuses[1] in ("passed", "failed") and statuses[2] == "pending"
    assert "worker process died (killed by SIGKILL)" in summary["jobs"][0]["error"]
    assert summary["interrupted"] is True and not (out / "jobs" / "c").exists()
    result = run_batch(jobs, out, BatchConfig(workers=1, progress=False, retry_errors=True))
    assert (result.ran, result.skipped) == (2, 1) and result.counts["crashed"] == 0
    assert result.counts["pending"] == 0 and result.all_passed == (result.counts["failed"] == 0)


def test_a_killed_batch_resumes(motions, tmp_path):
    """SIGKILL once the first job is written (12 jobs of a few tenths of a second each leave the
    batch far from done), then resume: the finished jobs are skipped, the rest run."""
    folder = tmp_path / "motions"
    folder.mkdir()
    names = [f"m{i:02d}.npz" for i in range(12)]
    for name in names:
        (folder / name).write_bytes((motions / "a.npz").read_bytes())
    out = tmp_path / "batch"
    cmd = [sys.executable, "-m", "controlmm", "batch", str(folder), "--out", str(out), "--workers", "1",
           "--no-progress"]  # fmt: skip
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)

    def finished() -> int:  # job folders in place (pathlib's * also matches the hidden temporaries)
        return sum(not p.parent.name.startswith(".") for p in out.glob("jobs/*/result.json"))

    deadline = time.monotonic() + 300
    while not finished() and time.monotonic() < deadline and proc.poll() is None:
        time.sleep(0.01)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    done = finished()
    assert 1 <= done < len(names), proc.stderr.read().decode() if proc.stderr else ""
    for job in (out / "jobs").iterdir():  # what is there is complete (or a temporary, swept later)
        assert job.name.startswith(".") or (job / "result.json").is_file()
    assert run_cli(["batch", str(folder), "--out", str(out), "--no-progress", "--workers", "1"]) in (0, 1)
    summary = _summary(out)
    assert (summary["ran"], summary["skipped"]) == (len(names) - done, done)
    assert summary["counts"]["pending"] == 0
    assert sorted(p.name for p in (out / "jobs").iterdir()) == [f"{name}.g1" for name in names]


def test_a_job_past_the_timeout_is_stopped_and_recorded(motions, tmp_path, capsys):
    out = tmp_path / "batch"
    jobs = _jsonl(tmp_path / "one.jsonl", [{**RETARGETS[0], "motion": str(motions / "a.npz")}])
    code = run_cli(
        ["batch", str(jobs), "--out", str(out), "--timeout", "0.05", "--no-progress", "--workers", "1"]
    )
    assert code == 1
    (row,) = _summary(out)["jobs"]
    assert row["status"] == "timeout" and "timeout of 0.05 s" in row["error"]
    assert json.loads((out / "jobs" / "a-g1" / "result.json").read_text())["files"] == []
    assert (
        run_cli(["batch", str(jobs), "--out", str(out), "--no-progress"]) == 1
    )  # final without --retry-errors
    assert "(0 run, 1 already finished)" in capsys.readouterr().out


def test_bad_input_exits_2_before_any_work(motions, tmp_path, capsys):
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "thesis.tex").write_text("years of work")
    one_line_error(capsys, ["batch", str(motions), "--out", str(mine)], "not empty", "--force")
    assert [p.name for p in mine.iterdir()] == ["thesis.tex"]
    bad = _jsonl(tmp_path / "bad.jsonl", [RETARGETS[0] | {"motion": str(motions / "a.npz")}, "{nope"])
    one_line_error(capsys, ["batch", str(bad), "--out", str(tmp_path / "o"), "--strict"], "bad.jsonl:2")
    one_line_error(
        capsys, ["batch", str(tmp_path / "nope.jsonl"), "--out", str(tmp_path / "o")], "does not exist"
    )
    one_line_error(capsys, ["batch", str(motions), "--out", str(tmp_path / "o"), "--ray", "nowhere"], "--ray")
    one_line_error(
        capsys, ["batch", str(bad), "--out", str(tmp_path / "o"), "--robot", "h1"], "--robot applies"
    )
    assert not (tmp_path / "o").exists()


def test_an_unreachable_ray_cluster_is_one_line(motions, tmp_path, capsys):
    pytest.importorskip("ray", reason=RAY_MISSING)
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    start = time.perf_counter()
    argv = ["batch", str(motions), "--out", str(tmp_path / "o"), "--ray", f"127.0.0.1:{port}"]
    one_line_error(capsys, argv, f"cannot reach Ray at '127.0.0.1:{port}'", "--ray auto")
    assert time.perf_counter() - start < 10 and not (tmp_path / "o").exists()
