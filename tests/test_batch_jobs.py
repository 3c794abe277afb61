"""Batch jobs without workers: the JSONL format, folders of motions, scene variations, the summary."""

import csv
import json

import numpy as np
import pytest

from controlmm.batch import load_jobs, read_jsonl, scene_variations, write_summary
from controlmm.batch.jobs import Job
from controlmm.batch.sources import folder_jobs
from controlmm.batch.variations import jitter_scene
from controlmm.errors import ControlMMError
from scenes import load_scene


def _write(path, lines):
    path.write_text("\n".join(json.dumps(x) if not isinstance(x, str) else x for x in lines) + "\n")
    return path


def test_jsonl_jobs_have_stable_ids_and_bad_lines_name_their_line(tmp_path):
    (tmp_path / "walk.npz").write_bytes(b"")
    jobs_file = _write(
        tmp_path / "jobs.jsonl",
        [
            "# plans and retargets",
            {"kind": "plan", "scene": "pillars", "seed": 3, "rounds": 1},
            {"kind": "retarget", "motion": "walk.npz", "robot": "h1", "id": "walk-h1", "family": "walks"},
            "",
            {"kind": "retarget", "motion": "missing.npz"},
            '{"kind": "plan", "seed": 1',
            {"kind": "plan", "seed": "3"},
            {"kind": "plan", "sede": 3},
            {"kind": "dance"},
            {"kind": "validate", "trajectory": "walk.npz", "id": "walk-h1"},
            {"kind": "plan", "id": "../escape"},
        ],
    )
    jobs = load_jobs(jobs_file)
    assert [j.id for j in jobs] == [j.id for j in load_jobs(jobs_file)]  # stable across reads
    assert len(read_jsonl(jobs_file)) == len(jobs)
    plan, walk, *bad = jobs
    assert plan.id.startswith("plan-pillars-s3-") and plan.kind == "plan" and plan.error is None
    assert (walk.id, walk.robot, walk.family, walk.input) == ("walk-h1", "h1", "walks", "walk.npz")
    assert walk.path("motion") == tmp_path.resolve() / "walk.npz"
    errors = [j.error for j in bad]
    assert all(j.kind == "invalid" for j in bad)
    assert "jobs.jsonl:5:" in errors[0] and "does not exist" in errors[0]
    assert "jobs.jsonl:6: not valid JSON" in errors[1]
    assert "jobs.jsonl:7: 'seed' must be a whole number" in errors[2]
    assert "unknown key 'sede'" in errors[3] and "seed" in errors[3]
    assert "unknown job kind 'dance'; allowed: plan, retarget, validate, variations" in errors[4]
    assert "jobs.jsonl:10:" in errors[5] and "already used by jobs.jsonl:3" in errors[5]
    assert "jobs.jsonl:11:" in errors[6] and "is not allowed" in errors[6]
    with pytest.raises(ControlMMError, match=r"^jobs.jsonl:5: motion file"):
        load_jobs(jobs_file, strict=True)
    # a changed argument is another job; the same arguments give the same id
    again = _write(tmp_path / "b.jsonl", [{"kind": "plan", "scene": "pillars", "seed": 3, "rounds": 2}])
    assert load_jobs(again)[0].id != plan.id
    with pytest.raises(ControlMMError, match="--robot applies to a folder of motions"):
        load_jobs(jobs_file, robots=["g1"])


def test_a_folder_gives_one_job_per_motion_and_robot(tmp_path, humanml3d_dir):
    (tmp_path / "walks").mkdir()
    for name in ("walks/a.npz", "b.bvh", "c.csv", "notes.txt", ".hidden/d.npz"):
        (tmp_path / name).parent.mkdir(exist_ok=True)
        (tmp_path / name).write_text("")
    jobs = load_jobs(tmp_path, robots=["g1", "h1"], scene="table")
    assert [j.id for j in jobs] == [
        "b.bvh.g1",
        "b.bvh.h1",
        "c.csv.g1",
        "c.csv.h1",
        "walks__a.npz.g1",
        "walks__a.npz.h1",
    ]
    assert {j.kind for j in jobs} == {"retarget"} and {j.scene for j in jobs} == {"table"}
    assert jobs[4].family == "walks" and jobs[0].family == ""
    assert jobs[2].args["csv_fps"] == 30.0 and "csv_fps" not in jobs[0].args
    # a HumanML3D folder: new_joint_vecs only (not new_joints, Mean/Std), families from meta/
    ids = [j.id for j in folder_jobs(humanml3d_dir)]
    assert ids == ["new_joint_vecs__012314.npy.g1"]
    (tmp_path / "empty").mkdir()
    with pytest.raises(ControlMMError, match="holds no motion files"):
        folder_jobs(tmp_path / "empty")


