"""Importing the official MoMask / MaskControl checkpoints (``controlmm import-official``).

State_dicts are built with exactly the official names and shapes (random values), saved in the official
folder layout, imported, and the loaded modules must reproduce an independent re-implementation of the
official forward passes (``official_reference``) to 1e-5.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import torch

from controlmm.cli.main import main
from controlmm.errors import ControlMMError, InputFileError
from controlmm.models import load_model, preset_config
from controlmm.models.model_dir import PARTS, load_state_strict
from controlmm.models.motion_control_model import control_input
from controlmm.models.official import import_official, map_official_state, read_opt
from tests.models.official_reference import (
    Dims,
    official_control_state,
    official_mask_state,
    official_residual_state,
    official_vq_state,
    ref_control_input,
    ref_control_logits,
    ref_mask_logits,
    ref_residual_logits,
    ref_vq_decode,
    write_official_checkpoints,
    write_opt,
)

TOL = 1e-5
D = Dims()


@pytest.fixture(autouse=True)
def _one_thread():
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


def _write_evaluator(root):
    t2m = root / "checkpoints" / "t2m"
    (t2m / "text_mot_match" / "model").mkdir(parents=True)
    torch.save(
        {
            "movement_encoder": {"w": torch.zeros(2)},
            "text_encoder": {"w": torch.zeros(2)},
            "motion_encoder": {"w": torch.zeros(2)},
            "epoch": 1,
        },
        t2m / "text_mot_match" / "model" / "finest.tar",
    )
    (t2m / "Comp_v6_KLD005" / "meta").mkdir(parents=True)
    np.save(t2m / "Comp_v6_KLD005" / "meta" / "mean.npy", np.zeros(263, np.float32))
    np.save(t2m / "Comp_v6_KLD005" / "meta" / "std.npy", np.ones(263, np.float32))
    (root / "glove").mkdir()
    np.save(root / "glove" / "our_vab_data.npy", np.zeros((2, 300), np.float32))
    for name, obj in (("our_vab_words.pkl", ["unk", "walk"]), ("our_vab_idx.pkl", {"unk": 0, "walk": 1})):
        with open(root / "glove" / name, "wb") as fh:
            pickle.dump(obj, fh)


@pytest.fixture(scope="module")
def official(tmp_path_factory):
    """Tiny official checkpoints (all-joint control model) + evaluator files, and their import."""
    torch.set_num_threads(1)
    root = tmp_path_factory.mktemp("official")
    tree = write_official_checkpoints(root, D, control_channels=36)
    _write_evaluator(root)
    out = import_official(tree["t2m"], root / "model", control=tree["control_dir"], evaluator=root)
    return tree, out


def _inputs(n=6, b=3, seed=0):
    gen = torch.Generator().manual_seed(seed)
    ids = torch.randint(0, D.nb_code, (b, n), generator=gen)
    lengths = torch.tensor([n, n - 2, 1][:b])
    pad = torch.arange(n)[None] >= lengths[:, None]
    cond = torch.randn(b, D.text_dim, generator=gen)
    return ids, pad, cond, gen


def test_opt_txt_values(tmp_path):
    path = tmp_path / "opt.txt"
    write_opt(
        path,
        {
            "n_heads": 6,
            "dropout": 0.2,
            "share_weight": True,
            "vq_norm": None,
            "milestones": [50000],
            "name": "t2m_nlayer8",
            "clip_version": "ViT-B/32",
        },
    )
    opt = read_opt(path)
    assert opt == {
        "clip_version": "ViT-B/32",
        "dropout": 0.2,
        "milestones": [50000],
        "n_heads": 6,
        "name": "t2m_nlayer8",
        "share_weight": True,
        "vq_norm": None,
    }
    path.write_text("------------ Options -------------\nno separator here\n")
    with pytest.raises(InputFileError, match="line 2"):
        read_opt(path)


def test_released_sizes_load_strictly_into_the_paper_preset():
    """Official trees at the released sizes: the tensor counts of the released checkpoints and a
    strict load."""
    d = Dims.paper()
    vq, base, res = (
        official_vq_state(d, empty=True),
        official_mask_state(d, empty=True),
        official_residual_state(d, empty=True),
    )
    ctrl = official_control_state(d, 6, empty=True, base=base, vq=vq)
    assert (len(vq), len(base), len(res), len(ctrl)) == (72, 108, 112, 326)
    split = map_official_state("control", ctrl)  # every ct2m tensor lands in exactly one part
    assert {k: len(v) for k, v in split.items()} == {"tokenizer": 72, "transformer": 108, "control": 146}
    parts = {**split, **map_official_state("residual", res)}
    cfg = preset_config("paper")
    cfg = type(cfg)(**{**cfg.__dict__, "control": type(cfg.control)(joints="pelvis")})
    for name, state in parts.items():
        load_state_strict(PARTS[name].build(cfg), state, name)  # raises on any missing/extra/misshapen tensor


def test_import_reproduces_the_official_forward(official):
    tree, out = official
    model = load_model(out)
    ids, pad, cond, gen = _inputs()
    with torch.no_grad():
        # RVQ-VAE decode from token ids, some layers dropped (-1) as the official decoder allows.
        all_ids = torch.randint(0, D.nb_code, (3, 6, D.num_q), generator=gen)
        all_ids[0, :, 2:] = -1
        ours = model.tokenizer.decode(all_ids)
        ref = ref_vq_decode(tree["vq"], all_ids, D)
        assert ours.shape == (3, 24, 263)
        torch.testing.assert_close(ours, ref, atol=TOL, rtol=0)
        # Masked transformer: ids and soft embeddings, valid positions.
        valid = ~pad
        ours = model.transformer(ids, cond, pad)
        ref = ref_mask_logits(tree["base"], ids, cond, pad, D)
        torch.testing.assert_close(ours[valid], ref[valid], atol=TOL, rtol=0)
        probs = torch.softmax(torch.randn(3, 6, D.nb_code, generator=gen), -1)
        soft = probs @ tree["base"]["token_emb.weight"][: D.nb_code]
        torch.testing.assert_close(
            model.transformer(soft, cond, pad)[valid],
            ref_mask_logits(tree["base"], soft, cond, pad, D)[valid],
            atol=TOL,
            rtol=0,
        )
        # Residual transformer, every layer q, with the shared/tied projections.
        res_ids = torch.where(pad[..., None], D.nb_code, all_ids.clamp(min=0))
        for q in range(1, D.num_q):
            history = model.residual.history(res_ids, q)
            ours = model.residual(history, torch.full((3,), q), cond, pad)
            ref = ref_residual_logits(tree["res"], res_ids, q, cond, pad, D)
            torch.testing.assert_close(ours[valid], ref[valid], atol=TOL, rtol=0)
        # Control branch: control input (36 channels) and logits with non-zero zero-linears.
        targets = torch.randn(3, 24, 22, 3, generator=gen)
        current = torch.randn(3, 24, 22, 3, generator=gen)
        mask = torch.rand(3, 24, 22, generator=gen) < 0.3
        ctrl_in = control_input(targets, mask, current, model.parts["control"].joint_ids)
        torch.testing.assert_close(
            ctrl_in, ref_control_input(targets, mask, current, trajectory=False), atol=0, rtol=0
        )
        ours = model.parts["control"](model.transformer, ids, cond, pad, ctrl_in)
        ref = ref_control_logits(tree["ctrl"], ids, cond, pad, ctrl_in, D)
        torch.testing.assert_close(ours[valid], ref[valid], atol=TOL, rtol=0)
        assert (ref - ref_mask_logits(tree["base"], ids, cond, pad, D))[
            valid
        ].abs().max() > 1e-2  # control matters


def test_import_writes_a_paper_model_directory(official):
    tree, out = official
    model = load_model(out)
    manifest = model.manifest
    assert model.config.preset == "paper" and model.config.control.joints == "all"
    assert model.config.text_encoder.name == "clip" and model.config.text_encoder.precision == "float16"
    assert model.config.text_encoder.dim == D.text_dim and model.config.transformer.num_heads == D.heads
    assert sorted(manifest["parts"]) == ["control", "residual", "tokenizer", "transformer"]
    assert (
        manifest["parts"]["control"]["trained_on"]["transformer"]
        == manifest["parts"]["transformer"]["sha256"]
    )
    assert manifest["official"]["sources"]["control"]["control"] == "cross"
    assert "transformer.num_layers: paper 8 -> 2" in manifest["official"]["differs_from_paper_preset"]
    # Normalisation: the VQ folder's meta files, unchanged (they already hold the Std/25 quirk).
    np.testing.assert_array_equal(model.normalizer.mean, tree["mean"])
    np.testing.assert_array_equal(model.normalizer.std, tree["std"])
    # Evaluator files copied in MoMask's layout.
    assert (out / "evaluator" / "text_mot_match" / "model" / "finest.tar").is_file()
    assert (out / "evaluator" / "glove" / "our_vab_idx.pkl").is_file()
    assert manifest["official"]["evaluator"]["path"] == "evaluator"
    assert any(
        n.startswith("evaluator Comp_v6_KLD005/meta vs the VQ meta") for n in manifest["official"]["notes"]
    )


def test_pelvis_model_and_control_checkpoint_copies_win(tmp_path):
    """6-channel (pelvis) control; a control checkpoint whose VQ differs from MoMask's is used as is."""
    tree = write_official_checkpoints(tmp_path, D, control_channels=6, control_vq_same=False)
    out = import_official(
        tree["t2m"], tmp_path / "model", control=tree["control_dir"] / "model" / "latest.tar"
    )
    model = load_model(out)
    assert model.config.control.joints == "pelvis" and model.parts["control"].joint_ids == (0,)
    ctrl_vq = {k[len("vq_model.") :]: v for k, v in tree["ctrl"].items() if k.startswith("vq_model.")}
    torch.testing.assert_close(
        model.tokenizer.codebooks[1], ctrl_vq["quantizer.layers.1.codebook"], atol=0, rtol=0
    )
    assert any(
        "tokenizer: taken from the control checkpoint" in n and "max |diff|" in n
        for n in model.manifest["official"]["notes"]
    )
    assert model.manifest["official"]["sources"]["tokenizer"]["weights_from"].endswith("latest.tar")
    ids, pad, cond, gen = _inputs(n=4, b=2, seed=1)
    targets, current = torch.randn(2, 16, 22, 3, generator=gen), torch.randn(2, 16, 22, 3, generator=gen)
    mask = torch.rand(2, 16, 22, generator=gen) < 0.5
    ctrl_in = control_input(targets, mask, current, (0,))
    torch.testing.assert_close(
        ctrl_in, ref_control_input(targets, mask, current, trajectory=True), atol=0, rtol=0
    )
    with torch.no_grad():
        ours = model.parts["control"](model.transformer, ids, cond, pad, ctrl_in)
        ref = ref_control_logits(tree["ctrl"], ids, cond, pad, ctrl_in, D)
    torch.testing.assert_close(ours[~pad], ref[~pad], atol=TOL, rtol=0)


