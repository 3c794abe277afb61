"""Residual quantizer: first-batch init, EMA updates, dead-code reset, quantizer dropout, Gumbel choice."""

from __future__ import annotations

import torch

from controlmm.models.quantizer import QuantizeEMAReset, ResidualVQ


def test_codebook_initialised_from_first_batch_then_ema_updated():
    torch.manual_seed(0)
    q = QuantizeEMAReset(nb_code=8, code_dim=4, mu=0.9).train()
    x = torch.randn(1, 4, 16)  # 16 latents >= 8 codes: the first 8 become the codebook
    q(x)
    flat = x[0].t()
    assert bool(q.initted)
    # After init the EMA starts from code_sum = first rows, count = 1; the update then mixes in the batch.
    idx = q.quantize(flat)  # eval-style argmin against the updated codebook is well defined
    assert idx.shape == (16,)
    # Check the EMA arithmetic on a second, controlled batch.
    before_sum, before_count = q.code_sum.clone(), q.code_count.clone()
    y = torch.randn(1, 4, 16)
    q.eval()
    chosen = q.quantize(y[0].t())
    q.train()
    q.update_codebook(y[0].t(), chosen)
    onehot = torch.nn.functional.one_hot(chosen, 8).float()
    expect_sum = 0.9 * before_sum + 0.1 * onehot.t() @ y[0].t()
    expect_count = 0.9 * before_count + 0.1 * onehot.sum(0)
    assert torch.allclose(q.code_sum, expect_sum, atol=1e-6)
    assert torch.allclose(q.code_count, expect_count, atol=1e-6)
    alive = expect_count >= 1.0
    assert torch.allclose(q.codebook[alive], (expect_sum / expect_count[:, None])[alive], atol=1e-5)


def test_dead_codes_are_reset_to_batch_latents():
    torch.manual_seed(0)
    q = QuantizeEMAReset(nb_code=16, code_dim=3, mu=0.5).train()
    a, b = torch.tensor([5.0, 5.0, 5.0]), torch.tensor([-5.0, 0.0, 0.0])
    first = torch.cat([a + 0.01 * torch.randn(8, 3), b + 0.01 * torch.randn(8, 3)])
    q(first.t()[None])  # initialises half the codes near a, half near b
    assert float(torch.cdist(q.codebook, b[None]).min()) < 0.1
    cluster = a + 0.01 * torch.randn(64, 3)
    q(cluster.t()[None])  # codes near b get no latent: their count decays to 0.5 < 1
    dead = q.code_count < 1.0
    assert int(dead.sum()) == 8
    # ... and they are replaced by latents of the current batch (all near a now).
    assert float(torch.cdist(q.codebook[dead], cluster).min(dim=1).values.max()) < 1e-6
    assert float(torch.cdist(q.codebook, b[None]).min()) > 9.0


def test_tile_pads_small_batches_with_noise():
    q = QuantizeEMAReset(nb_code=10, code_dim=2, mu=0.99).train()
    x = torch.tensor([[1.0, 0.0], [0.0, 1.0], [2.0, 2.0]])
    q.init_codebook(x)
    assert torch.allclose(q.codebook[:3], x, atol=0.05)
    assert torch.allclose(q.codebook[3:6], x, atol=0.05) and not torch.equal(q.codebook[3:6], x)


def test_quantizer_dropout_and_forced_cut():
    torch.manual_seed(0)
    rvq = ResidualVQ(num_quantizers=4, nb_code=8, code_dim=3, mu=0.99, quantize_dropout_prob=1.0).train()
    x = torch.randn(2, 3, 5)
    cuts = set()
    for _ in range(40):
        _, ids, _, _ = rvq(x)
        used = int((ids[0, 0] >= 0).sum())
        assert torch.all(ids[..., :used] >= 0) and torch.all(ids[..., used:] == -1)
        cuts.add(used)
    assert cuts == {1, 2, 3, 4}  # s ~ U{0..3}: layers above s are skipped
    _, ids, _, _ = rvq(x, force_dropout_index=1)
    assert torch.all(ids[..., 2:] == -1) and torch.all(ids[..., :2] >= 0)
    rvq.quantize_dropout_prob = 0.0
    _, ids, _, _ = rvq(x)
    assert torch.all(ids >= 0)
    rvq.eval()
    rvq.quantize_dropout_prob = 1.0
    _, ids, _, _ = rvq(x)
    assert torch.all(ids >= 0)  # no dropout at evaluation


def test_training_code_choice_is_gumbel_eval_is_nearest():
    torch.manual_seed(0)
    q = QuantizeEMAReset(nb_code=2, code_dim=1, mu=0.99)
    q.codebook.copy_(torch.tensor([[0.0], [1.0]]))
    x = torch.full((2000, 1), 0.4)  # nearer to code 0; distances 0.16 vs 0.36
    q.eval()
    assert torch.all(q.quantize(x, temperature=0.5) == 0)
    q.train()
    picks = q.quantize(x, temperature=0.5).float().mean()
    # P(code 1) = sigmoid((0.16 - 0.36) / 0.5) = 0.401
    assert abs(float(picks) - 0.401) < 0.04


def test_residual_quantization_reduces_error_layer_by_layer():
    torch.manual_seed(0)
    rvq = ResidualVQ(num_quantizers=3, nb_code=32, code_dim=4, mu=0.9, quantize_dropout_prob=0.0).train()
    x = torch.randn(4, 4, 32)
    for _ in range(30):
        rvq(x)
    rvq.eval()
    ids = rvq.quantize(x)
    codes = rvq.get_codes_from_indices(ids)  # (Q, B, N, D)
    target = x.permute(0, 2, 1)
    errors = [float((codes[: k + 1].sum(0) - target).pow(2).mean()) for k in range(3)]
    assert errors[0] > errors[1] > errors[2]
    ema = rvq.ema_state()
    other = ResidualVQ(num_quantizers=3, nb_code=32, code_dim=4, mu=0.9, quantize_dropout_prob=0.0)
    other.load_ema_state(ema)
    assert torch.equal(other.layers[2].code_count, rvq.layers[2].code_count) and bool(other.layers[0].initted)
