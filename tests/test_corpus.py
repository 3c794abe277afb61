"""The procedural corpus: HumanML3D format, determinism, physical plausibility, caption truth.

Physical measures (bone lengths, foot skating, floor, knees, facing) are computed here from
the written files with the test's own formulas, independently of the library's.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from controlmm.corpus import CorpusConfig, family_names, get_family, make_clip, write_corpus
from controlmm.corpus.dataset import ClipSpec
from controlmm.corpus.text.templates import HELD_SUBJECTS
from controlmm.motion import features_to_joints_np
from controlmm.motion.normalization import FEATURE_GROUPS
from controlmm.motion.skeleton import BONE_LENGTHS, PARENTS

N_CLIPS = 98  # two clips per family


@pytest.fixture(scope="module")
def corpus(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("corpus") / "c"
    write_corpus(out, CorpusConfig(clips=N_CLIPS, seed=123), workers=1, progress=False)
    return out


def _ids(root: Path, split: str) -> list[str]:
    return (root / f"{split}.txt").read_text().split()


def _facing(j: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Test's own facing: right-to-left 'across' from hips + shoulders; forward = up x across."""
    across = (j[..., 2, :] - j[..., 1, :]) + (j[..., 17, :] - j[..., 16, :])
    across[..., 1] = 0
    across /= np.linalg.norm(across, axis=-1, keepdims=True)
    fwd = np.cross([0.0, 1.0, 0.0], across)
    return fwd, -across


def _skating(j: np.ndarray) -> float:
    """Protocol foot skating (feet 10, 11; < 5 cm at t and t+1; > 0.5 m/s now and on a
    zero-padded 5-frame average), written out without the library."""
    feet = j[:, [10, 11]]
    v = np.linalg.norm(feet[1:, :, [0, 2]] - feet[:-1, :, [0, 2]], axis=-1) * 20.0
    padded = np.concatenate([np.zeros((2, 2)), v, np.zeros((2, 2))])
    avg = np.stack([padded[i : i + len(v)] for i in range(5)]).mean(0)
    contact = (feet[:-1, :, 1] < 0.05) & (feet[1:, :, 1] < 0.05)
    return float(np.any(contact & (v > 0.5) & (avg > 0.5), axis=1).sum() / (len(j) - 1))


def test_humanml3d_layout_and_round_trip(corpus):
    for name in ("new_joint_vecs", "new_joints", "texts", "meta"):
        assert (corpus / name).is_dir()
    train, val, test = (_ids(corpus, s) for s in ("train", "val", "test"))
    all_ids = _ids(corpus, "all")
    assert len(all_ids) == N_CLIPS and sorted(train + val + test) == sorted(all_ids)
    assert len(set(train) & set(test)) == 0 and len(test) == round(0.15 * N_CLIPS)
    for clip_id in all_ids:
        feats = np.load(corpus / "new_joint_vecs" / f"{clip_id}.npy")
        joints = np.load(corpus / "new_joints" / f"{clip_id}.npy")
        assert feats.dtype == np.float32 and feats.shape[1] == 263 and 40 <= len(feats) <= 196
        assert joints.dtype == np.float32 and joints.shape == (len(feats), 22, 3)
        np.testing.assert_array_equal(features_to_joints_np(feats), joints)  # exact round trip
        meta = json.loads((corpus / "meta" / f"{clip_id}.json").read_text())
        lines = (corpus / "texts" / f"{clip_id}.txt").read_text().splitlines()
        assert len(lines) >= 3 and len(set(lines)) == len(lines)
        assert [ln.split("#")[0] for ln in lines] == [c["text"] for c in meta["captions"]]
        for line in lines:
            caption, tokens, start, end = line.split("#")
            assert (start, end) == ("0.0", "0.0")
            words = caption.lower().replace("-", " ").replace(",", "").replace(".", "").split()
            pairs = [tok.split("/") for tok in tokens.split()]
            assert len(pairs) == len(words) and all(len(p) == 2 and p[1].isupper() for p in pairs)
        assert meta["frames"] == len(feats) and meta["family"] in family_names()


