"""Motion control model and masked consistency training: structure, zero-init equivalence, control input,
control masks, one training step, the ``control`` stage and its model-directory part."""

from __future__ import annotations

import json
from dataclasses import replace

import pytest
import torch

from controlmm.errors import ControlMMError
from controlmm.generate import load_model
from controlmm.models import ControlConfig, MotionControlModel, control_input
from controlmm.models.config import preset_config
from controlmm.models.layers import lengths_to_mask
from controlmm.models.motion_control_model import estimate_latent, mask_embedding
from controlmm.training import TrainOptions, train
from controlmm.training.control import ControlLoss, ControlTraining, sample_control_mask, token_probabilities

CONTROL = (0, 10, 11, 15, 20, 21)


@pytest.fixture(scope="module")
def model(tiny_model_dir):
    return load_model(tiny_model_dir)


def test_paper_preset_matches_the_official_control_branch():
    """Names, tensor count and shapes of MaskControl's ControlTransformer branch (MaskControl's
    released `ct2m_transformer` checkpoints)."""
    for joints, channels in (("pelvis", 6), ("all", 36)):
        cfg = replace(preset_config("paper"), control=ControlConfig(joints=joints))
        state = MotionControlModel(cfg).state_dict()
        assert len(state) == 96 + 32 + 2 + 16
        assert {k.split(".")[0] for k in state} == {
            "seqTransEncoder_control",
            "encoder_control",
            "first_zero_linear",
            "mid_zero_linear",
        }
        assert state["encoder_control.model.0.weight"].shape == (512, channels, 3)
        assert state["encoder_control.model.2.0.weight"].shape == (512, 512, 4)
        assert state["encoder_control.model.3.1.model.2.conv2.weight"].shape == (512, 512, 1)
        assert state["encoder_control.model.4.weight"].shape == (384, 512, 3)
        assert state["mid_zero_linear.7.weight"].shape == (384, 384)
        assert state["seqTransEncoder_control.layers.7.linear1.weight"].shape == (1024, 384)
        if joints == "pelvis":  # the verified trainable parameter count of the official pelvis model
            assert sum(v.numel() for v in state.values()) == 21_372_160


def test_zero_initialised_model_equals_the_base(model):
    base = model.transformer
    control = MotionControlModel(model.config).init_from_base(base).eval()
    torch.manual_seed(0)
    b, n = 3, 12
    lengths = torch.tensor([12, 9, 5])
    padding = ~lengths_to_mask(lengths, n)
    ids = torch.randint(0, base.cfg.nb_code, (b, n)).masked_fill(padding, base.pad_id)
    ids[0, :4] = base.mask_id
    cond = torch.randn(b, base.cfg.text_dim)
    states = torch.randn(b, 5, base.cfg.text_dim)  # text token states, the third text 2 tokens long
    states[2, 2:] = 0
    ctrl = torch.randn(b, model.config.control.channels, 4 * n)
    with torch.no_grad():
        for text in (cond, states):
            assert torch.equal(control(base, ids, text, padding, ctrl), base(ids, text, padding))
            assert torch.equal(
                control.cfg_logits(base, ids, text, padding, ctrl, 4.0),
                base.cfg_logits(ids, text, padding, 4.0),
            )
        # trained zero linears make the control matter
        torch.nn.init.normal_(control.first_zero_linear.weight, std=0.1)
        assert not torch.allclose(control(base, ids, cond, padding, ctrl), base(ids, cond, padding))


