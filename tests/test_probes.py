"""Text-adherence probes: pass on the corpus' ground truth, fail on mismatched captions."""

from __future__ import annotations

import json

import numpy as np
import pytest

from controlmm.corpus import CorpusConfig, family_names, make_clip, write_corpus
from controlmm.corpus.dataset import ClipSpec
from controlmm.corpus.probes import PROBES, ProbeCase, check, probe
from controlmm.errors import ControlMMError
from controlmm.eval.cases import evaluate, ground_truth, list_cases
from controlmm.motion import Motion


@pytest.fixture(scope="module")
def corpus(tmp_path_factory):
    out = tmp_path_factory.mktemp("probes") / "c"
    write_corpus(out, CorpusConfig(clips=2 * len(family_names()), seed=2024), workers=1, progress=False)
    return out


def _motion(family: str, index: int = 0, **claims_override):
    feats, joints, caps, meta = make_clip(ClipSpec(index, f"{index:06d}", family, "train", seed=31))
    return Motion.from_features(feats), meta


def test_every_family_has_a_probe():
    assert set(family_names()) <= set(PROBES)
    assert len(family_names()) >= 20


def test_probes_pass_on_ground_truth(corpus):
    cases = list_cases(corpus, "all")
    assert len(cases) == 2 * len(family_names()) * 3
    report = evaluate(cases, ground_truth(corpus), split="all", per_clip=True)
    assert report.rate == 1.0, report.table()
    assert set(report.counts) == set(family_names())
    assert "all" in report.table() and report.to_json()["passed"] == len(cases)


def test_probes_fail_on_wrong_pairs():
    swap = {"left": "right", "right": "left"}
    for side in ("left", "right"):
        wave, _ = _motion(f"wave_{side}")
        assert probe(wave, f"wave_{side}", {"hand": side}).passed
        wrong = probe(wave, f"wave_{swap[side]}", {"hand": swap[side]})
        assert not wrong.passed and wrong.failures()[0].name.startswith(swap[side])
        step, _ = _motion(f"sidestep_{side}")
        assert not probe(step, f"sidestep_{swap[side]}", {"direction": swap[side]}).passed
        turn, meta = _motion(f"turn_{side}")
        assert not probe(turn, f"turn_{swap[side]}", {"direction": swap[side]}).passed
        other_angle = 90 if meta["params"]["angle"] != 90 else 180
        assert not probe(turn, f"turn_{side}", {"direction": side, "angle": other_angle}).passed
    cw, _ = _motion("circle_cw")
    assert probe(cw, "circle_cw", {"rotation": "clockwise"}).passed
    assert not probe(cw, "circle_ccw", {"rotation": "counterclockwise"}).passed
    walk, _ = _motion("walk")
    assert not probe(walk, "walk_backward", {}).passed
    back, _ = _motion("walk_backward")
    assert not probe(back, "walk", {}).passed
    jump, meta = _motion("jump_in_place")
    n = meta["params"]["count"]
    assert probe(jump, "jump_in_place", {"count": n}).passed
    assert not probe(jump, "jump_in_place", {"count": n + 1}).passed
    punch, meta = _motion("punch")
    hand, n = meta["params"]["hand"], meta["params"]["count"]
    assert not probe(punch, "punch", {"hand": swap[hand], "count": n}).passed
    assert not probe(punch, "punch", {"hand": hand, "count": n + 1}).passed
    kneel, meta = _motion("kneel")
    assert not probe(kneel, "kneel", {"knee": swap[meta["params"]["knee"]]}).passed
    reach, meta = _motion("reach_sideways")
    assert not probe(reach, "reach_sideways", {"hand": swap[meta["params"]["hand"]]}).passed
    squat, _ = _motion("squat")
    assert not probe(squat, "jump_in_place", {"count": 1}).passed


