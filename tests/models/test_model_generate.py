"""Generation: lengths, determinism, batches, CFG, hooks, residual layers, latents, loading errors."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest
import torch

from controlmm.errors import ControlMMError, InputFileError
from controlmm.generate import (
    DecodeOptions,
    frames_for,
    generate,
    latent_to_joints,
    load_model,
    mask_counts,
    masked_decode,
)
from controlmm.models.layers import top_k_filter


@pytest.fixture(scope="module")
def model(tiny_model_dir):
    return load_model(tiny_model_dir)


def test_mask_schedule_matches_momask():
    counts = [int(c[0]) for c in mask_counts(torch.tensor([49]), 10)]
    assert counts == [49, 48, 46, 42, 38, 31, 24, 17, 9, 1]
    assert int((top_k_filter(torch.randn(2, 512), 0.9) > -float("inf")).sum(-1)[0]) == 52


def test_lengths_from_seconds_or_frames():
    assert frames_for(2, seconds=6) == [120, 120]
    assert frames_for(2, frames=[40, 196]) == [40, 196]
    assert frames_for(1) == [120]
    for kwargs, needle in [
        (dict(seconds=12), "length 12 s (240 frames) is out of range"),
        (dict(frames=39), "allowed 40..196 frames"),
        (dict(frames=[50]), "1 lengths given for 2 prompts"),
        (dict(seconds=3, frames=60), "not both"),
    ]:
        with pytest.raises(ControlMMError, match=needle.replace("(", r"\(").replace(")", r"\)")):
            frames_for(2, **kwargs)


def test_shapes_lengths_and_outputs(model):
    result = generate(model, ["a person squats slowly", "someone bends over"], frames=[101, 48], seed=0)
    assert [m.num_frames for m in result.motions] == [101, 48]  # 26 tokens decoded, cropped to 101 frames
    for motion, text in zip(result.motions, result.texts, strict=True):
        assert motion.joints.shape[1:] == (22, 3) and motion.features.shape[1] == 263
        assert motion.fps == 20.0 and motion.text == text and motion.metadata["seed"] == 0
        np.testing.assert_allclose(motion.joints[0, 0, [0, 2]], 0.0, atol=1e-6)  # starts at the origin
    q = model.config.tokenizer.num_quantizers
    assert result.ids.shape == (2, 26, q)
    assert torch.all(result.ids[1, 12:] == -1) and torch.all(result.ids[0] >= 0)  # 48 frames = 12 tokens
    assert result.base_logits.shape == (2, 26, model.config.transformer.nb_code)
    assert len(result.residual_logits) == q - 1 and result.residual_logits[0].shape == (2, 26, 33)
    assert torch.allclose(result.latent, model.tokenizer.ids_to_latent(result.ids))
    joints = latent_to_joints(model, result.latent)
    np.testing.assert_allclose(joints[0, :101].numpy(), result.motions[0].joints, atol=1e-5)


def test_seed_makes_generation_reproducible(model):
    a = generate(model, "a person squats slowly", seconds=3, seed=7)
    b = generate(model, "a person squats slowly", seconds=3, seed=7)
    c = generate(model, "a person squats slowly", seconds=3, seed=8)
    assert torch.equal(a.ids, b.ids) and np.array_equal(a.motion.joints, b.motion.joints)
    assert not torch.equal(a.ids, c.ids)
    base_only = generate(model, "a person squats slowly", seconds=3, seed=7, use_residual=False)
    assert base_only.ids.shape[-1] == 1 and torch.equal(base_only.ids[..., 0], a.ids[..., 0])
    one_layer = generate(model, "a person squats slowly", seconds=3, seed=7, residual_layers=1)
    assert one_layer.ids.shape[-1] == 2 and torch.equal(one_layer.ids, a.ids[..., :2])
    assert len(one_layer.residual_logits) == 1
    with pytest.raises(ControlMMError, match="residual_layers must be in 0..2"):
        generate(model, "a person squats slowly", seconds=3, residual_layers=5)


def test_guidance_scale_changes_the_sampling_distribution(model):
    cond = model.encode_text(["a person squats slowly"])
    lengths = torch.tensor([10])
    gen = torch.Generator().manual_seed(0)
    plain = masked_decode(model.transformer, cond, lengths, DecodeOptions(cfg_scale=1.0), gen)
    pad = torch.zeros(1, 10, dtype=torch.bool)
    ids = torch.full((1, 10), model.transformer.mask_id)
    expect = model.transformer(ids, cond, pad)
    guided = model.transformer.cfg_logits(ids, cond, pad, 4.0)
    uncond = model.transformer(ids, torch.zeros_like(cond), pad)
    assert torch.allclose(guided, uncond + 4.0 * (expect - uncond), atol=1e-5)
    assert plain.ids.shape == (1, 10)


def test_logits_hook_controls_every_iteration(model):
    cond = model.encode_text(["a person squats slowly", "someone bends over"])
    lengths = torch.tensor([12, 7])
    steps = []

    def force_code_3(logits, state):
        steps.append(state.step)
        assert state.is_mask.shape == (2, 12) and torch.all(~state.is_mask[1, 7:])
        edited = logits.clone()
        edited[..., 3] += 100.0
        return edited

    out = masked_decode(
        model.transformer,
        cond,
        lengths,
        DecodeOptions(iterations=5),
        torch.Generator().manual_seed(0),
        logits_hook=force_code_3,
    )
    assert steps == [0, 1, 2, 3, 4]
    assert torch.all(out.ids[0] == 3) and torch.all(out.ids[1, :7] == 3) and torch.all(out.ids[1, 7:] == -1)
    assert out.logits[0, 0, 3] > 50  # the returned logits are the edited ones


def test_greedy_decoding_is_deterministic_without_seed(model):
    opts = DecodeOptions(temperature=0.0)
    a = generate(model, "someone bends over", frames=60, options=opts, residual_temperature=0.0)
    b = generate(model, "someone bends over", frames=60, options=opts, residual_temperature=0.0)
    assert torch.equal(a.ids, b.ids)


def test_bad_inputs(model):
    with pytest.raises(ControlMMError, match="text must not be empty"):
        generate(model, "   ", seconds=3)
    with pytest.raises(ControlMMError, match="no text given"):
        generate(model, [], seconds=3)
    with pytest.raises(ControlMMError, match="out of range"):
        generate(model, "a person squats", seconds=10.5)


@pytest.fixture()
def copy_of_model(tiny_model_dir, tmp_path):
    target = tmp_path / "model"
    shutil.copytree(tiny_model_dir, target, ignore=shutil.ignore_patterns("checkpoints", "cache"))
    return target


def test_loading_errors_are_one_line(copy_of_model, tmp_path):
    with pytest.raises(InputFileError, match="does not exist"):
        load_model(tmp_path / "nowhere")
    (copy_of_model / "transformer.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(InputFileError, match="transformer.pt' is corrupt"):
        load_model(copy_of_model)
    (copy_of_model / "transformer.pt").unlink()
    with pytest.raises(InputFileError, match="has no transformer.pt"):
        load_model(copy_of_model)
    partial = load_model(copy_of_model, parts=("tokenizer",))
    with pytest.raises(ControlMMError, match="has no trained transformer"):
        generate(partial, "a person squats", seconds=3)
    manifest = json.loads((copy_of_model / "model.json").read_text())
    manifest["format_version"] = 99
    (copy_of_model / "model.json").write_text(json.dumps(manifest))
    with pytest.raises(InputFileError, match="format version 99"):
        load_model(copy_of_model)
    (copy_of_model / "model.json").unlink()
    with pytest.raises(InputFileError, match="model.json is missing"):
        load_model(copy_of_model)


def test_truncated_part_and_wrong_shapes(copy_of_model):
    data = (copy_of_model / "residual.pt").read_bytes()
    (copy_of_model / "residual.pt").write_bytes(data[: len(data) // 2])
    with pytest.raises(InputFileError, match="residual.pt' is corrupt"):
        load_model(copy_of_model)
    manifest = json.loads((copy_of_model / "model.json").read_text())
    manifest["config"]["transformer"]["latent_dim"] = 64
    manifest["config"]["transformer"]["num_heads"] = 2
    manifest["parts"].pop("residual")
    (copy_of_model / "model.json").write_text(json.dumps(manifest))
    with pytest.raises(InputFileError, match="does not fit the configured model; .*wrong shape"):
        load_model(copy_of_model)


def test_float16_storage_round_trip(tiny_model_dir, tmp_path, model):
    from controlmm.models.model_dir import load_part_state, save_part

    entry = save_part(tmp_path, "transformer", model.transformer, "float16")
    raw = torch.load(tmp_path / "transformer.pt", weights_only=True)["state_dict"]
    assert raw["token_emb.weight"].dtype == torch.float16 and entry["dtype"] == "float16"
    loaded = load_part_state(tmp_path, "transformer", entry)
    assert loaded["token_emb.weight"].dtype == torch.float32
    assert torch.allclose(loaded["token_emb.weight"], model.transformer.token_emb.weight, atol=1e-3)


def test_default_model_is_found_without_configuration():
    from controlmm.assets import default_model_dir

    if (default_model_dir() / "model.json").is_file():
        model = load_model()
        assert model.directory == default_model_dir() and "transformer" in model.parts
    else:
        with pytest.raises(InputFileError, match="no embedded default model"):
            load_model()


def test_embedded_checkpoints_fit_the_size_budget():
    """Everything under controlmm/checkpoints (default model, evaluator) stays within 25 MiB."""
    from controlmm.assets import CHECKPOINT_ROOT

    size = sum(p.stat().st_size for p in CHECKPOINT_ROOT.rglob("*") if p.is_file())
    assert 0 < size <= 25 * 2**20, size


def test_embedded_default_has_the_demo_preset_architecture():
    """The shipped model is what `controlmm train ... --preset demo` builds (its schedules included)."""
    from dataclasses import fields

    from controlmm.assets import default_model_dir
    from controlmm.models.config import ModelConfig, preset_config

    manifest = json.loads((default_model_dir() / "model.json").read_text())
    shipped, demo = ModelConfig.from_dict(manifest["config"]), preset_config("demo")
    for f in fields(demo):
        if f.name != "schedules":
            assert getattr(shipped, f.name) == getattr(demo, f.name), f.name
    for stage, schedule in shipped.schedules.items():
        assert schedule == demo.schedules[stage], stage
    assert set(manifest["parts"]) == {"tokenizer", "transformer", "token_transformer", "residual", "control"}
