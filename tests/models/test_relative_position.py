"""Relative position bias of the masked transformer: starts as MoMask, depends only on token offsets,
learns, carries over to the motion control model, and round-trips through the config."""

from __future__ import annotations

from dataclasses import replace

import pytest
import torch

from controlmm.errors import ControlMMError
from controlmm.models import MaskTransformer, ModelConfig, MotionControlModel, preset_config
from controlmm.models.layers import lengths_to_mask

K = 4


def _pair(seed: int = 0) -> tuple[MaskTransformer, MaskTransformer]:
    """The tiny preset's transformer without and with the bias, same weights, eval mode."""
    torch.manual_seed(seed)
    cfg = preset_config("tiny").transformer
    plain = MaskTransformer(cfg).eval()
    biased = MaskTransformer(replace(cfg, relative_positions=K)).eval()
    missing = biased.load_state_dict(plain.state_dict(), strict=False).missing_keys
    assert missing == ["relative_bias.table"]
    return plain, biased


def _inputs(model: MaskTransformer, n: int = 10) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    lengths = torch.tensor([n, 7, 3])
    padding = ~lengths_to_mask(lengths, n)
    ids = torch.randint(0, model.cfg.nb_code, (3, n)).masked_fill(padding, model.pad_id)
    ids[0, :3] = model.mask_id
    return ids, torch.randn(3, model.cfg.text_dim), padding


def test_a_zero_table_is_momask_and_a_trained_one_depends_only_on_offsets():
    plain, biased = _pair()
    ids, cond, padding = _inputs(plain)
    states = torch.randn(3, 5, plain.cfg.text_dim)  # token states: 5 condition rows, the last text 2 long
    states[2, 2:] = 0
    with torch.no_grad():
        for text in (cond, states):
            assert torch.equal(biased(ids, text, padding), plain(ids, text, padding))
            assert torch.equal(
                biased.cfg_logits(ids, text, padding, 4.0), plain.cfg_logits(ids, text, padding, 4.0)
            )
        biased.relative_bias.table.normal_()
        assert not torch.allclose(biased(ids, cond, padding), plain(ids, cond, padding))

    n, heads = ids.shape[1], plain.cfg.num_heads
    _, key_padding = biased.embed(ids, cond, padding)  # (B, 1 + N): one condition row
    mask = biased.attention_mask(key_padding, n, torch.float32).view(3, heads, n + 1, n + 1)
    table = biased.relative_bias.table.detach()
    for i in range(n):
        for j in range(7):  # keys valid in the first two samples
            offset = max(-K, min(K, j - i)) + K
            assert torch.equal(mask[:2, :, 1 + i, 1 + j], table[offset].expand(2, heads))
    assert torch.equal(mask[0, :, 0, :], torch.zeros(heads, n + 1))  # the condition row: no bias
    assert torch.equal(mask[0, :, 1:, 0], torch.zeros(heads, n))
    assert (
        torch.isinf(mask[1, :, :, 1 + 7 :]).all() and torch.isinf(mask[2, :, :, 1 + 3 :]).all()
    )  # padded keys
    assert torch.isfinite(mask[2, :, :, : 1 + 3]).all()


def test_the_table_learns_and_the_base_raises_without_num_tokens():
    _, biased = _pair()
    biased.train()
    ids, cond, padding = _inputs(biased)
    loss, _ = biased.masked_loss(ids.clamp(max=biased.cfg.nb_code - 1), cond, (~padding).sum(1))
    loss.backward()
    assert biased.relative_bias.table.grad.abs().sum() > 0
    h, mask = biased.embed(ids, cond, padding)
    with pytest.raises(ValueError, match="num_tokens"):
        biased.run_layers(h, mask)


def test_zero_initialised_control_model_equals_a_biased_base():
    cfg = preset_config("tiny")
    cfg = replace(cfg, transformer=replace(cfg.transformer, relative_positions=K))
    torch.manual_seed(1)
    base = MaskTransformer(cfg.transformer).eval()
    with torch.no_grad():
        base.relative_bias.table.normal_()
    control = MotionControlModel(cfg).init_from_base(base).eval()
    ids, cond, padding = _inputs(base, n=8)
    ctrl = torch.randn(3, cfg.control.channels, 4 * 8)
    with torch.no_grad():
        assert torch.equal(control(base, ids, cond, padding, ctrl), base(ids, cond, padding))
        torch.nn.init.normal_(control.first_zero_linear.weight, std=0.1)
        assert not torch.allclose(control(base, ids, cond, padding, ctrl), base(ids, cond, padding))


def test_config_round_trip_and_a_negative_distance():
    data = preset_config("tiny").to_dict()
    data["token_view"]["transformer"]["relative_positions"] = 16
    cfg = ModelConfig.from_dict(data)
    assert cfg.token_view.transformer.relative_positions == 16 and cfg.transformer.relative_positions == 0
    assert ModelConfig.from_dict(cfg.to_dict()) == cfg
    data["transformer"]["relative_positions"] = -1
    with pytest.raises(ControlMMError, match="relative_positions must be 0"):
        ModelConfig.from_dict(data)
