"""The HumanML3D loader: the official quirks, the datasets, the sampler, malformed directories."""

from __future__ import annotations

import shutil
from dataclasses import replace

import numpy as np
import pytest

from controlmm.data import HumanML3D, StepBatchSampler, TextMotionDataset, WindowDataset
from controlmm.errors import ControlMMError, InputFileError
from controlmm.models.config import preset_config


def _write(root, motion_id, frames, lines, source):
    np.save(root / "new_joint_vecs" / f"{motion_id}.npy", source[:frames])
    (root / "texts" / f"{motion_id}.txt").write_text("\n".join(lines) + "\n")


@pytest.fixture()
def quirky(tmp_path, humanml3d_dir, sample_features):
    """Clips chosen to hit each rule of the official loader."""
    root = tmp_path / "hml"
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    long = np.concatenate([sample_features, sample_features])  # 340 frames
    _write(
        root,
        "whole",
        120,
        [
            "a person walks#a/DET person/NOUN walks/VERB#0.0#0.0",
            "someone walks#someone/PRON walks/VERB#nan#nan",
            "a person stops#a/DET person/NOUN stops/VERB#1.0#4.0",  # span: frames 20..80
            "a person blinks#a/DET#0.5#1.0",
        ],
        long,
    )  # span of 10 frames: dropped
    _write(root, "spanonly", 150, ["a person turns#x#2.0#6.0"], long)  # no whole caption: only the span
    _write(root, "short", 39, ["too short#x#0#0"], long)
    _write(root, "toolong", 200, ["too long#x#0#0", "long span#x#0.0#3.0"], long)  # skipped entirely
    (root / "train.txt").write_text("whole\nspanonly\nshort\ntoolong\n")
    (root / "val.txt").write_text("whole\n")
    (root / "test.txt").write_text("whole\n")
    shutil.copy(humanml3d_dir / "Mean.npy", root / "Mean.npy")
    shutil.copy(humanml3d_dir / "Std.npy", root / "Std.npy")
    return root, long


def test_official_span_and_length_rules(quirky):
    root, long = quirky
    data = HumanML3D(root)
    samples = {s.name: s for s in data.text_samples("train")}
    assert set(samples) == {"whole", "whole#2", "spanonly#0"}
    assert samples["whole"].captions == ["a person walks", "someone walks"]  # NaN start/end = whole motion
    assert samples["whole#2"].captions == ["a person stops"]
    np.testing.assert_array_equal(samples["whole#2"].motion, long[20:80])
    np.testing.assert_array_equal(samples["spanonly#0"].motion, long[40:120])
    assert len(data.motions("train", 64)) == 3  # tokenizer: whole files with >= 64 frames (toolong included)


def test_text_motion_items_round_pad_and_normalise(quirky):
    root, long = quirky
    data = HumanML3D(root)
    norm = data.normalizer
    samples = data.text_samples("train")
    sample = next(s for s in samples if s.name == "whole")
    ds = TextMotionDataset([sample], norm, {"a person walks": 0, "someone walks": 1}, seed=3)
    lengths, captions = [], set()
    for epoch in range(300):
        motion, m, cap = ds[(0, epoch)]
        lengths.append(m)
        captions.add(cap)
        assert motion.shape == (196, 263) and m % 4 == 0
        assert np.all(motion[m:].numpy() == 0)  # zero padding after normalisation
        # The crop is a normalised window of the source motion.
        window = motion[:m].numpy()
        raw = norm.denormalize(window)
        starts = [s for s in range(0, 120 - m + 1) if np.allclose(long[s : s + m], raw, atol=1e-4)]
        assert starts
    assert set(lengths) == {120, 116}  # single: 120; double: 116
    assert 0.25 < lengths.count(116) / len(lengths) < 0.42
    assert captions == {0, 1}
    again = ds[(0, 7)]
    assert again[1] == ds[(0, 7)][1] and np.array_equal(again[0], ds[(0, 7)][0])  # keyed by (index, epoch)


def test_window_dataset_and_sampler(quirky):
    root, _ = quirky
    data = HumanML3D(root)
    motions = data.motions("train", 64)
    ds = WindowDataset(motions, data.normalizer, window=64, seed=0)
    assert ds[(1, 0)].shape == (64, 263)
    full = list(StepBatchSampler(10, 4, seed=1, epoch=2))
    assert len(full) == 2 and all(len(b) == 4 for b in full)
    shards = [list(StepBatchSampler(10, 4, seed=1, epoch=2, rank=r, world=2)) for r in range(2)]
    for step in range(2):
        assert sorted(shards[0][step] + shards[1][step]) == sorted(full[step])
    assert list(StepBatchSampler(10, 4, seed=1, epoch=2, start_step=1)) == full[1:]
    assert full != list(StepBatchSampler(10, 4, seed=1, epoch=3))


