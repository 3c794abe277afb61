"""Text-view ensemble: the token-state transformer (``token_view``): config, training stage, decoding."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import pytest
import torch

from controlmm.cli.main import main
from controlmm.data import HumanML3D
from controlmm.errors import ControlMMError
from controlmm.generate import (
    DecodeOptions,
    DecodeState,
    generate,
    load_model,
    masked_decode,
    token_view_logits_fn,
)
from controlmm.models.config import ModelConfig, preset_config
from controlmm.models.mask_transformer import MaskTransformer
from controlmm.motion import load_motion
from controlmm.text.config import TextEncoderConfig
from controlmm.training import TrainOptions, train
from controlmm.training.model_stage import StageContext
from controlmm.training.transformer import WARM_START_SKIP, TokenTransformerStage, warm_start


@pytest.fixture(scope="module")
def view_dir(tmp_path_factory, tiny_model_dir, tiny_data):
    """The tiny model plus a token-state transformer trained for a few iterations."""
    out = tmp_path_factory.mktemp("view") / "tiny"
    shutil.copytree(tiny_model_dir, out)
    train("token_transformer", TrainOptions(data=tiny_data, out=out, iters=12, progress=False, device="cpu"))
    return out


def test_config_round_trip_and_errors():
    cfg = preset_config("tiny")
    assert cfg.token_view is not None and ModelConfig.from_dict(cfg.to_dict()) == cfg
    assert preset_config("paper").token_view is None
    data = cfg.to_dict()
    for change, needle in [
        ({"weight": 1.0}, "weight must be between 0 and 1"),
        ({"tokens": 0}, "1..128 tokens"),
        (
            {"transformer": {**data["token_view"]["transformer"], "text_dim": 512}},
            "must match the tokenizer and the text encoder",
        ),
    ]:
        with pytest.raises(ControlMMError, match=needle):
            ModelConfig.from_dict({**data, "token_view": {**data["token_view"], **change}})
    # switching to CLIP drops the view (token states are MiniLM's); old model.json files have none
    assert cfg.with_text_encoder(TextEncoderConfig(name="clip")).token_view is None
    assert ModelConfig.from_dict({k: v for k, v in data.items() if k != "token_view"}).token_view is None


def test_stage_writes_part_trained_on_the_tokenizer(view_dir):
    manifest = json.loads((view_dir / "model.json").read_text())
    entry = manifest["parts"]["token_transformer"]
    assert entry["trained_on"]["tokenizer"] == manifest["parts"]["tokenizer"]["sha256"]
    assert manifest["training"]["token_transformer"]["iterations"] == 12
    model = load_model(view_dir)
    member, cfg = model.token_transformer, model.config.token_view
    assert member is not None and member.cfg == cfg.transformer
    states = model.encode_token_states(["a person squats slowly", "someone bends"])
    assert (
        states.ndim == 3 and states.shape[0] == 2 and states.shape[1] <= cfg.tokens
    )  # (B, L <= tokens, 384)
    assert load_model(view_dir, parts=("tokenizer", "transformer")).token_transformer is None


def test_one_text_pass_gives_both_views_exactly(view_dir):
    model = load_model(view_dir)
    texts = [
        "jump",
        "a person squats slowly",
        "someone walks forward a few steps, turns around to the left, waves the right hand twice "
        "and then walks back to where they started from before sitting down on the floor",
    ]  # > the token limit
    cond, states = model.encode_text_views(texts)
    assert torch.equal(cond, model.encode_text(texts))
    assert torch.equal(states, model.encode_token_states(texts))
    assert states.shape[1] == model.config.token_view.tokens and not states[0, 3:].any()  # [CLS] jump [SEP]
    alone, none = load_model(view_dir, parts=("tokenizer", "transformer")).encode_text_views(texts)
    assert none is None and torch.equal(alone, cond)


def test_decoding_mixes_both_views(view_dir):
    model = load_model(view_dir)
    texts = ["a person squats slowly", "someone bends over and comes back"]
    fn = token_view_logits_fn(model, texts, cfg_scale=4.0)
    cond = model.encode_text(texts)
    ids = torch.full((2, 10), model.transformer.mask_id)
    padding = torch.zeros(2, 10, dtype=torch.bool)
    padding[1, 7:] = True
    ids[1, 7:] = model.transformer.pad_id
    state = DecodeState(step=0, ids=ids, is_mask=~padding, padding_mask=padding, cond=cond)
    mixed = fn(ids, state)
    sentence = torch.log_softmax(model.transformer.cfg_logits(ids, cond, padding, 4.0), -1)
    states = model.encode_token_states(texts)
    tokens = torch.log_softmax(model.token_transformer.cfg_logits(ids, states, padding, 4.0), -1)
    w = model.config.token_view.weight
    assert torch.allclose(mixed, (1 - w) * sentence + w * tokens, atol=1e-5)
    assert not torch.allclose(mixed, sentence, atol=1e-3)  # the second view changes the table

    # generate(): the view is used by default and recorded; token_view=False equals the model without it
    both = generate(model, texts, frames=[60, 48], seed=3)
    alone = generate(model, texts, frames=[60, 48], seed=3, token_view=False)
    without = generate(
        load_model(view_dir, parts=("tokenizer", "transformer", "residual")), texts, frames=[60, 48], seed=3
    )
    assert both.motion.metadata["token_view"] and not alone.motion.metadata["token_view"]
    assert torch.equal(alone.ids, without.ids) and not torch.equal(both.ids, alone.ids)
    base = masked_decode(
        model.transformer,
        cond,
        torch.tensor([15, 12]),
        DecodeOptions(),
        torch.Generator().manual_seed(3),
        logits_fn=fn,
    )
    assert torch.equal(base.ids, both.ids[..., 0])  # generate() decodes the base layer exactly so


def test_cli_stage_and_missing_view(view_dir, tiny_data, tmp_path, capsys):
    out = tmp_path / "old"
    shutil.copytree(view_dir, out)
    manifest = json.loads((out / "model.json").read_text())
    del manifest["config"]["token_view"]
    (out / "model.json").write_text(json.dumps(manifest))
    code = main(
        [
            "train",
            "token-transformer",
            "--data",
            str(tiny_data),
            "--out",
            str(out),
            "--force",
            "--no-progress",
        ]
    )
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "has no token_view in its configuration" in err, err


def test_warm_start_copies_all_but_the_attention_layers(view_dir, tiny_model_dir, tiny_data):
    """The stage starts from the sentence-vector transformer's embeddings, text projection and head; its
    attention layers start fresh. ``warm_start`` without ``skip`` copies every shared tensor."""

    source = load_model(tiny_model_dir).transformer
    theirs = source.state_dict()
    cfg = load_model(view_dir).config.token_view.transformer
    deeper = MaskTransformer(replace(cfg, num_layers=cfg.num_layers + 1))
    fresh = {k: v.clone() for k, v in deeper.state_dict().items()}
    warm = warm_start(deeper, source).state_dict()
    extra = f"seqTransEncoder.layers.{cfg.num_layers}."
    for k, v in warm.items():
        assert torch.equal(v, theirs[k] if not k.startswith(extra) else fresh[k]), k
    assert any(k.startswith(extra) for k in warm)
    member = MaskTransformer(cfg)
    fresh = {k: v.clone() for k, v in member.state_dict().items()}
    partial = warm_start(member, source, skip=WARM_START_SKIP).state_dict()
    layers = [k for k in partial if k.startswith(WARM_START_SKIP)]
    assert layers and "token_emb.weight" not in layers and "output_process.poseFinal.weight" not in layers
    for k, v in partial.items():
        assert torch.equal(v, fresh[k] if k in layers else theirs[k]), k
    assert not torch.equal(partial[layers[0]], theirs[layers[0]])
    # the stage builds its member that way from the model directory's trained transformer
    model = load_model(view_dir)
    ctx = StageContext(
        config=model.config,
        data=HumanML3D(tiny_data),
        normalizer=model.normalizer,
        model_dir=view_dir,
        device=torch.device("cpu"),
        seed=0,
        progress=False,
        base=load_model(view_dir, parts=TokenTransformerStage.requires),
    )
    built = TokenTransformerStage(ctx).build_model().state_dict()
    for k, v in built.items():
        assert k in layers or torch.equal(v, theirs[k]), k
    assert not any(torch.equal(built[k], theirs[k]) for k in layers if k.endswith("linear1.weight"))
    manifest = json.loads((view_dir / "model.json").read_text())
    assert set(manifest["parts"]["token_transformer"]["trained_on"]) == {"tokenizer", "transformer"}
    with pytest.raises(ControlMMError, match="shares no tensor"):
        warm_start(torch.nn.Linear(2, 2), source)


def test_cli_generate_uses_the_view_unless_told_not_to(view_dir, tmp_path, capsys):
    for flag, used in (([], True), (["--no-token-view"], False)):
        out = tmp_path / f"m{used}.npz"
        code = main(
            [
                "generate",
                "--text",
                "a person squats slowly",
                "--frames",
                "48",
                "--seed",
                "1",
                "--model",
                str(view_dir),
                "--out",
                str(out),
            ]
            + flag
        )
        assert code == 0, capsys.readouterr().err
        assert load_motion(out).metadata["token_view"] is used
