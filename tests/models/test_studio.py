"""``controlmm studio`` and ``controlmm view`` as a user runs them: the real CLI in a subprocess (a tiny
trained model), its JSON API through a real HTTP client, and its page in a real headless Chromium."""

from __future__ import annotations

import base64
import csv
import io
import json
import time

import numpy as np
import pytest
from browser import element_pixels, headless_chromium
from studio_helpers import call, running_server, wait_for

from retarget import RobotTrajectory, robot_scale
from scenes import load_scene
from sim import check_trajectory, make_world

from .conftest import subprocess_env

PLAN = {"scene": "table", "rounds": 1, "preset": "fast", "seed": 3}
"""A short plan: the bundled table scene and its hand target, fast editing, one feedback round."""


@pytest.fixture(scope="module")
def studio(tiny_model_dir):
    # the tiny model's seed 3 makes a motion the retargeter takes (most of its motions are not human)
    argv = ["studio", "--model", str(tiny_model_dir), "--threads", "1"]
    with running_server(argv, subprocess_env()) as url:
        wait_for(url + "api/info", lambda d: d["model"] != "loading")
        yield url


@pytest.fixture(scope="module")
def done_plan(studio):
    status, body = call("POST", studio + "api/plans", PLAN)
    assert status == 202, body
    seen = set()

    def finished(job):
        seen.add(job["status"])
        return job["status"] in ("done", "failed")

    job = wait_for(studio + f"api/plans/{body['id']}", finished)
    assert job["status"] == "done", job.get("error")
    return body["id"], job, seen


def test_a_plan_runs_in_the_worker_and_reports(studio, done_plan):
    plan_id, job, seen = done_plan
    assert seen <= {"queued", "running", "done"} and "done" in seen
    report = job["report"]
    assert report["plan"]["scene"] == "table" and report["plan"]["seed"] == 3
    assert len(report["rounds"]) == report["plan"]["rounds_run"] >= 1
    assert any(line.startswith("round 0:") for line in job["progress"])
    assert {"robot.csv", "robot.npz", "motion.npz", "report.json", "plan.json"} <= set(job["files"])
    assert not any(f.startswith("plots/") or f == "render.mp4" for f in job["files"])  # plots off, no video
    # the same report as a file, and the trajectory rows the report counts
    status, served = call("GET", studio + f"api/plans/{plan_id}/files/report.json")
    assert status == 200 and served["passed"] == report["passed"]
    status, rows = call("GET", studio + f"api/plans/{plan_id}/files/robot.csv")
    table = list(csv.reader(io.StringIO(rows.decode())))
    assert status == 200 and len(table) == report["num_frames"] and len(table[0]) == 7 + 29
    status, listing = call("GET", studio + "api/plans")
    assert status == 200 and [p["id"] for p in listing["plans"]] == [plan_id]


def test_the_returned_plan_rechecks_in_mujoco(studio, done_plan, tmp_path):
    plan_id, job, _ = done_plan
    status, npz = call("GET", studio + f"api/plans/{plan_id}/files/robot.npz")
    assert status == 200
    (tmp_path / "robot.npz").write_bytes(npz)
    traj = RobotTrajectory.load(tmp_path / "robot.npz")
    report = check_trajectory(make_world(load_scene("table", robot="g1")), traj)
    assert report.passed == job["report"]["passed"]
    assert report.max_penetration_m == pytest.approx(job["report"]["max_penetration_m"], abs=1e-6)