def test_control_input_channels():
    b, t = 2, 8
    targets = torch.arange(b * t * 22 * 3, dtype=torch.float32).reshape(b, t, 22, 3) / 100
    current = torch.full((b, t, 22, 3), 0.5)
    mask = torch.zeros(b, t, 22, dtype=torch.bool)
    mask[0, 3, 0] = True  # pelvis
    mask[1, 5, 21] = True  # right wrist
    mask[1, 6, 7] = True  # left ankle: not a control joint, never seen by the branch
    x = control_input(targets, mask, current, CONTROL)
    assert x.shape == (b, 36, t)
    # channel layout [rel j0 xyz, rel j10, ..., rel j21, abs j0 xyz, ..., abs j21]
    torch.testing.assert_close(x[0, 0:3, 3], targets[0, 3, 0] - 0.5)
    torch.testing.assert_close(x[0, 18:21, 3], targets[0, 3, 0])
    torch.testing.assert_close(x[1, 15:18, 5], targets[1, 5, 21] - 0.5)
    torch.testing.assert_close(x[1, 33:36, 5], targets[1, 5, 21])
    assert int((x != 0).sum()) == 12
    pelvis = control_input(targets, mask, current, (0,))
    assert pelvis.shape == (b, 6, t) and int((pelvis != 0).sum()) == 6


def test_current_motion_estimate_uses_the_mean_code_where_unknown():
    codebook = torch.randn(16, 4)
    ids = torch.tensor([[3, 17, 5, 16]])  # 16/17 = mask/pad ids of a 16-code model
    known = torch.tensor([[True, False, True, False]])
    latent = estimate_latent(ids, codebook, known)
    torch.testing.assert_close(latent[0, 0], codebook[3])
    torch.testing.assert_close(latent[0, 1], mask_embedding(codebook))
    torch.testing.assert_close(latent[0, 3], codebook.mean(0))


def test_control_masks_follow_the_modes():
    gen = torch.Generator().manual_seed(0)
    lengths = torch.tensor([40, 80, 196, 12] * 8)
    for mode in ("trajectory", "random", "cross", "mixed"):
        mask = sample_control_mask(lengths, 196, CONTROL, mode, "mixed", gen)
        assert mask.shape == (32, 196, 22)
        counts = mask.flatten(1).sum(-1)
        assert bool((counts >= 1).all())
        for i, m in enumerate(lengths.tolist()):
            assert not mask[i, m:].any()  # only valid frames
        joints_used = mask.any(1)
        assert not joints_used[:, [j for j in range(22) if j not in CONTROL]].any()
        if mode == "trajectory":
            assert not joints_used[:, 1:].any()
        if mode == "random":
            assert bool((joints_used.sum(-1) == 1).all())
    dense = sample_control_mask(torch.tensor([196] * 64), 196, (0,), "trajectory", "uniform", gen)
    frames = dense[..., 0].sum(-1)
    assert int(frames.min()) >= 1 and int(frames.max()) > 150  # from one frame to (nearly) every frame


@pytest.mark.skipif(not torch.cuda.is_available(), reason="no CUDA device on this machine")
def test_control_masks_take_a_cuda_generator():
    """The control stage validates with a generator on its device; on CUDA that once crashed here."""
    lengths = torch.tensor([40, 196], device="cuda")
    first = sample_control_mask(
        lengths, 196, CONTROL, "mixed", "mixed", torch.Generator("cuda").manual_seed(0)
    )
    again = sample_control_mask(
        lengths, 196, CONTROL, "mixed", "mixed", torch.Generator("cuda").manual_seed(0)
    )
    assert first.device.type == "cuda" and torch.equal(first, again) and bool(first.any())


def test_straight_through_gumbel_is_one_hot_forward_and_soft_backward():
    logits = torch.randn(2, 5, 7, requires_grad=True)
    p = token_probabilities(logits, "gumbel", 1.0, torch.Generator().manual_seed(0))
    assert torch.equal(p.detach().sum(-1), torch.ones(2, 5)) and set(p.detach().unique().tolist()) <= {
        0.0,
        1.0,
    }
    (p * torch.arange(7.0)).sum().backward()
    assert logits.grad.abs().sum() > 0
    soft = token_probabilities(logits.detach(), "softmax")
    torch.testing.assert_close(soft, torch.softmax(logits.detach(), -1))


