"""The paper preset is the released MoMask architecture: parameter counts, tensor names and shapes."""

from __future__ import annotations

import pytest
import torch

from controlmm.errors import ControlMMError
from controlmm.models import (
    RVQVAE,
    MaskTransformer,
    ModelConfig,
    ResidualTransformer,
    preset_config,
)


@pytest.fixture(scope="module")
def paper():
    cfg = preset_config("paper")
    return cfg, RVQVAE(cfg.tokenizer), MaskTransformer(cfg.transformer), ResidualTransformer(cfg.residual)


def _params(module: torch.nn.Module) -> int:
    return sum(p.numel() for p in module.parameters())


def test_paper_parameter_counts_match_the_verified_official_counts(paper):
    _, vq, mask, res = paper
    assert _params(vq) == 19_436_807
    assert _params(mask) == 12_048_768
    assert _params(res) == 13_364_224
    assert (len(vq.state_dict()), len(mask.state_dict()), len(res.state_dict())) == (72, 108, 112)


def test_rvqvae_tensor_names_and_shapes(paper):
    sd = paper[1].state_dict()
    expect = {
        "encoder.model.0.weight": (512, 263, 3),
        "encoder.model.2.0.weight": (512, 512, 4),
        "encoder.model.3.0.bias": (512,),
        "encoder.model.2.1.model.0.conv1.weight": (512, 512, 3),
        "encoder.model.3.1.model.2.conv2.weight": (512, 512, 1),
        "encoder.model.4.weight": (512, 512, 3),
        "decoder.model.0.weight": (512, 512, 3),
        "decoder.model.2.0.model.1.conv1.weight": (512, 512, 3),
        "decoder.model.3.2.weight": (512, 512, 3),
        "decoder.model.4.weight": (512, 512, 3),
        "decoder.model.6.weight": (263, 512, 3),
        "decoder.model.6.bias": (263,),
    }
    for i in range(6):
        expect[f"quantizer.layers.{i}.codebook"] = (512, 512)
    for name, shape in expect.items():
        assert tuple(sd[name].shape) == shape, name
    # Reversed dilations (9, 3, 1) in encoder and decoder residual stacks; Upsample at decoder.model.{2,3}.1.
    vq = paper[1]
    for stack in (
        vq.encoder.model[2][1],
        vq.encoder.model[3][1],
        vq.decoder.model[2][0],
        vq.decoder.model[3][0],
    ):
        assert [blk.conv1.dilation[0] for blk in stack.model] == [9, 3, 1]
    assert isinstance(vq.decoder.model[2][1], torch.nn.Upsample)


def test_mask_transformer_tensor_names_and_layout(paper):
    mask = paper[2]
    sd = mask.state_dict()
    expect = {
        "token_emb.weight": (514, 512),
        "input_process.poseEmbedding.weight": (384, 512),
        "position_enc.pe": (5000, 1, 384),
        "cond_emb.weight": (384, 512),
        "output_process.dense.weight": (384, 384),
        "output_process.LayerNorm.weight": (384,),
        "output_process.poseFinal.weight": (512, 384),
        "output_process.poseFinal.bias": (512,),
    }
    for i in range(8):
        expect[f"seqTransEncoder.layers.{i}.self_attn.in_proj_weight"] = (1152, 384)
        expect[f"seqTransEncoder.layers.{i}.linear1.weight"] = (1024, 384)
        expect[f"seqTransEncoder.layers.{i}.linear2.weight"] = (384, 1024)
        expect[f"seqTransEncoder.layers.{i}.norm2.bias"] = (384,)
    for name, shape in expect.items():
        assert tuple(sd[name].shape) == shape, name
    layer = mask.seqTransEncoder.layers[0]
    assert not layer.norm_first and layer.self_attn.num_heads == 6 and not layer.self_attn.batch_first
    assert layer.activation is torch.nn.functional.gelu or "gelu" in str(layer.activation).lower()
    assert mask.output_process.LayerNorm.eps == 1e-12
    assert (mask.mask_id, mask.pad_id) == (512, 513)


def test_residual_transformer_tensor_names_and_tied_projections(paper):
    res = paper[3]
    sd = res.state_dict()
    expect = {
        "embed_proj_shared_weight": (4, 513, 512),
        "token_embed_weight_": (1, 513, 512),
        "output_proj_weight_": (1, 513, 512),
        "input_process.poseEmbedding.weight": (384, 512),
        "position_enc.pe": (5000, 1, 384),
        "quant_emb.weight": (384, 6),
        "cond_emb.weight": (384, 512),
        "output_process.poseFinal.weight": (512, 384),
    }
    for name, shape in expect.items():
        assert tuple(sd[name].shape) == shape, name
    emb, proj = res.token_embed_weight, res.output_proj_weight
    assert emb.shape == proj.shape == (5, 513, 512)
    for q in range(1, 5):  # P_q = E_q for q = 1..4 (tied); P_5 and E_0 are their own tensors
        assert torch.equal(proj[q - 1], emb[q])
    assert not torch.equal(proj[4], emb[0])