def test_mean_std_are_train_statistics_with_group_std(corpus):
    feats = np.concatenate(
        [np.load(corpus / "new_joint_vecs" / f"{i}.npy").astype(np.float64) for i in _ids(corpus, "train")]
    )
    mean, std = np.load(corpus / "Mean.npy"), np.load(corpus / "Std.npy")
    assert mean.shape == std.shape == (263,)
    np.testing.assert_allclose(mean, feats.mean(0), rtol=1e-5, atol=1e-6)
    for sl in FEATURE_GROUPS.values():
        np.testing.assert_allclose(std[sl], feats[:, sl].std(0).mean(), rtol=1e-4)


def test_deterministic_for_a_seed_whatever_the_workers(tmp_path):
    a, b, c = tmp_path / "a", tmp_path / "b", tmp_path / "c"
    write_corpus(a, CorpusConfig(clips=10, seed=7), workers=1, progress=False)
    write_corpus(b, CorpusConfig(clips=10, seed=7), workers=2, progress=False)
    write_corpus(c, CorpusConfig(clips=10, seed=8), workers=1, progress=False)
    files = sorted(p.relative_to(a) for p in a.rglob("*") if p.is_file())
    assert files == sorted(p.relative_to(b) for p in b.rglob("*") if p.is_file())
    for rel in files:
        assert (a / rel).read_bytes() == (b / rel).read_bytes(), rel
    assert (a / "new_joint_vecs" / "000000.npy").read_bytes() != (
        c / "new_joint_vecs" / "000000.npy"
    ).read_bytes()


def test_bones_floor_knees_and_foot_skating_measured_independently(corpus):
    skating = []
    for clip_id in _ids(corpus, "all"):
        j = np.load(corpus / "new_joints" / f"{clip_id}.npy").astype(np.float64)
        bones = np.linalg.norm(j[:, 1:] - j[:, list(PARENTS[1:])], axis=-1)
        assert np.abs(bones - BONE_LENGTHS[1:]).max() < 1e-5  # constant, reference lengths
        assert j[..., 1].min() == pytest.approx(0.0, abs=1e-6)  # floor at y = 0 ...
        assert j[:, [10, 11], 1].min() == pytest.approx(0.0, abs=1e-6)  # ... and the feet stand on it
        body = np.delete(j, [7, 8, 10, 11], axis=1)
        assert body[..., 1].min() > 0.03  # no knee/hand/pelvis through the floor
        for hip, knee, ankle, toe in ((1, 4, 7, 10), (2, 5, 8, 11)):
            axis = j[:, ankle] - j[:, hip]
            axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
            rel = j[:, knee] - j[:, hip]
            bend = rel - (rel * axis).sum(-1, keepdims=True) * axis
            foot = j[:, toe] - j[:, ankle]
            foot[:, 1] = 0
            assert (
                (bend * foot).sum(-1) / np.linalg.norm(foot, axis=-1)
            ).min() > -0.01  # knees never backwards
        steps = np.linalg.norm(np.diff(j, axis=0), axis=-1) * 20
        assert steps.max() < 15.0  # no teleporting joints (m/s)
        skating.append(_skating(j))
    assert np.mean(skating) <= 0.05 and max(skating) <= 0.1


def test_facing_convention_on_the_real_humanml3d_sample(sample_joints):
    fwd, left = _facing(sample_joints.astype(np.float64))
    np.testing.assert_allclose(fwd[0], [0, 0, 1], atol=1e-6)
    np.testing.assert_allclose(left[0], [1, 0, 0], atol=1e-6)
    assert sample_joints[0, 1, 0] > sample_joints[0, 2, 0]  # left hip on +X


def _clip(family: str, index: int, split: str = "train"):
    feats, joints, caps, meta = make_clip(ClipSpec(index, f"{index:06d}", family, split, seed=99))
    return joints.astype(np.float64), caps, meta


