"""The editing optimisers follow torch.optim's AdamW and L-BFGS step for step, without importing
torch._dynamo (the reason they exist: :mod:`controlmm.editing.optimizers`)."""

from __future__ import annotations

import subprocess
import sys

import pytest
import torch

from controlmm.editing.optimizers import LBFGS, AdamW, cubic_minimum


def rosenbrock(x: torch.Tensor) -> torch.Tensor:
    """Per-row Rosenbrock of a (B, 2k) tensor: a curved valley, minimum 0 at all ones."""
    a, b = x[:, 0::2], x[:, 1::2]
    return (100.0 * (b - a * a) ** 2 + (1.0 - a) ** 2).sum(dim=1)


def start(dtype: torch.dtype = torch.float64) -> torch.Tensor:
    g = torch.Generator().manual_seed(0)
    return (torch.randn(3, 6, generator=g, dtype=dtype) * 1.5).requires_grad_(True)


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
def test_adamw_matches_torch(dtype):
    """Bit for bit (editing runs in float32)."""
    ours, theirs = start(dtype), start(dtype)
    mine = AdamW(ours, lr=0.05, betas=(0.8, 0.95), weight_decay=0.1)
    ref = torch.optim.AdamW([theirs], lr=0.05, betas=(0.8, 0.95), weight_decay=0.1)
    for _ in range(40):
        for x, opt in ((ours, mine), (theirs, ref)):
            opt.zero_grad()
            rosenbrock(x).sum().backward()
            opt.step()
    assert torch.equal(ours, theirs)
    assert not torch.allclose(ours, start(dtype))  # it moved


def run_lbfgs(make, chunks: int, max_eval: int, dtype: torch.dtype) -> tuple[torch.Tensor, list[float], int]:
    x = start(dtype)
    opt = make(x)
    count = 0

    def closure() -> torch.Tensor:
        nonlocal count
        count += 1
        x.grad = None
        loss = rosenbrock(x).sum()
        loss.backward()
        return loss

    losses = []
    for _ in range(chunks):
        if isinstance(opt, torch.optim.LBFGS):
            opt.param_groups[0]["max_eval"] = max_eval
        else:
            opt.max_eval = max_eval
        losses.append(
            float(opt.step(closure).detach() if isinstance(opt, torch.optim.LBFGS) else opt.step(closure))
        )
    return x.detach(), losses, count


@pytest.mark.parametrize("dtype", [torch.float32, torch.float64])
@pytest.mark.parametrize("history", [3, 50])
def test_lbfgs_matches_torch(history, dtype):
    """Bit for bit the same iterates, losses and number of evaluations over several chunks (the
    history carried between step calls, the evaluation budget cut per chunk as codebook editing
    does, line searches cut short by it)."""
    kw = dict(lr=1.0, max_iter=10, max_eval=20, history_size=history)
    ours = run_lbfgs(lambda x: LBFGS(x, **kw), chunks=4, max_eval=15, dtype=dtype)
    theirs = run_lbfgs(
        lambda x: torch.optim.LBFGS(
            [x], **kw, tolerance_grad=0.0, tolerance_change=0.0, line_search_fn="strong_wolfe"
        ),
        chunks=4,
        max_eval=15,
        dtype=dtype,
    )
    assert ours[2] == theirs[2]
    assert ours[1] == theirs[1]
    assert torch.equal(ours[0], theirs[0])
    assert float(rosenbrock(ours[0]).sum()) < 1e-3 * float(rosenbrock(start(dtype).detach()).sum())


def test_lbfgs_stops_at_a_zero_gradient():
    x = torch.ones(2, 4, dtype=torch.float64, requires_grad=True)  # the minimum: gradient 0
    calls = []

    def closure() -> torch.Tensor:
        calls.append(1)
        x.grad = None
        loss = rosenbrock(x).sum()
        loss.backward()
        return loss

    assert LBFGS(x, max_iter=10).step(closure) == 0.0
    assert len(calls) == 1


def test_cubic_minimum_of_a_cubic():
    f = lambda t: (t - 1.0) ** 3 - 3.0 * (t - 1.0)  # noqa: E731  minimum at t = 2
    df = lambda t: 3.0 * (t - 1.0) ** 2 - 3.0  # noqa: E731
    assert cubic_minimum(0.5, f(0.5), df(0.5), 3.0, f(3.0), df(3.0)) == pytest.approx(2.0)
    assert cubic_minimum(3.0, f(3.0), df(3.0), 0.5, f(0.5), df(0.5)) == pytest.approx(2.0)
    assert cubic_minimum(0.5, f(0.5), df(0.5), 3.0, f(3.0), df(3.0), bounds=(0.0, 1.5)) == 1.5


def test_editing_does_not_import_the_compiler():
    """An editing run (both optimisers) leaves torch._dynamo unimported: ~1 s of every cold plan."""
    code = """
import sys, torch
from controlmm.editing.optimizers import AdamW, LBFGS
x = torch.randn(4, requires_grad=True)
def closure():
    x.grad = None
    loss = (x ** 2).sum()
    loss.backward()
    return loss
opt = AdamW(x, lr=0.1)
closure(); opt.step()
LBFGS(x, max_iter=3).step(closure)
print('torch._dynamo' in sys.modules)
"""
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