def test_demo_preset_is_small_enough_to_ship():
    cfg = preset_config("demo")
    total = sum(
        _params(m)
        for m in (
            RVQVAE(cfg.tokenizer),
            MaskTransformer(cfg.transformer),
            MaskTransformer(cfg.token_view.transformer),
            ResidualTransformer(cfg.residual),
        )
    )
    assert cfg.storage_dtype == "float16" and cfg.text_encoder.name == "minilm"
    assert total * 2 / 2**20 < 16  # MiB as float16: room left for the control branch and the evaluator
    assert cfg.transformer.text_dim == 384


def test_config_round_trip_and_errors():
    cfg = preset_config("demo")
    assert ModelConfig.from_dict(cfg.to_dict()) == cfg
    with pytest.raises(ControlMMError, match="unknown preset 'huge'"):
        preset_config("huge")
    bad = cfg.to_dict()
    bad["residual"]["nb_code"] = 7
    with pytest.raises(ControlMMError, match="nb_code"):
        ModelConfig.from_dict(bad)
    bad = cfg.to_dict()
    bad["tokenizer"]["colour"] = 1
    with pytest.raises(ControlMMError, match="colour"):
        ModelConfig.from_dict(bad)


def test_tokenizer_shapes_and_latent_decoding():
    cfg = preset_config("tiny").tokenizer
    vq = RVQVAE(cfg).train()
    x = torch.randn(3, 48, 263)
    recon, commit, perplexity, ids = vq(x)
    assert recon.shape == x.shape and ids.shape == (3, 12, 3) and commit.ndim == 0
    vq.eval()
    ids = vq.encode(x)
    assert ids.shape == (3, 12, 3) and ids.min() >= 0 and ids.max() < cfg.nb_code
    latent = vq.ids_to_latent(ids)
    assert latent.shape == (3, 12, cfg.code_dim)
    manual = sum(vq.codebooks[q][ids[..., q]] for q in range(3))
    assert torch.allclose(latent, manual)
    assert torch.allclose(vq.decode(ids), vq.decode_latent(latent))
    # Fewer layers (or -1) contribute zero vectors.
    assert torch.allclose(vq.ids_to_latent(ids[..., :1]), vq.codebooks[0][ids[..., 0]])
    # Deterministic encoding equals the eval-mode straight-through path.
    quantized, ids2, _, _ = vq.quantizer(vq.encoder(x.permute(0, 2, 1)))
    assert torch.equal(ids, ids2)


def test_mask_transformer_ids_soft_embeddings_hooks_and_cfg():
    cfg = preset_config("tiny").transformer
    torch.manual_seed(0)
    model = MaskTransformer(cfg).eval()
    ids = torch.randint(0, cfg.nb_code, (2, 7))
    ids[1, 5:] = model.pad_id
    pad = torch.zeros(2, 7, dtype=torch.bool)
    pad[1, 5:] = True
    cond = torch.randn(2, cfg.text_dim)
    logits = model(ids, cond, pad)
    assert logits.shape == (2, 7, cfg.nb_code)
    soft = model.token_emb(ids)
    assert torch.allclose(model(soft, cond, pad), logits, atol=1e-6)
    # The explicit layer loop is nn.TransformerEncoder's forward.
    h, mask = model.embed(ids, cond, pad)
    ref = model.seqTransEncoder(h, src_key_padding_mask=mask)
    assert torch.allclose(model.run_layers(h, mask)[:, 0], ref[:, 0], atol=1e-5)
    calls = []
    out = model.head(model.run_layers(h, mask, hook=lambda i, x: (calls.append(i), x + 1.0)[1]), 7)
    assert calls == list(range(cfg.num_layers)) and not torch.allclose(out, logits)
    # CFG: l_u + s (l_c - l_u), with the unconditional pass on a zero text vector.
    uncond = model(ids, torch.zeros_like(cond), pad)
    assert torch.allclose(model.cfg_logits(ids, cond, pad, 4.0), uncond + 4.0 * (logits - uncond), atol=1e-5)
    assert torch.allclose(model(ids, cond, pad, force_mask=True), uncond)
    assert torch.allclose(model.cfg_logits(ids, cond, pad, 1.0), logits)


def test_condition_dropout_only_in_training():
    cfg = preset_config("tiny").transformer
    model = MaskTransformer(cfg)
    cond = torch.ones(4000, cfg.text_dim)
    model.train()
    dropped = (model.mask_cond(cond).abs().sum(-1) == 0).float().mean()
    assert 0.08 < float(dropped) < 0.12
    model.eval()
    assert torch.equal(model.mask_cond(cond), cond)