def test_the_view_holds_every_round_with_poses_failures_and_targets(studio, done_plan):
    plan_id, job, _ = done_plan
    status, view = call("GET", studio + f"api/plans/{plan_id}/view")
    assert status == 200 and view["rounds_drawn"] == "all"
    assert [r["index"] for r in view["rounds"]] == list(range(len(job["report"]["rounds"])))
    geometry_status, geometry = call("GET", studio + f"api/geometry/{view['geometry']}")
    assert geometry_status == 200
    assert sum(g["kind"] == "robot" for g in geometry["geoms"]) > 20
    assert "table_top" in {g["name"] for g in geometry["geoms"]}
    for r in view["rounds"]:
        poses = np.frombuffer(base64.b64decode(r["poses"]), dtype="<f4")
        assert poses.size == r["num_frames"] * len(geometry["bodies"]) * 7
        assert len(r["clearance"]) == r["num_frames"]
        (target,) = r["targets"]  # the table's right-hand target
        assert target["joint"] == "right_wrist" and target["frame"] == 80
        assert target["target"] == pytest.approx([1.0, -0.15, 0.75], abs=1e-3)
        assert np.linalg.norm(np.subtract(target["achieved"], target["target"])) > 0
    chosen = next(r for r in view["rounds"] if r["index"] == view["chosen"])
    assert chosen["failures"] == job["report"]["failures"]


@pytest.mark.parametrize(
    ("body", "field", "needle"),
    [
        ({"scene": "no_such_scene"}, "scene", "unknown scene 'no_such_scene'"),
        ({"robot": "r2d2"}, "robot", "unknown robot 'r2d2'"),
        ({"seed": -1}, "seed", "seed must be"),
        ({"seed": "zero"}, "seed", "seed must be a whole number"),
        ({"rounds": 11}, "rounds", "rounds must be"),
        ({"seconds": 30}, "seconds", "seconds must be from 2 to 9.8"),
        ({"preset": "slow"}, "preset", "slow"),
        ({"colour": "red"}, "colour", "unknown field 'colour'"),
        (
            {"control": {"constraints": [{"joint": "tail", "frame": 5, "position": [0, 1, 0]}]}},
            "control",
            "tail",
        ),
        (
            {
                "text": "a person waves",
                "seconds": 3,
                "control": {"constraints": [{"joint": "pelvis", "frame": 150, "position": [0, 0.9, 1]}]},
            },
            "control",
            "frame 150 is outside the motion (frames 0..59)",
        ),
    ],
)
def test_bad_requests_answer_400_with_one_line_naming_the_field(studio, body, field, needle):
    status, answer = call("POST", studio + "api/plans", body)
    assert status == 400, answer
    assert answer["field"] == field and needle in answer["error"] and "\n" not in answer["error"]


def test_a_scene_file_that_does_not_compile_is_a_400_and_the_server_goes_on(studio, tmp_path):
    broken = tmp_path / "broken.xml"
    broken.write_text('<mujoco><worldbody><geom type="box" size="0.1"/><body></worldbody></mujoco>')
    status, answer = call("POST", studio + "api/plans", {"scene": str(broken)})
    assert status == 400 and answer["field"] == "scene" and "malformed MJCF" in answer["error"]
    status, answer = call("POST", studio + "api/plans", raw=b"{not json")
    assert status == 400 and "not JSON" in answer["error"]
    status, answer = call("GET", studio + "api/plans/nope")
    assert status == 404 and "no plan 'nope'" in answer["error"]
    status, info = call("GET", studio + "api/info")
    assert status == 200 and info["model"] == "ready"


def test_controlmm_view_serves_a_finished_plan_without_a_model(studio, done_plan, tmp_path):
    plan_id, job, _ = done_plan
    out = tmp_path / "plan"
    for name in job["files"]:  # the plan's files, as a user downloads them
        status, data = call("GET", studio + f"api/plans/{plan_id}/files/{name}")
        assert status == 200
        path = out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(data if isinstance(data, bytes) else json.dumps(data).encode())
    with running_server(["view", str(out)], subprocess_env()) as url:
        status, info = call("GET", url + "api/info")
        assert status == 200 and info["mode"] == "view" and info["model"] == "none"
        status, listing = call("GET", url + "api/plans")
        (entry,) = listing["plans"]
        assert entry["status"] == "done" and entry["id"] == "plan"
        status, view = call("GET", url + "api/plans/plan/view")
        assert status == 200 and view["rounds_drawn"] == "chosen"
        assert [r["index"] for r in view["rounds"]] == [job["report"]["plan"]["chosen_round"]]
        assert len(view["round_figures"]) == len(job["report"]["rounds"])
        status, answer = call("POST", url + "api/plans", {})
        assert status == 405 and "controlmm studio" in answer["error"]