def _expect_error(match, **kwargs):
    with pytest.raises(ControlMMError) as info:
        import_official(**kwargs)
    message = str(info.value)
    assert "\n" not in message
    for m in [match] if isinstance(match, str) else match:
        assert m in message, message


def test_mismatches_are_one_line_errors(tmp_path):
    tree = write_official_checkpoints(tmp_path, D, control_channels=None)
    res_file = tree["t2m"] / "tres_nlayer8_ld384_ff1024_rvq6ns_cdp0.2_sw" / "model" / "net_best_fid.tar"
    original = torch.load(res_file, weights_only=True)
    bad = dict(original["res_transformer"])
    bad["quant_emb.bias"] = torch.zeros(D.latent + 1)
    bad["extra.weight"] = torch.zeros(1)
    del bad["output_process.dense.bias"]
    torch.save({"res_transformer": bad}, res_file)
    _expect_error(
        ["missing: output_process.dense.bias", "unexpected: extra.weight", "wrong shape: quant_emb.bias"],
        momask=tmp_path,
        out=tmp_path / "m",
    )
    torch.save({"something": {}}, res_file)
    _expect_error("has no 'res_transformer' entry", momask=tmp_path, out=tmp_path / "m")
    res_file.write_bytes(b"not a checkpoint")
    _expect_error(
        "is not a valid checkpoint (not a file written by torch.save)", momask=tmp_path, out=tmp_path / "m"
    )
    torch.save(original, res_file)
    _expect_error("--control", momask=tmp_path, out=tmp_path / "m", control=tmp_path / "nowhere")
    ctrl_tree = write_official_checkpoints(tmp_path / "c", D, control_channels=36)
    ctrl_file = ctrl_tree["control_dir"] / "model" / "latest.tar"
    payload = torch.load(ctrl_file, weights_only=True)
    payload["ct2m_transformer"]["vq_model.decoder.model.0.bias"] = torch.zeros(3)
    torch.save(payload, ctrl_file)
    _expect_error(
        [f"{ctrl_file} (tokenizer)", "wrong shape: decoder.model.0.bias"],
        momask=ctrl_tree["t2m"],
        out=tmp_path / "m",
        control=ctrl_tree["control_dir"],
    )
    vq_dir = tree["t2m"] / "rvq_nq6_dc512_nc512_noshare_qdp0.2"
    _expect_error("expected one tokenizer folder", momask=vq_dir, out=tmp_path / "m")
    (vq_dir / "meta" / "std.npy").unlink()
    _expect_error("meta/std.npy' is missing", momask=tmp_path, out=tmp_path / "m")
    assert not (tmp_path / "m").exists()  # nothing half-written