def test_residual_transformer_layer_logits_and_loss():
    cfg = preset_config("tiny").residual
    torch.manual_seed(0)
    model = ResidualTransformer(cfg).eval()
    ids = torch.randint(0, cfg.nb_code, (2, 6, cfg.num_quantizers))
    cond = torch.randn(2, cfg.text_dim)
    pad = torch.zeros(2, 6, dtype=torch.bool)
    history = model.history(ids, 2)
    emb = model.token_embed_weight
    assert torch.allclose(history, emb[0][ids[..., 0]] + emb[1][ids[..., 1]])
    logits = model(history, torch.tensor([2, 2]), cond, pad)
    assert logits.shape == (2, 6, cfg.nb_code + 1)
    loss, acc = model.residual_loss(ids, cond, torch.tensor([6, 4]))
    assert loss.ndim == 0 and torch.isfinite(loss) and 0 <= float(acc) <= 1


def test_text_norm_lifts_unit_length_text_vectors_to_unit_variance():
    demo, paper = preset_config("demo"), preset_config("paper")
    assert demo.transformer.text_norm and demo.residual.text_norm
    assert not paper.transformer.text_norm and not paper.residual.text_norm  # MoMask has no such layer
    plain_cfg = preset_config("tiny").transformer
    normed_cfg = ModelConfig.from_dict(
        {**preset_config("tiny").to_dict(), "transformer": {**plain_cfg.__dict__, "text_norm": True}}
    ).transformer
    torch.manual_seed(0)
    plain = MaskTransformer(plain_cfg).eval()
    normed = MaskTransformer(normed_cfg).eval()
    assert "text_norm.weight" in normed.state_dict() and not any("text_norm" in k for k in plain.state_dict())
    # A model without the layer still loads its own weights strictly; the new one has the layer on top.
    missing = normed.load_state_dict(plain.state_dict(), strict=False).missing_keys
    assert sorted(missing) == ["text_norm.bias", "text_norm.weight"]
    text = torch.nn.functional.normalize(torch.randn(3, plain_cfg.text_dim), dim=-1)  # as MiniLM's vectors
    ids = torch.randint(0, plain_cfg.nb_code, (3, 5))
    pad = torch.zeros(3, 5, dtype=torch.bool)
    with torch.no_grad():
        c_plain = plain.embed(ids, text, pad)[0][0]
        c_normed = normed.embed(ids, text, pad)[0][0]
    # Same cond_emb weights: only the LayerNorm differs, and it scales the unit vector by ~sqrt(text_dim).
    ratio = float(c_normed.norm() / c_plain.norm())
    assert 0.5 * plain_cfg.text_dim**0.5 < ratio < 2 * plain_cfg.text_dim**0.5
    # The unconditional pass does not depend on the text.
    assert torch.allclose(
        normed(ids, text, pad, force_mask=True), normed(ids, text.flip(0), pad, force_mask=True)
    )
    tiny = preset_config("tiny")
    res_cfg = ModelConfig.from_dict(
        {**tiny.to_dict(), "residual": {**tiny.residual.__dict__, "text_norm": True}}
    ).residual
    assert "text_norm.weight" in ResidualTransformer(res_cfg).state_dict()


def test_text_token_states_are_condition_rows_and_padding_is_ignored():
    cfg = preset_config("tiny").transformer
    torch.manual_seed(0)
    model = MaskTransformer(cfg).eval()
    ids = torch.randint(0, cfg.nb_code, (2, 6))
    pad = torch.zeros(2, 6, dtype=torch.bool)
    states = torch.randn(2, 5, cfg.text_dim)
    states[1, 3:] = 0  # the second text has 3 token states
    logits = model(ids, states, pad)
    assert logits.shape == (2, 6, cfg.nb_code)
    h, mask = model.embed(ids, states, pad)
    assert h.shape[0] == 5 + 6 and mask[1, 3:5].all() and not mask[0, :5].any()
    # Extra zero columns (longer padding) change nothing; dropping the second text's padding neither.
    longer = torch.cat([states, torch.zeros(2, 4, cfg.text_dim)], dim=1)
    assert torch.allclose(model(ids, longer, pad), logits, atol=1e-5)
    assert torch.allclose(model(ids[1:], states[1:, :3], pad[1:]), logits[1:], atol=1e-5)
    # The words matter, and an all-zero text is the unconditional pass.
    other = states.clone()
    other[0, 1] += 1.0
    assert not torch.allclose(model(ids, other, pad)[0], logits[0])
    assert torch.allclose(model(ids, torch.zeros_like(states), pad), model(ids, states, pad, force_mask=True))
    # The residual transformer pools token states into the sentence vector.
    from controlmm.models.layers import pool_text_tokens

    res = ResidualTransformer(preset_config("tiny").residual).eval()
    q_ids = torch.randint(0, cfg.nb_code, (2, 6, 3))
    history = res.history(q_ids, 1)
    q = torch.ones(2, dtype=torch.long)
    assert torch.allclose(
        res(history, q, states, pad), res(history, q, pool_text_tokens(states), pad), atol=1e-6
    )