def test_scene_variations_are_seeded_jittered_copies_that_load(tmp_path):
    jobs = scene_variations(
        {"scene": "corridor", "count": 3, "jitter_m": 0.2, "variation_seed": 7, "seed": 1}
    )
    assert [j.id.rsplit("-", 1)[1] for j in jobs] == ["v0", "v1", "v2"]
    assert all(j.kind == "plan" and j.args["seed"] == 1 and j.scene == "corridor" for j in jobs)
    xml, moved = jitter_scene("corridor", index=1, seed=7, jitter_m=0.2)
    assert (xml, moved) == jitter_scene("corridor", index=1, seed=7, jitter_m=0.2)  # the same scene again
    assert moved != jitter_scene("corridor", index=2, seed=7, jitter_m=0.2)[1]
    assert set(moved) == {"walls", "box_left", "box_right"}  # the floor stays
    offsets = np.array(list(moved.values()))
    assert np.all(np.abs(offsets) <= 0.2) and np.any(np.abs(offsets) > 0.01)
    path = tmp_path / "corridor-v1.xml"
    path.write_text(xml)
    original, copy = load_scene("corridor"), load_scene(path)
    assert copy.suggested_prompt == original.suggested_prompt and copy.start == original.start
    box = copy.model.body("box_left").pos - original.model.body("box_left").pos
    assert np.allclose(box, [*moved["box_left"], 0.0], atol=1e-9)
    # a scene with a mesh keeps finding it; moving obstacles (mocap tracks) stay on their track
    xml, moved = jitter_scene("mesh_rock", index=0, seed=0, jitter_m=0.1)
    (tmp_path / "rock.xml").write_text(xml)
    assert load_scene(tmp_path / "rock.xml").obstacle_geom_ids and set(moved) == {"rock"}
    assert jitter_scene("moving_obstacle", index=0, seed=0, jitter_m=0.1)[1] == {}
    with pytest.raises(ControlMMError, match="'count' must be from 1 to 10000"):
        scene_variations({"count": 0})


def test_summary_counts_and_pass_rates_per_group(tmp_path):
    jobs = [Job(f"j{i}", "retarget", {"motion": f"m{i}.npz", "robot": r}, family=f) for i, (r, f) in
            enumerate([("g1", "walk"), ("g1", "run"), ("h1", "walk"), ("h1", "walk")])]  # fmt: skip
    records = {
        "j0": {"status": "passed", "max_penetration_m": 0.0, "failure_kinds": {}},
        "j1": {"status": "failed", "failure_kinds": {"foot_sliding": 2, "self_collision": 1}},
        "j2": {"status": "timeout", "error": "ran longer than the timeout of 5 s"},
    }
    summary = write_summary(tmp_path, jobs, records)
    assert summary["counts"] == {"jobs": 4, "passed": 1, "failed": 1, "done": 0, "error": 0, "crashed": 0,
                                 "timeout": 1, "pending": 1, "pass_rate": round(1 / 3, 4)}  # fmt: skip
    assert summary["by_robot"]["g1"]["pass_rate"] == 0.5 and summary["by_robot"]["h1"]["pass_rate"] == 0.0
    assert summary["by_family"]["walk"]["jobs"] == 3
    rows = list(csv.DictReader((tmp_path / "summary.csv").open()))
    assert [r["status"] for r in rows] == ["passed", "failed", "timeout", "pending"]
    assert rows[1]["failure_kinds"] == "foot_sliding:2;self_collision:1" and rows[3]["input"] == "m3.npz"
    assert json.loads((tmp_path / "summary.json").read_text())["jobs"][2]["error"].startswith("ran longer")
    md = (tmp_path / "summary.md").read_text()
    assert "| g1 | 2 | 1 | 1 | 0 | 0 | 0 | 0 | 50.0 % |" in md and "| j1 | failed | foot_sliding:2" in md