def test_length_bucketing_keeps_the_epoch_and_groups_similar_lengths():
    lengths = np.random.default_rng(3).integers(40, 197, size=200)
    plain = StepBatchSampler(200, 8, seed=1, epoch=2).batches()
    bucketed = StepBatchSampler(200, 8, seed=1, epoch=2, lengths=lengths, bucket=5).batches()
    # the same items once each (the incomplete last batch is dropped either way), in other batches
    assert sorted(np.concatenate(bucketed).tolist()) == sorted(np.concatenate(plain).tolist())
    assert len(bucketed) == len(plain) == 25 and all(len(b) == 8 for b in bucketed)
    spread = [np.ptp(lengths[b]) for b in bucketed]
    assert np.mean(spread) < 0.5 * np.mean([np.ptp(lengths[b]) for b in plain])
    # a pure function of (seed, epoch): resumption, several processes and later epochs
    again = list(StepBatchSampler(200, 8, seed=1, epoch=2, lengths=lengths, bucket=5, start_step=3))
    assert again == [[(int(i), 2) for i in b] for b in bucketed[3:]]
    shards = [
        list(StepBatchSampler(200, 8, seed=1, epoch=2, lengths=lengths, bucket=5, rank=r, world=2))
        for r in range(2)
    ]
    assert sorted(shards[0][0] + shards[1][0]) == sorted((int(i), 2) for i in bucketed[0])
    other = StepBatchSampler(200, 8, seed=1, epoch=3, lengths=lengths, bucket=5).batches()
    assert any(not np.array_equal(a, b) for a, b in zip(bucketed, other, strict=True))
    with pytest.raises(ValueError, match="one length per item"):
        StepBatchSampler(200, 8, seed=1, epoch=2, lengths=lengths[:10], bucket=5)


def test_bucketing_only_where_batches_are_trimmed():
    cfg = preset_config("tiny")
    assert cfg.schedules["transformer"].bucket > 0 and cfg.schedules["tokenizer"].bucket == 0
    with pytest.raises(ControlMMError, match="schedule 'tokenizer': bucket must be 0"):
        replace(cfg, schedules={**cfg.schedules, "tokenizer": replace(cfg.schedules["tokenizer"], bucket=4)})
    with pytest.raises(ControlMMError, match="got -1"):
        replace(cfg, schedules={**cfg.schedules, "residual": replace(cfg.schedules["residual"], bucket=-1)})


@pytest.mark.parametrize(
    "breakage,needle",
    [
        (lambda r: shutil.rmtree(r / "new_joint_vecs"), "no 'new_joint_vecs/' folder"),
        (lambda r: (r / "Std.npy").unlink(), "has no Std.npy"),
        (lambda r: np.save(r / "Mean.npy", np.zeros(10)), "Mean.npy' must hold a finite (263,) array"),
        (lambda r: (r / "train.txt").unlink(), "has no train.txt"),
        (lambda r: (r / "train.txt").write_text("whole\nghost\n"), "'ghost' is listed but"),
        (lambda r: (r / "texts" / "spanonly.txt").unlink(), "spanonly.txt' does not exist"),
        (
            lambda r: np.save(r / "new_joint_vecs" / "short.npy", np.zeros((50, 22, 3))),
            "must hold (T, 263) features",
        ),
        (lambda r: np.save(r / "new_joint_vecs" / "short.npy", np.full((50, 263), np.nan)), "non-finite"),
        (
            lambda r: (r / "texts" / "whole.txt").write_text("just a caption\n"),
            "line 1: expected 'caption#tokens#start#end'",
        ),
        (lambda r: (r / "texts" / "whole.txt").write_text("a#b#x#y\n"), "are not numbers"),
    ],
)
def test_malformed_directories_name_the_problem(quirky, breakage, needle):
    root, _ = quirky
    breakage(root)
    with pytest.raises(InputFileError) as info:
        HumanML3D(root).text_samples("train")
    assert needle in str(info.value) and "\n" not in str(info.value)


def test_missing_directory(tmp_path):
    with pytest.raises(InputFileError, match="does not exist"):
        HumanML3D(tmp_path / "none")
