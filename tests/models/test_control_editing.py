"""Inference-time editing and controlled generation on the tiny model: the editors reduce loss terms and meet
reachable targets, early stopping, presets, residual consistency, the fast joint decoder."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from controlmm.control import ControlSpec, LossTerm, constraint_errors
from controlmm.editing import (
    PRESETS,
    EditingConfig,
    Objective,
    codebook_editing,
    editing_preset,
    logits_editing,
    optimize,
)
from controlmm.errors import ControlMMError
from controlmm.generate import (
    generate,
    generate_controlled,
    latent_to_joints,
    latent_to_positions,
    load_model,
    residual_decode,
)


@pytest.fixture(scope="module")
def model(tiny_control_dir):
    return load_model(tiny_control_dir)


@pytest.fixture(scope="module")
def reference(model):
    """A motion of the model itself (so targets near it are reachable) and its latent."""
    result = generate(model, "a person squats slowly", frames=64, seed=0)
    return result.latent.detach(), latent_to_joints(model, result.latent).detach()


def _decode(model, frames):
    return lambda latent: latent_to_positions(model, latent)[:, :frames]


def test_fast_joint_decoder_equals_the_full_one(model, reference):
    latent, joints = reference
    torch.testing.assert_close(latent_to_positions(model, latent), joints, atol=1e-5, rtol=1e-5)


def test_presets_follow_the_paper():
    assert (PRESETS["fast"].logits_steps, PRESETS["fast"].codebook_steps) == (0, 100)
    assert (PRESETS["medium"].logits_steps, PRESETS["medium"].codebook_steps) == (0, 600)
    assert (PRESETS["accurate"].logits_steps, PRESETS["accurate"].codebook_steps) == (100, 600)
    assert all(p.control_model and p.tolerance == 0.01 for p in PRESETS.values())
    assert (PRESETS["accurate"].lr, PRESETS["accurate"].betas) == (0.06, (0.5, 0.9))
    with pytest.raises(
        ControlMMError, match="unknown editing preset 'slow'; allowed: fast, medium, accurate"
    ):
        editing_preset("slow")
    with pytest.raises(ControlMMError, match="codebook_steps"):
        EditingConfig(codebook_steps=-1)


def _shifted_targets(joints, frames_joints, shift):
    targets = joints.clone()
    mask = torch.zeros(joints.shape[:3], dtype=torch.bool)
    for f, j in frames_joints:
        mask[0, f, j] = True
        targets[0, f, j] += torch.tensor(shift)
    return targets, mask


def _reachable(model, latent, frames_joints, scale=3.0, seed=0):
    """Targets taken from the motion of a perturbed latent: reachable by construction."""
    gen = torch.Generator().manual_seed(seed)
    other = latent_to_joints(model, latent + scale * torch.randn(latent.shape, generator=gen)).detach()
    mask = torch.zeros(other.shape[:3], dtype=torch.bool)
    for f, j in frames_joints:
        mask[0, f, j] = True
    return other, mask


def test_codebook_editing_meets_a_reachable_target_and_stops_early(model, reference):
    latent, joints = reference
    targets, mask = _reachable(model, latent, [(10, 0), (40, 21), (63, 10)])
    objective = Objective(targets=targets, mask=mask, tolerance=0.01)
    _, _, before = objective.evaluate(joints)
    assert float(before) > 0.05
    outcome = codebook_editing(latent, _decode(model, 64), objective, EditingConfig(codebook_steps=400))
    edited = latent_to_joints(model, outcome.param)
    err = (edited - targets).norm(dim=-1)[mask]
    assert bool(outcome.done[0]) and float(err.max()) <= 0.01
    assert 0 < int(outcome.steps[0]) < 400  # stopped as soon as every constraint was within 1 cm
    full = codebook_editing(
        latent, _decode(model, 64), objective, EditingConfig(codebook_steps=10, early_stop=False)
    )
    assert int(full.steps[0]) == 10 and not bool(full.done[0])
    # the paper's first-order optimiser (AdamW) behind the same interface
    adam = codebook_editing(
        latent, _decode(model, 64), objective, EditingConfig(codebook_steps=400, codebook_optimizer="adam")
    )
    assert float(adam.loss[0]) < 0.05 * float(objective.evaluate(joints)[0])
    with pytest.raises(ControlMMError, match="codebook_optimizer must be adam or lbfgs; got 'sgd'"):
        EditingConfig(codebook_optimizer="sgd")


def test_editing_stops_on_a_plateau_and_on_the_mean_error(model, reference):
    latent, joints = reference
    flat = LossTerm("flat", lambda j: (j * 0.0).sum(dim=(1, 2, 3)) + 1.0)
    outcome = optimize(latent, _decode(model, 64), Objective(terms=[flat]), 50, EditingConfig(), patience=4)
    assert int(outcome.steps[0]) == 4 and not bool(outcome.done[0])
    targets = joints.clone()
    targets[0, 10, 0, 0] += 0.05  # one constraint 5 cm off, nine met exactly
    mask = torch.zeros(joints.shape[:3], dtype=torch.bool)
    mask[0, 10:20, 0] = True
    _, done_max, _ = Objective(targets=targets, mask=mask, tolerance=0.01).evaluate(joints)
    _, done_mean, _ = Objective(targets=targets, mask=mask, tolerance=0.01, stop_on="mean").evaluate(joints)
    assert not bool(done_max[0]) and bool(done_mean[0])
    # the hinge only pulls on constraints over half the tolerance: 5 cm over 10 entries -> (0.045^2) / 10
    hinge = Objective(targets=targets, mask=mask, tolerance=0.01, hinge_weight=10.0)
    torch.testing.assert_close(
        hinge.control_hinge(joints), torch.tensor([0.045**2 / 10]), atol=1e-6, rtol=1e-3
    )
    plain = Objective(targets=targets, mask=mask, tolerance=0.01).term_values(joints)["control"]
    torch.testing.assert_close(
        hinge.term_values(joints)["control"], plain + 10.0 * 0.045**2 / 10, atol=1e-6, rtol=1e-3
    )


def test_codebook_editing_takes_any_loss_term(model, reference):
    latent, joints = reference
    height = float(joints[0, :, 15, 1].max())
    duck = LossTerm(
        "duck", lambda j: torch.relu(j[:, :, 15, 1] - (height - 0.05)).square().sum(-1), weight=10.0
    )
    objective = Objective(terms=[duck], loss_tolerance=1e-7)
    outcome = codebook_editing(latent, _decode(model, 64), objective, EditingConfig(codebook_steps=300))
    edited = latent_to_joints(model, outcome.param)
    assert float(duck(edited)) < 0.01 * float(duck(joints)) and bool(outcome.done[0])
    assert float(edited[0, :, 15, 1].max()) < height - 0.04
    # several samples stop independently: a sample with nothing to do takes no step
    both = Objective(
        targets=joints.expand(2, -1, -1, -1).clone(),
        mask=torch.stack(
            [
                torch.zeros_like(joints[0, ..., 0], dtype=torch.bool),
                torch.ones_like(joints[0, ..., 0], dtype=torch.bool),
            ]
        ),
    )
    both.targets[1, 30:, 0, 0] += 0.05
    two = codebook_editing(
        latent.expand(2, -1, -1), _decode(model, 64), both, EditingConfig(codebook_steps=200)
    )
    assert int(two.steps[0]) == 0 and int(two.steps[1]) > 0
    torch.testing.assert_close(two.param[0], latent[0])


def test_logits_editing_reduces_the_loss(model, reference):
    latent, joints = reference
    codebook = model.tokenizer.codebooks[0]
    n = latent.shape[1]
    torch.manual_seed(1)
    logits = torch.randn(1, n, codebook.shape[0]) * 2
    editable = torch.ones(1, n, dtype=torch.bool)
    editable[0, :3] = False
    fixed = torch.zeros(1, n, codebook.shape[1])
    fixed[0, :3] = codebook[:3]
    targets, mask = _shifted_targets(joints, [(20, 0), (50, 0)], [0.0, 0.0, 0.0])
    objective = Objective(targets=targets, mask=mask, tolerance=1e-4)
    config = EditingConfig(logits_steps=60, logits_patience=0)  # the full budget: no plateau stop
    from controlmm.editing.logits_editing import soft_latent

    def expected_loss(x):
        gen = torch.Generator().manual_seed(5)
        return np.mean(
            [
                float(
                    objective.evaluate(
                        _decode(model, 64)(soft_latent(x, codebook, editable, fixed, 1.0, gen))
                    )[0]
                )
                for _ in range(8)
            ]
        )

    outcome = logits_editing(
        logits,
        editable,
        fixed,
        codebook,
        _decode(model, 64),
        objective,
        config,
        torch.Generator().manual_seed(0),
    )
    assert int(outcome.steps[0]) == 60
    torch.testing.assert_close(outcome.param[0, :3], logits[0, :3], atol=1e-3, rtol=0)  # no gradient there
    assert expected_loss(outcome.param) < 0.5 * expected_loss(logits)


@pytest.fixture(scope="module")
def spec(model, reference):
    """Six constraints (pelvis, right wrist, a dense left-knee range) on a reachable motion."""
    latent, _ = reference
    j = _reachable(model, latent, [], seed=1)[0][0].numpy()
    return ControlSpec.from_dict(
        {
            "coords": "human",
            "constraints": [
                {"joint": "pelvis", "frame": 30, "position": j[30, 0].tolist()},
                {"joint": "right_wrist", "frame": 50, "position": j[50, 21].tolist()},
                {"joint": "left_knee", "frame_range": [60, 63], "positions": j[60:64, 4].tolist()},
            ],
        }
    )


def test_controlled_generation_meets_the_spec(model, spec):
    out = generate_controlled(
        model, "a person squats slowly", control=spec, frames=64, preset="medium", seed=0
    )
    motion, errors, record = out.motion, out.errors[0], out.records[0]
    assert motion.joints.shape == (64, 22, 3) and errors.shape == (6,)
    np.testing.assert_allclose(errors, constraint_errors(motion.joints, spec), atol=1e-6)
    assert record.control_model and record.logits_steps == [] and record.converged
    assert float(errors.max()) <= 0.01 and record.codebook_steps < 600
    meta = motion.metadata["control"]
    assert meta["spec"]["constraints"][2]["frame_range"] == [60, 63]
    assert [c["joint"] for c in meta["constraints"]][:2] == ["pelvis", "right_wrist"]
    assert motion.extras["control_mask"].sum() == 6 and motion.extras["control_errors"].shape == (6,)
    # the same targets as arrays give the same result
    targets, mask = spec.dense(64)
    again = generate_controlled(
        model, "a person squats slowly", targets=targets, mask=mask, preset="medium", seed=0
    )
    assert again.motion.num_frames == 64  # the length covers the last controlled frame
    np.testing.assert_allclose(sorted(again.errors[0]), sorted(errors), atol=1e-6)


def test_accurate_preset_edits_logits_and_keeps_residual_layers_consistent(model, spec):
    accurate = PRESETS["accurate"].with_overrides(logits_steps=8)  # fewer steps: a quick test
    out = generate_controlled(
        model,
        ["a person squats slowly", "someone bends over"],
        control=[spec, None],
        frames=[64, 48],
        preset=accurate,
        seed=3,
    )
    record = out.records[0]
    assert len(record.logits_steps) == 10 and 0 < sum(record.logits_steps) <= 80
    assert float(out.errors[0].max()) <= 0.01 and out.errors[1].shape == (0,)
    assert out.records[1].total_steps == 0  # nothing to meet: no editing
    # residual layers are the arg-max prediction from the final (edited) base tokens
    ids = torch.stack([out.ids[0][:12], out.ids[1][:12]])
    cond = model.encode_text(out.texts)
    lengths = torch.tensor([16, 12])
    full = torch.full((2, 16, ids.shape[-1]), -1, dtype=torch.long)
    full[0], full[1, :12] = out.ids[0], out.ids[1]
    again, _ = residual_decode(model.residual, full[..., 0], cond, lengths, 5.0, temperature=0.0, topk=None)
    assert torch.equal(again, full)


def test_extra_loss_terms_and_early_stopping_in_generation(model, spec):
    none = EditingConfig(control_model=False, logits_steps=0, codebook_steps=0)
    plain = generate_controlled(model, "a person squats slowly", control=spec, frames=64, seed=1, preset=none)
    assert plain.records[0].total_steps == 0 and not plain.records[0].control_model
    head = float(plain.motion.joints[:, 15, 1].max())
    duck = LossTerm(
        "duck", lambda j: torch.relu(j[:, :, 15, 1] - (head - 0.03)).square().sum(-1), weight=10.0
    )
    out = generate_controlled(
        model, "a person squats slowly", control=spec, terms=[duck], frames=64, preset="medium", seed=1
    )
    record = out.records[0]
    assert set(record.losses) == {"control", "duck"}
    assert record.converged and record.losses["duck"] <= 1e-6 and record.codebook_steps < 600
    assert float(out.errors[0].max()) <= 0.01 < float(plain.errors[0].max())
    assert float(out.motion.joints[:, 15, 1].max()) < head - 0.02


def test_bad_control_input_is_one_line(model, spec):
    for kwargs, needle in [
        (dict(control=spec, frames=50), "at frame 50 is outside the motion (frames 0..49)"),
        (dict(control=[spec, spec]), "2 control specs given for 1 prompts"),
        (dict(targets=np.zeros((64, 22, 3)), mask=np.zeros((64, 21), bool)), "mask must have shape"),
        (dict(targets=np.zeros((64, 22, 3))), "targets and mask go together"),
        (dict(control=spec, preset="slow"), "unknown editing preset"),
    ]:
        with pytest.raises(ControlMMError, match=needle.replace("(", r"\(").replace(")", r"\)")):
            generate_controlled(model, "a person squats", **kwargs)


def test_editors_keep_only_admissible_states(model, reference):
    """A term that pulls the pelvis 10 cm sideways while only states within 2 cm of the start may be
    kept (the foot-contact run's rule: never trade a constraint away): both optimisers return the best
    admissible state, and without the rule they go past it."""
    latent, joints = reference
    decode = _decode(model, 64)
    start = joints[:, :, 0, 0].clone()  # (1, 64) the pelvis x of the start (m)
    pull = LossTerm("pull", lambda j: (j[:, :, 0, 0] - (start + 0.10)).square().mean(-1))

    def moved(j: torch.Tensor) -> torch.Tensor:  # (B,) the pelvis' largest x displacement (m)
        return (j[:, :, 0, 0] - start).abs().amax(-1)

    def admissible(j: torch.Tensor) -> torch.Tensor:
        return moved(j) <= 0.02

    for optimizer in ("lbfgs", "adam"):
        config = EditingConfig(codebook_steps=30, codebook_optimizer=optimizer)
        free = codebook_editing(latent, decode, Objective(terms=[pull]), config)
        held = codebook_editing(latent, decode, Objective(terms=[pull]), config, admissible=admissible)
        with torch.no_grad():
            assert float(moved(decode(free.param))[0]) > 0.02
            kept = float(moved(decode(held.param))[0])
        assert 0.0 < kept <= 0.02