def _batch(model, tiny_data):
    from controlmm.data.datasets import TextMotionDataset
    from controlmm.data.humanml3d import HumanML3D
    from controlmm.motion.recover import features_to_joints

    samples = HumanML3D(tiny_data).text_samples("train")
    index = {c: i for i, c in enumerate(sorted({c for s in samples for c in s.captions}))}
    ds = TextMotionDataset(samples, model.normalizer, index, unit=4, seed=0)
    motion, lengths, caption = torch.utils.data.default_collate([ds[(i, 0)] for i in range(8)])
    ids = model.tokenizer.encode(motion)[..., 0]
    targets = features_to_joints(model.normalizer.denormalize(motion))
    cond = model.encode_text(sorted(index)).index_select(0, caption)
    return ids, targets, cond, lengths // 4, lengths


def test_one_training_step_reduces_the_consistency_loss(model, tiny_data):
    batch = _batch(model, tiny_data)
    settings = ControlTraining(estimator="softmax", alpha=0.1, cond_drop=0.0)
    for estimator, steps in (("softmax", 1), ("gumbel", 3)):
        torch.manual_seed(0)
        control = MotionControlModel(model.config).init_from_base(model.transformer)
        loss_fn = ControlLoss(
            control,
            model.transformer,
            model.tokenizer,
            model.normalizer,
            replace(settings, estimator=estimator),
        )
        assert [n for n, _ in loss_fn.named_parameters()] == [
            f"control.{n}" for n, _ in control.named_parameters()
        ]
        # measured with the deterministic expectation (the straight-through forward is piecewise constant)
        probe = ControlLoss(control, model.transformer, model.tokenizer, model.normalizer, settings)

        def consistency(probe: ControlLoss = probe) -> float:
            with torch.no_grad():
                return float(probe(*batch, generator=torch.Generator().manual_seed(3))[1]["ctrl"])

        before = consistency()
        opt = torch.optim.AdamW(control.parameters(), lr=2e-3)
        for _ in range(steps):
            loss, metrics = loss_fn(*batch, generator=torch.Generator().manual_seed(3))
            assert set(metrics) == {"loss", "ce", "acc", "ctrl"}
            torch.testing.assert_close(loss, 0.1 * metrics["ce"] + 0.9 * metrics["ctrl"])
            opt.zero_grad()
            loss.backward()
            assert control.first_zero_linear.weight.grad.abs().sum() > 0
            opt.step()
        assert consistency() < before, estimator


def test_control_stage_writes_a_loadable_part(tiny_control_dir, tiny_model_dir, tiny_data):
    manifest = json.loads((tiny_control_dir / "model.json").read_text())
    assert set(manifest["parts"]) == {"tokenizer", "transformer", "residual", "control"}
    assert manifest["config"]["control"]["joints"] == "all"
    part = manifest["parts"]["control"]
    assert part["trained_on"] == {
        "tokenizer": manifest["parts"]["tokenizer"]["sha256"],
        "transformer": manifest["parts"]["transformer"]["sha256"],
    }
    record = manifest["training"]["control"]
    assert record["consistency_training"]["estimator"] == "gumbel" and record["iterations"] == 20
    assert "val_hard_err_cm" in record["best"]
    loaded = load_model(tiny_control_dir)
    assert isinstance(loaded.parts["control"], MotionControlModel)
    assert loaded.parts["control"].encoder_control.model[0].in_channels == 36
    # a second run needs --resume or --force; --joints cannot change under --resume
    with pytest.raises(ControlMMError, match="--resume"):
        train("control", TrainOptions(data=tiny_data, out=tiny_control_dir, iters=1, progress=False))
    with pytest.raises(ControlMMError, match="--joints pelvis does not match"):
        train(
            "control",
            TrainOptions(
                data=tiny_data,
                out=tiny_control_dir,
                iters=21,
                progress=False,
                resume=True,
                stage_options={"joints": "pelvis"},
            ),
        )
    with pytest.raises(ControlMMError, match="unknown estimator 'argmax'"):
        ControlTraining(estimator="argmax")