# ------------------------------------------------------------------------------------------ browser
@pytest.fixture(scope="module")
def browser():
    with headless_chromium() as b:
        yield b


def _wait_js(browser, script: str, timeout: float = 240.0):
    end = time.monotonic() + timeout
    while True:
        value = browser.execute_script(script)
        if value:
            return value
        if time.monotonic() > end:
            raise TimeoutError(f"page never satisfied: {script}")
        time.sleep(0.25)


@pytest.mark.slow
def test_the_page_plans_and_draws_the_robot_in_the_scene(studio, browser, tmp_path):
    from selenium.webdriver.common.by import By

    browser.get(studio)
    _wait_js(browser, "return document.getElementById('model-state').dataset.model === 'ready'")
    _wait_js(browser, "return Number(document.getElementById('view').dataset.robotGeoms) > 0")  # preview
    rows = browser.find_elements(By.CSS_SELECTOR, "#targets tbody tr")
    assert len(rows) == 1  # the table's suggested hand target, placed in the page
    for field, value in (("rounds", "1"), ("seed", "3")):
        element = browser.find_element(By.ID, field)
        element.clear()
        element.send_keys(value)
    browser.find_element(By.ID, "preset").send_keys("fast")
    browser.find_element(By.ID, "plan-button").click()
    _wait_js(browser, "return ['done', 'failed'].includes(document.getElementById('status').dataset.status)")
    assert browser.find_element(By.ID, "status").get_attribute("data-status") == "done"
    _wait_js(browser, "return window.studio.state.view !== null && window.studio.viewer.view !== null")
    assert browser.find_elements(By.CSS_SELECTOR, "#progress li")  # the rounds' progress lines
    links = [a.get_attribute("href") for a in browser.find_elements(By.CSS_SELECTOR, "#downloads a")]
    csv_link = next(h for h in links if h.endswith("/robot.csv"))
    assert call("GET", csv_link)[0] == 200
    assert len(browser.find_elements(By.CSS_SELECTOR, "#rounds-table tr")) >= 2
    assert browser.find_elements(By.CSS_SELECTOR, "#target-results td")

    # the scene contains the robot: drawn (its geoms counted) and visible (hiding it changes pixels)
    browser.execute_script("window.studio.viewer.draw()")
    assert int(browser.find_element(By.ID, "view").get_attribute("data-robot-geoms")) > 20
    browser.save_screenshot(str(tmp_path / "studio.png"))
    assert (tmp_path / "studio.png").stat().st_size > 10_000
    shown = element_pixels(browser, "view")
    browser.find_element(By.ID, "show-robot").click()
    browser.execute_script("window.studio.viewer.draw()")
    hidden = element_pixels(browser, "view")
    assert int(browser.find_element(By.ID, "view").get_attribute("data-robot-geoms")) == 0
    changed = (np.abs(shown.astype(int) - hidden.astype(int)).max(axis=2) > 40).sum()
    assert changed > 2000, changed
    browser.find_element(By.ID, "show-robot").click()

    # rounds side by side: one panel per round
    rounds = len(browser.execute_script("return window.studio.state.view.rounds"))
    browser.find_element(By.ID, "side-by-side").click()
    browser.execute_script("window.studio.viewer.draw()")
    assert int(browser.find_element(By.ID, "view").get_attribute("data-panels")) == rounds
    browser.find_element(By.ID, "side-by-side").click()

    # the timeline: scrub to the end, then play moves time on
    end = int(browser.find_element(By.ID, "timeline").get_attribute("max"))
    assert end > 50
    browser.execute_script(
        "const t = document.getElementById('timeline'); t.value = arguments[0];"
        "t.dispatchEvent(new Event('input'));",
        end // 2,
    )
    assert browser.execute_script("return window.studio.viewer.time") > 0.4
    browser.find_element(By.ID, "play").click()
    before = browser.execute_script("return window.studio.viewer.time")
    time.sleep(0.6)
    assert browser.execute_script("return window.studio.viewer.time") != before
    # pause through the page: a WebDriver click waits for the playing headless renderer (~15 s)
    browser.execute_script("document.getElementById('play').click()")
    assert browser.find_element(By.ID, "play").text == "play"