def test_a_vq_checkpoint_saved_as_net_is_accepted(tmp_path):
    """Some releases save the RVQ-VAE as {'net': state_dict}; the official loaders accept it too."""
    tree = write_official_checkpoints(tmp_path, D, control_channels=None)
    vq_file = tree["t2m"] / "rvq_nq6_dc512_nc512_noshare_qdp0.2" / "model" / "net_best_fid.tar"
    state = torch.load(vq_file, weights_only=True)["vq_model"]
    torch.save({"net": state, "ep": 3}, vq_file)
    out = import_official(tree["t2m"], tmp_path / "model")  # checks every tensor's name and shape
    tokenizer = torch.load(out / "tokenizer.pt", weights_only=True)["state_dict"]
    key = "quantizer.layers.0.codebook"
    torch.testing.assert_close(tokenizer[key].float(), state[key].float())


def test_cli_import_then_generate(official, tmp_path, tiny_clip_dir, capsys):
    tree, _ = official
    out = tmp_path / "imported"
    args = [
        "import-official",
        "--momask",
        str(tree["t2m"]),
        "--control",
        str(tree["control_dir"]),
        "--out",
        str(out),
    ]
    assert main(args) == 0
    assert "wrote" in capsys.readouterr().out
    assert main(args) == 2  # exists: needs --force
    assert "--force" in capsys.readouterr().err
    assert main(args + ["--force", "--clip-precision", "float32"]) == 0
    motion = tmp_path / "m.npz"
    code = main(
        [
            "generate",
            "--model",
            str(out),
            "--clip-weights",
            str(tiny_clip_dir),
            "--text",
            "a person walks",
            "--frames",
            "40",
            "--seed",
            "0",
            "--out",
            str(motion),
            "--iterations",
            "2",
        ]
    )
    assert code == 0, capsys.readouterr().err
    from controlmm.motion import load_motion

    assert load_motion(motion).joints.shape == (40, 22, 3)