def test_pooled_row_adds_the_sentence_vector_of_the_token_states():
    from dataclasses import replace

    from controlmm.models.layers import pool_text_tokens

    cfg = replace(preset_config("tiny").transformer, pooled_row=True)
    torch.manual_seed(0)
    model = MaskTransformer(cfg).eval()
    assert {"pooled_norm.weight", "pooled_emb.weight"} <= set(model.state_dict())
    ids = torch.randint(0, cfg.nb_code, (2, 6))
    pad = torch.zeros(2, 6, dtype=torch.bool)
    states = torch.randn(2, 5, cfg.text_dim)
    states[1, 3:] = 0
    h, mask = model.embed(ids, states, pad)
    # One pooled row first (never masked), then the 5 token rows (the second text's padding masked).
    assert h.shape[0] == 1 + 5 + 6 and not mask[:, 0].any() and mask[1, 4:6].all() and not mask[0, :6].any()
    pooled = model.pooled_emb(model.pooled_norm(pool_text_tokens(states)))
    assert torch.allclose(h[0], pooled, atol=1e-6)
    # Scaling every state of a text changes its token rows but not the pooled (normalised) row.
    assert torch.allclose(model.embed(ids, 3 * states, pad)[0][0], h[0], atol=1e-5)
    # The unconditional pass is still an all-zero text.
    logits = model(ids, states, pad)
    assert torch.allclose(model(ids, torch.zeros_like(states), pad), model(ids, states, pad, force_mask=True))
    assert not torch.allclose(model(ids, torch.zeros_like(states), pad), logits)


def test_word_dropout_zeroes_whole_token_states_only_while_training():
    from dataclasses import replace

    from controlmm.models.layers import text_token_padding

    cfg = replace(preset_config("tiny").transformer, cond_drop_prob=0.0, token_drop_prob=0.5)
    torch.manual_seed(0)
    model = MaskTransformer(cfg).train()
    states = torch.randn(64, 12, cfg.text_dim)
    dropped = model.mask_cond(states)
    gone = text_token_padding(dropped)
    # Whole rows are zeroed (they become padding), the others pass unchanged, about half of them.
    assert torch.equal(dropped[~gone], states[~gone])
    assert 0.4 < gone.float().mean() < 0.6
    assert len({tuple(r.tolist()) for r in gone}) > 1  # per caption, not one pattern for the batch
    # Sentence vectors, evaluation and token_drop_prob = 0 are left alone (and draw no random numbers).
    vectors = torch.randn(64, cfg.text_dim)
    assert torch.equal(model.mask_cond(vectors), vectors)
    assert torch.equal(model.eval().mask_cond(states), states)
    plain = MaskTransformer(replace(cfg, token_drop_prob=0.0)).train()
    before = torch.get_rng_state()
    assert torch.equal(plain.mask_cond(states), states)
    assert torch.equal(torch.get_rng_state(), before)


def test_token_drop_prob_must_be_a_probability():
    cfg = preset_config("demo").to_dict()
    cfg["token_view"]["transformer"]["token_drop_prob"] = 1.0
    with pytest.raises(ControlMMError, match="token_drop_prob must be in \\[0, 1\\); got 1.0"):
        ModelConfig.from_dict(cfg)
    cfg["token_view"]["transformer"]["token_drop_prob"] = 0.2
    assert ModelConfig.from_dict(cfg).token_view.transformer.token_drop_prob == 0.2


def test_pooled_row_needs_token_states():
    cfg = preset_config("tiny").to_dict()
    cfg["transformer"]["pooled_row"] = True
    with pytest.raises(ControlMMError, match="pooled_row needs text token states"):
        ModelConfig.from_dict(cfg)
    cfg["text_encoder"]["tokens"] = 16
    assert ModelConfig.from_dict(cfg).transformer.pooled_row


def test_text_tokens_need_minilm():
    cfg = preset_config("tiny").to_dict()
    cfg["text_encoder"]["tokens"] = 16
    assert ModelConfig.from_dict(cfg).text_encoder.tokens == 16
    cfg["text_encoder"]["tokens"] = 500
    with pytest.raises(ControlMMError, match="tokens must be 0 .* got 500"):
        ModelConfig.from_dict(cfg)
