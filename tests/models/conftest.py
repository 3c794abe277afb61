"""Fixtures of the model tests: a tiny HumanML3D-format dataset and a tiny trained model directory.

The dataset is built from the real HumanML3D sample 012314 (crops, left/right mirror, time stretch)
with made-up captions, written exactly in the HumanML3D layout. The trained model uses the ``tiny``
preset for a few dozen iterations per stage: enough to exercise every code path, not to be good.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
import torch
from torch_threads import one_thread

from controlmm.motion import joints_to_features
from controlmm.motion.container import resample
from controlmm.motion.skeleton import LEFT_RIGHT_MIRROR

CAPTIONS = [
    "a person bends down and stands back up",
    "someone crouches then rises",
    "a man leans forward and straightens",
    "the person squats slowly",
    "a person reaches down to the floor",
    "someone bends over and comes back",
]


def _caption_line(text: str, start: float = 0.0, end: float = 0.0) -> str:
    tokens = " ".join(f"{w}/OTHER" for w in text.split())
    return f"{text}#{tokens}#{start}#{end}"


def build_tiny_dataset(root: Path, features: np.ndarray, joints: np.ndarray, stats: Path) -> Path:
    """Write a 16-clip HumanML3D-format directory under ``root`` and return it."""
    mirrored = joints.copy()
    mirrored[..., 0] *= -1
    mirrored = mirrored[:, list(LEFT_RIGHT_MIRROR)]
    mirror_feats, _ = joints_to_features(mirrored)
    slow_feats, _ = joints_to_features(resample(joints, 24.0, 20.0))  # 1.2x slower
    sources = [features, mirror_feats, slow_feats]
    (root / "new_joint_vecs").mkdir(parents=True)
    (root / "texts").mkdir()
    rng = np.random.default_rng(0)
    ids = []
    for k in range(16):
        src = sources[k % 3]
        length = int(rng.integers(48, min(len(src), 180)))
        start = int(rng.integers(0, len(src) - length + 1))
        clip = src[start : start + length].astype(np.float32)
        motion_id = f"{k:06d}"
        np.save(root / "new_joint_vecs" / f"{motion_id}.npy", clip)
        lines = [_caption_line(CAPTIONS[(k + j) % len(CAPTIONS)]) for j in range(3)]
        if k % 4 == 0 and length >= 90:  # a span caption becomes its own sample
            lines.append(_caption_line("a person holds still", 0.5, 0.5 + 44 / 20))
        (root / "texts" / f"{motion_id}.txt").write_text("\n".join(lines) + "\n")
        ids.append(motion_id)
    (root / "train.txt").write_text("\n".join(ids[:11]) + "\n")
    (root / "val.txt").write_text("\n".join(ids[11:14]) + "\n")
    (root / "test.txt").write_text("\n".join(ids[14:]) + "\n")
    shutil.copy(stats / "Mean.npy", root / "Mean.npy")
    shutil.copy(stats / "Std.npy", root / "Std.npy")
    return root


@pytest.fixture(scope="session")
def tiny_data(tmp_path_factory, humanml3d_dir, sample_features, sample_joints) -> Path:
    return build_tiny_dataset(
        tmp_path_factory.mktemp("data") / "tiny", sample_features, sample_joints, humanml3d_dir
    )


@pytest.fixture(scope="session")
def tiny_model_dir(tmp_path_factory, tiny_data) -> Path:
    """A model directory with every part trained on the tiny dataset (tiny preset)."""
    from controlmm.training import TrainOptions, train

    out = tmp_path_factory.mktemp("model") / "tiny"
    with one_thread():
        for stage, iters in (("tokenizer", 30), ("transformer", 20), ("residual", 20)):
            train(
                stage,
                TrainOptions(
                    data=tiny_data, out=out, preset="tiny", iters=iters, progress=False, device="cpu"
                ),
            )
    return out


@pytest.fixture(autouse=True, scope="module")
def _one_torch_thread():
    with one_thread():
        yield


def subprocess_env() -> dict:
    """Environment of CLI subprocesses in these tests: one thread, offline."""
    import os

    env = dict(os.environ)
    env.update(OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", HF_HUB_OFFLINE="1", TRANSFORMERS_OFFLINE="1")
    return env


def _byte_vocab() -> dict[str, int]:
    """A byte-level BPE vocabulary without merges (every byte, and every byte ending a word)."""
    keep = (
        list(range(ord("!"), ord("~") + 1)) + list(range(ord("¡"), ord("¬") + 1)) + list(range(ord("®"), 256))
    )
    chars, extra = [], 0
    for b in range(256):
        chars.append(chr(b) if b in keep else chr(256 + extra))
        extra += b not in keep
    vocab = {c: i for i, c in enumerate(chars)}
    vocab.update({c + "</w>": 256 + i for i, c in enumerate(chars)})
    vocab["<|startoftext|>"] = 512
    vocab["<|endoftext|>"] = 513
    return vocab


@pytest.fixture(scope="session")
def tiny_clip_dir(tmp_path_factory):
    """A randomly initialised CLIPModel + tokenizer written with save_pretrained (nothing downloaded)."""
    from transformers import CLIPConfig, CLIPModel, CLIPTokenizer

    vocab = _byte_vocab()
    torch.manual_seed(0)
    config = CLIPConfig(
        text_config=dict(
            vocab_size=len(vocab),
            hidden_size=32,
            intermediate_size=64,
            num_hidden_layers=2,
            num_attention_heads=2,
            max_position_embeddings=77,
            bos_token_id=512,
            eos_token_id=513,
            pad_token_id=513,
        ),
        vision_config=dict(
            hidden_size=32,
            intermediate_size=64,
            num_hidden_layers=1,
            num_attention_heads=2,
            image_size=32,
            patch_size=16,
        ),
        projection_dim=24,
    )
    path = tmp_path_factory.mktemp("clip") / "tiny-clip"
    CLIPModel(config).save_pretrained(path)
    CLIPTokenizer(vocab=vocab, merges=[]).save_pretrained(path)
    return path


@pytest.fixture(scope="session")
def tiny_control_dir(tmp_path_factory, tiny_data, tiny_model_dir) -> Path:
    """A copy of the tiny model directory with a motion control model (all joints) trained on top."""
    from controlmm.training import TrainOptions, train

    out = tmp_path_factory.mktemp("control") / "tiny"
    shutil.copytree(tiny_model_dir, out, ignore=shutil.ignore_patterns("checkpoints"))
    with one_thread():
        train(
            "control",
            TrainOptions(
                data=tiny_data,
                out=out,
                iters=20,
                progress=False,
                device="cpu",
                stage_options={"joints": "all"},
            ),
        )
    return out