def test_clip_float16_as_the_official_code(tiny_clip_dir):
    """Official CLIP: float16 weights, LayerNorms computed in float32, HTML-unescaped text, no
    normalisation."""
    from controlmm.text import load_text_encoder
    from controlmm.text.config import TextEncoderConfig

    half = load_text_encoder(TextEncoderConfig(name="clip", precision="float16"), weights=str(tiny_clip_dir))
    full = load_text_encoder(TextEncoderConfig(name="clip", precision="float32"), weights=str(tiny_clip_dir))
    norms = [m for m in half.text_model.modules() if isinstance(m, torch.nn.LayerNorm)]
    linears = [m for m in half.text_model.modules() if isinstance(m, torch.nn.Linear)]
    assert norms and all(m.weight.dtype == torch.float32 for m in norms)
    assert linears and all(m.weight.dtype == torch.float16 for m in linears)
    texts = ["a person walks &amp; waves", "someone   jumps\ttwice"]
    a, b = half.encode(texts), full.encode(texts)
    assert a.dtype == torch.float32 and a.shape == b.shape == (2, 24)
    assert 0 < (a - b).abs().max() < 2e-2 * b.abs().max()  # float16 rounding only
    torch.testing.assert_close(
        full.encode(["a person walks & waves", "someone jumps twice"]), b, atol=0, rtol=0
    )


def test_float64_forward_matches_to_rounding(official):
    """In float64 the imported modules and the reference agree to 1e-10: the float32 gaps are rounding
    only."""
    tree, out = official
    model = load_model(out)
    ids, pad, cond, gen = _inputs(seed=3)
    cond, valid = cond.double(), ~pad
    sd = {name: {k: v.double() for k, v in tree[name].items()} for name in ("vq", "res", "ctrl")}
    with torch.no_grad():
        all_ids = torch.randint(0, D.nb_code, (3, 6, D.num_q), generator=gen)
        torch.testing.assert_close(
            model.tokenizer.double().decode(all_ids), ref_vq_decode(sd["vq"], all_ids, D), atol=1e-10, rtol=0
        )
        res_ids = torch.where(pad[..., None], D.nb_code, all_ids)
        res = model.residual.double()
        ours = res(res.history(res_ids, 2), torch.full((3,), 2), cond, pad)
        torch.testing.assert_close(
            ours[valid], ref_residual_logits(sd["res"], res_ids, 2, cond, pad, D)[valid], atol=1e-10, rtol=0
        )
        ctrl_in = torch.randn(3, 36, 24, generator=gen, dtype=torch.float64)
        ours = model.parts["control"].double()(model.transformer.double(), ids, cond, pad, ctrl_in)
        ref = ref_control_logits(sd["ctrl"], ids, cond, pad, ctrl_in, D)
        torch.testing.assert_close(ours[valid], ref[valid], atol=1e-10, rtol=0)