@pytest.mark.slow
def test_the_page_shows_bad_input_next_to_the_field(studio, browser, tmp_path):
    from selenium.webdriver.common.by import By

    browser.get(studio)
    _wait_js(browser, "return Number(document.getElementById('view').dataset.robotGeoms) > 0")
    broken = tmp_path / "broken.xml"
    broken.write_text("<mujoco><worldbody><body></worldbody></mujoco>")
    path = browser.find_element(By.ID, "scene-path")
    path.send_keys(str(broken))
    browser.find_element(By.ID, "text").click()  # leave the field: the page loads the scene
    message = _wait_js(browser, "return document.getElementById('error-scene').textContent", 30)
    assert "malformed MJCF" in message and str(broken) in message
    path.clear()
    browser.find_element(By.ID, "text").click()  # back to the bundled scene: its error goes
    _wait_js(browser, "return document.getElementById('error-scene').textContent === ''", 30)
    seed = browser.find_element(By.ID, "seed")
    seed.clear()
    seed.send_keys("-3")
    browser.find_element(By.ID, "plan-button").click()
    message = _wait_js(browser, "return document.getElementById('error-seed').textContent", 30)
    assert "seed must be" in message and "-3" in message
    assert "invalid" in browser.find_element(By.ID, "seed").get_attribute("class")
    seed.clear()
    seed.send_keys("0")
    # a spec file in human coordinates: its targets come back in world coordinates, one row each
    spec = tmp_path / "spec.json"
    spec.write_text(
        json.dumps(
            {
                "coords": "human",
                "constraints": [
                    {"joint": "pelvis", "frame": 40, "position": [0.0, 0.9, 1.0]},
                    {"joint": "left_wrist", "frame": 70, "position": [0.3, 1.2, 1.5]},
                ],
            }
        )
    )
    browser.find_element(By.ID, "spec-file").send_keys(str(spec))
    _wait_js(browser, "return document.querySelectorAll('#targets tbody tr').length === 2", 30)
    edits = browser.execute_script("return window.studio.state.edits")
    table = load_scene("table", robot="g1")
    world = table.human_to_world(robot_scale("g1")).to_world(np.array([[0.0, 0.9, 1.0], [0.3, 1.2, 1.5]]))
    assert [e["joint"] for e in edits] == ["pelvis", "left_wrist"]
    assert np.array([e["position"] for e in edits]) == pytest.approx(world, abs=1e-3)
    spec.write_text(json.dumps({"constraints": [{"joint": "tail", "frame": 5, "position": [0, 1, 0]}]}))
    browser.find_element(By.ID, "spec-file").send_keys(str(spec))
    message = _wait_js(browser, "return document.getElementById('error-control').textContent", 30)
    assert "tail" in message
    frame = browser.find_element(By.CSS_SELECTOR, "#targets tbody tr input[data-k=frame]")
    frame.clear()
    frame.send_keys("900")
    browser.find_element(By.ID, "plan-button").click()
    message = _wait_js(browser, "return document.getElementById('error-control').textContent", 30)
    assert "frame 900" in message and "outside the motion" in message
    assert document_errors(browser) == {"control"}  # shown next to that field only
    assert call("GET", studio + "api/info")[0] == 200  # the server goes on


def document_errors(browser) -> set[str]:
    return set(
        browser.execute_script(
            "return [...document.querySelectorAll('.error')].filter(e => e.textContent)"
            ".map(e => e.id.replace('error-', ''))"
        )
    )