def _turn(j: np.ndarray) -> float:
    fwd, _ = _facing(j)
    h = np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2]))
    return float(np.degrees(h[-3:].mean() - h[:3].mean()))


@pytest.mark.parametrize("index", [0, 1])
def test_captions_tell_the_truth_about_sides_rotation_and_direction(index):
    # Left/right: the side moved to, in the start's own frame (+X is the person's left).
    for side, sign in (("left", 1), ("right", -1)):
        j, caps, _ = _clip(f"sidestep_{side}", index)
        fwd, left = _facing(j[:5])
        d = j[-1, 0] - j[0, 0]
        assert sign * (d @ left[0]) > 0.3 and all(
            f" {side}" in c.text or f"{side}ward" in c.text or f"the {side} " in c.text for c in caps
        )
        j, caps, _ = _clip(f"turn_{side}", index)
        assert sign * _turn(j) > 60
        j, caps, _ = _clip(f"wave_{side}", index)
        wrist, other = (20, 21) if side == "left" else (21, 20)
        assert (j[:, wrist, 1] - j[:, 15, 1]).max() > 0.1 and (j[:, other, 1] - j[:, 15, 1]).max() < 0
        assert all(f"{side} hand" in c.text or f"{side} arm" in c.text for c in caps)
    # Clockwise is a right turn (heading decreases), counter-clockwise a left turn.
    j, caps, _ = _clip("circle_cw", index)
    assert _turn(j) < -300 and not any("counter" in c.text or "anticlockwise" in c.text for c in caps)
    j, caps, _ = _clip("circle_ccw", index)
    assert _turn(j) > 300
    # Forward / backward: pelvis displacement along / against the facing direction.
    for family, sign in (("walk", 1), ("walk_backward", -1)):
        j, caps, _ = _clip(family, index)
        fwd, _ = _facing(j)
        along = (np.diff(j[:, 0], axis=0) * fwd[:-1]).sum()
        assert sign * along > 0.5
    j, caps, meta = _clip("jump_in_place", index)
    lows = j[:, [7, 8, 10, 11], 1].min(1)
    airborne = np.concatenate([[0], (lows > 0.1).astype(int), [0]])
    assert np.count_nonzero(np.diff(airborne) == 1) == meta["params"]["count"]


def test_held_out_phrasings_only_in_the_test_split(corpus):
    for split in ("train", "val", "test"):
        for clip_id in _ids(corpus, split):
            meta = json.loads((corpus / "meta" / f"{clip_id}.json").read_text())
            family = get_family(meta["family"])
            for cap in meta["captions"]:
                template = family.templates[int(cap["template"].split("/")[1])]
                assert cap["held_out"] == (split == "test")
                if split != "test":
                    assert not template.held
                    assert not any(
                        cap["text"].startswith(s) or f" {s} " in cap["text"] for s, _ in HELD_SUBJECTS
                    )
                    slots = family.slots(meta["params"])
                    held_words = {h for slot in slots.values() for h in slot.held}
                    assert not any(
                        h and h.replace("{poss}", "") in cap["text"] for h in held_words if len(h) > 6
                    )


def test_features_reproduce_the_joints_through_full_turns():
    from controlmm.corpus.processing import process
    from controlmm.motion import joints_to_features

    family = get_family("circle_ccw")
    rng = np.random.default_rng(5)
    raw = family.build(family.sample(rng), rng)
    features, joints, positions = process(raw)
    assert np.abs(joints - positions[:-1]).max() < 1e-4
    np.testing.assert_array_equal(features_to_joints_np(features), joints)
    # HumanML3D's processing as published flips the sign of the root rotation velocity of a
    # frame when the facing passes 180 degrees (HumanML3D issue #156); the corpus repairs it.
    plain, _ = joints_to_features(raw, regulate_turn_sign=False)
    assert np.abs(features_to_joints_np(plain) - positions[:-1]).max() > 0.05
    np.testing.assert_array_equal(plain[:, 1:], features[:, 1:])