def test_check_accepts_a_metadata_record_and_reports_values(corpus):
    clip_id = (corpus / "test.txt").read_text().split()[0]
    meta = json.loads((corpus / "meta" / f"{clip_id}.json").read_text())
    motion = Motion.from_features(np.load(corpus / "new_joint_vecs" / f"{clip_id}.npy"))
    result = check(meta, motion)
    assert result.passed and np.isfinite(result.value) and result.family == meta["family"]
    case = ProbeCase(
        clip_id,
        meta["captions"][0]["text"],
        meta["family"],
        meta["captions"][0]["claims"],
        meta["frames"],
        "test",
    )
    assert check(case, motion.joints).passed
    with pytest.raises(ControlMMError):
        probe(motion, "fly_to_the_moon", {})


def test_list_cases_rejects_missing_or_malformed_data(tmp_path, corpus):
    with pytest.raises(ControlMMError, match="not a directory"):
        list_cases(tmp_path / "nope")
    with pytest.raises(ControlMMError, match="test.txt"):
        list_cases(tmp_path)
    (tmp_path / "test.txt").write_text("000001\n")
    with pytest.raises(ControlMMError, match="meta"):
        list_cases(tmp_path)
    (tmp_path / "meta").mkdir()
    (tmp_path / "meta" / "000001.json").write_text("{not json")
    with pytest.raises(ControlMMError, match="malformed"):
        list_cases(tmp_path)
    with pytest.raises(ControlMMError, match="split"):
        list_cases(corpus, "everything")


def test_probes_of_the_new_families_fail_on_wrong_pairs():
    swap = {"left": "right", "right": "left"}
    for family, flip in (("sit_down", "stand_up"), ("lie_down", "stand_up")):
        motion, meta = _motion(family)
        claim = meta["params"][flip]
        assert probe(motion, family, {flip: claim}).passed
        assert not probe(motion, family, {flip: not claim}).passed
    kick, meta = _motion("kick")
    p = meta["params"]
    assert probe(kick, "kick", {"leg": p["leg"], "kick": p["kind"], "count": p["count"]}).passed
    assert not probe(kick, "kick", {"leg": swap[p["leg"]]}).passed
    assert not probe(
        kick, "kick", {"leg": p["leg"], "kick": "side" if p["kind"] == "front" else "front"}
    ).passed
    assert not probe(kick, "kick", {"leg": p["leg"], "count": p["count"] + 1}).passed
    point, meta = _motion("point")
    p = meta["params"]
    assert not probe(point, "point", {"hand": swap[p["hand"]]}).passed
    wrong_where = p["hand"] if p["where"] == "ahead" else "ahead"
    assert not probe(point, "point", {"hand": p["hand"], "where": wrong_where}).passed
    for index in range(3):
        look, meta = _motion("look_around", index)
        side = meta["params"]["look"]
        if side != "both":
            assert not probe(look, "look_around", {"look": swap[side]}).passed
            assert not probe(look, "look_around", {"look": "both"}).passed
    for family in ("platform", "stairs"):
        motion, meta = _motion(family)
        v = meta["params"]["vertical"]
        assert not probe(motion, family, {"vertical": "down" if v == "up" else "up"}).passed
    walk, _ = _motion("walk")
    for family in ("step_over", "carry", "stairs", "platform"):
        assert not probe(walk, family, {}).passed, family
    pick, meta = _motion("pick_up")
    style = meta["params"]["style"]
    assert not probe(pick, "pick_up", {"style": "stoop" if style == "squat" else "squat"}).passed
    bow, meta = _motion("bow")
    assert not probe(bow, "bow", {"count": meta["params"]["count"] + 1}).passed
    assert not probe(_motion("squat")[0], "bow", {}).passed
    assert not probe(_motion("raise_both_arms")[0], "stretch_arms", {}).passed
    assert not probe(_motion("reach_forward")[0], "push", {}).passed
    assert not probe(_motion("squat")[0], "sit_down", {}).passed
    assert not probe(_motion("kneel")[0], "lie_down", {}).passed
    assert not probe(_motion("walk_then_squat")[0], "walk_then_sit", {}).passed
