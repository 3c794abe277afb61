"""AdamW and L-BFGS (strong Wolfe line search) for the one tensor that editing optimises.

Why not ``torch.optim``: its optimisers import ``torch._dynamo`` (the compiler stack) the first
time one is constructed or stepped, about 1 s on this project's 2-core machine, in every
``controlmm plan`` process: a tenth of the cold command. Editing optimises a single tensor with
two textbook methods, written out here and checked step for step against ``torch.optim.AdamW``
and ``torch.optim.LBFGS`` (``tests/test_editing_optimizers.py``), so a plan never pays that import.

* :class:`AdamW`: Adam with decoupled weight decay (Loshchilov & Hutter 2019), bias-corrected.
* :class:`LBFGS`: limited-memory BFGS (two-loop recursion, Nocedal & Wright 2006, Alg. 7.4) with
  a line search satisfying the strong Wolfe conditions (Alg. 3.5 and 3.6, cubic interpolation).
  Like ``torch.optim.LBFGS``, each :meth:`LBFGS.step` evaluates the closure at the current point
  first and keeps its curvature history for the next call; ``max_eval`` is checked after each
  line search.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import torch

Closure = Callable[[], torch.Tensor]
"""Evaluates the loss at the parameter's current value, leaving its gradient in ``param.grad``."""


class AdamW:
    """AdamW on one tensor ``param`` (updated in place from ``param.grad``)."""

    def __init__(
        self,
        param: torch.Tensor,
        lr: float,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
        weight_decay: float = 0.01,
    ) -> None:
        self.param, self.lr, self.betas, self.eps, self.weight_decay = param, lr, betas, eps, weight_decay
        self.exp_avg = torch.zeros_like(param)  # first moment
        self.exp_avg_sq = torch.zeros_like(param)  # second moment
        self.steps = 0

    def zero_grad(self) -> None:
        self.param.grad = None

    @torch.no_grad()
    def step(self) -> None:
        """One update from ``param.grad`` (none without a gradient)."""
        grad = self.param.grad
        if grad is None:
            return
        self.steps += 1
        beta1, beta2 = self.betas
        self.param.mul_(1.0 - self.lr * self.weight_decay)
        self.exp_avg.lerp_(grad, 1.0 - beta1)
        self.exp_avg_sq.mul_(beta2).addcmul_(grad, grad, value=1.0 - beta2)
        denom = (self.exp_avg_sq.sqrt() / math.sqrt(1.0 - beta2**self.steps)).add_(self.eps)
        self.param.addcdiv_(self.exp_avg, denom, value=-self.lr / (1.0 - beta1**self.steps))


Scalar = Any
"""A step length, loss or slope: a Python float or a 0-d tensor of the parameter's dtype (``Any``:
the type checker does not follow comparisons that mix the two). The arithmetic below keeps each
as ``torch.optim.LBFGS`` does, so float32 runs give the same iterates as it."""


def cubic_minimum(
    t1: Scalar,
    f1: Scalar,
    g1: Scalar,
    t2: Scalar,
    f2: Scalar,
    g2: Scalar,
    bounds: tuple[Scalar, Scalar] | None = None,
) -> Scalar:
    """Minimiser of the cubic through (t, f, f') at t1 and t2 (Nocedal & Wright eq. 3.59), clamped
    to ``bounds`` (default: between t1 and t2); the middle of the bounds where the cubic has none."""
    lo, hi = bounds if bounds is not None else ((t1, t2) if t1 <= t2 else (t2, t1))
    d1 = g1 + g2 - 3 * (f1 - f2) / (t1 - t2)
    disc = d1**2 - g1 * g2
    if disc < 0:
        return (lo + hi) / 2.0
    d2 = disc.sqrt() if isinstance(disc, torch.Tensor) else math.sqrt(disc)
    if t1 <= t2:
        t = t2 - (t2 - t1) * ((g2 + d2 - d1) / (g2 - g1 + 2 * d2))
    else:
        t = t1 - (t1 - t2) * ((g1 + d2 - d1) / (g1 - g2 + 2 * d2))
    return min(max(t, lo), hi)


@dataclass
class _Point:
    """A trial step ``t`` along the search direction: loss, flat gradient and directional derivative."""

    t: Scalar
    f: Scalar
    g: torch.Tensor
    gtd: Scalar


def strong_wolfe(
    evaluate: Callable[[Scalar], tuple[float, torch.Tensor]],
    t: Scalar,
    d: torch.Tensor,
    f0: float,
    g0: torch.Tensor,
    gtd0: Scalar,
    max_ls: int = 25,
    c1: float = 1e-4,
    c2: float = 0.9,
    tolerance_change: float = 1e-9,
) -> tuple[Scalar, torch.Tensor, Scalar, int]:
    """A step along ``d`` meeting the strong Wolfe conditions, within ``max_ls`` trials.

    ``evaluate(t) -> (loss, flat gradient)`` at the start point + t d; (f0, g0, gtd0) at t = 0.
    Returns (loss, gradient, t, evaluations) of the step taken: the best bracketed one (possibly
    t = 0) when the trials run out.
    """
    d_norm = d.abs().max()
    start = _Point(0, f0, g0.clone(), gtd0)
    f, g = evaluate(t)
    new = _Point(t, f, g, g.dot(d))
    evals, trials = 1, 0
    prev = start
    bracket: list[_Point] = []
    done = False
    # Bracketing: grow the step until it overshoots (too little decrease, or the slope turns).
    while trials < max_ls:
        if new.f > f0 + c1 * new.t * gtd0 or (trials > 1 and new.f >= prev.f):
            bracket = [prev, new]
            break
        if abs(new.gtd) <= -c2 * gtd0:
            bracket, done = [new], True
            break
        if new.gtd >= 0:
            bracket = [prev, new]
            break
        bounds = (new.t + 0.01 * (new.t - prev.t), new.t * 10)
        t = cubic_minimum(prev.t, prev.f, prev.gtd, new.t, new.f, new.gtd, bounds)
        prev = new
        f, g = evaluate(t)
        new = _Point(t, f, g, g.dot(d))
        evals += 1
        trials += 1
    if trials == max_ls:
        bracket = [start, new]
    # Zoom: shrink the bracket by cubic interpolation until a point meets both conditions.
    low, high = (0, 1) if bracket[0].f <= bracket[-1].f else (1, 0)
    stuck = False
    while not done and trials < max_ls:
        a, b = bracket[0], bracket[1]
        if abs(b.t - a.t) * d_norm < tolerance_change:
            break
        t = cubic_minimum(a.t, a.f, a.gtd, b.t, b.f, b.gtd)
        # Safeguard: a trial too close to an end of the bracket moves 10 % inside it.
        top, bottom = max(a.t, b.t), min(a.t, b.t)
        margin = 0.1 * (top - bottom)
        if min(top - t, t - bottom) < margin:
            if stuck or t >= top or t <= bottom:
                t = top - margin if abs(t - top) < abs(t - bottom) else bottom + margin
                stuck = False
            else:
                stuck = True
        else:
            stuck = False
        f, g = evaluate(t)
        new = _Point(t, f, g, g.dot(d))
        evals += 1
        trials += 1
        if new.f > f0 + c1 * t * gtd0 or new.f >= bracket[low].f:
            bracket[high] = new
            low, high = (0, 1) if bracket[0].f <= bracket[1].f else (1, 0)
        else:
            if abs(new.gtd) <= -c2 * gtd0:
                done = True
            elif new.gtd * (bracket[high].t - bracket[low].t) >= 0:
                bracket[high] = bracket[low]
            bracket[low] = new
    best = bracket[low]
    return best.f, best.g, best.t, evals


@dataclass
class _History:
    """L-BFGS memory kept between :meth:`LBFGS.step` calls."""

    steps: list[torch.Tensor] = field(default_factory=list)  # s_k = x_{k+1} - x_k
    changes: list[torch.Tensor] = field(default_factory=list)  # y_k = g_{k+1} - g_k
    rho: list[Scalar] = field(default_factory=list)  # 1 / (y_k . s_k)
    scale: Scalar = 1.0  # initial inverse Hessian: (y . s) / (y . y) of the newest pair
    iterations: int = 0
    direction: torch.Tensor | None = None
    step_size: Scalar = 0.0
    prev_grad: torch.Tensor | None = None


class LBFGS:
    """L-BFGS with a strong Wolfe line search on one tensor ``param`` (updated in place).

    ``step(closure)`` runs at most ``max_iter`` iterations and stops once ``max_eval`` closure
    evaluations are spent (checked after each line search, which gets the evaluations left),
    the gradient is zero, or the search direction does not descend. ``history_size`` curvature
    pairs are kept; the first iteration's step is ``lr * min(1, 1 / |g|_1)``, later ones start
    at ``lr``.
    """

    def __init__(
        self,
        param: torch.Tensor,
        lr: float = 1.0,
        max_iter: int = 20,
        max_eval: int | None = None,
        history_size: int = 100,
    ) -> None:
        self.param, self.lr, self.max_iter, self.history_size = param, lr, max_iter, history_size
        self.max_eval = max_eval if max_eval is not None else max_iter * 5 // 4
        self.history = _History()

    def _grad(self) -> torch.Tensor:
        g = self.param.grad
        if g is None:
            return torch.zeros(self.param.numel(), dtype=self.param.dtype, device=self.param.device)
        return g.reshape(-1).clone()

    def _direction(self, g: torch.Tensor) -> torch.Tensor:
        """-H g by the two-loop recursion over the kept pairs."""
        h = self.history
        q = g.neg()
        alpha: list[Scalar] = [0.0] * len(h.steps)
        for i in range(len(h.steps) - 1, -1, -1):
            alpha[i] = h.steps[i].dot(q) * h.rho[i]
            q.add_(h.changes[i], alpha=-float(alpha[i]))
        r = torch.mul(q, h.scale)
        for i in range(len(h.steps)):
            beta = h.changes[i].dot(r) * h.rho[i]
            r.add_(h.steps[i], alpha=float(alpha[i] - beta))
        return r

    def _remember(self, g: torch.Tensor) -> None:
        """Add the curvature pair of the last step (when it has positive curvature)."""
        h = self.history
        assert h.prev_grad is not None and h.direction is not None
        y = g.sub(h.prev_grad)
        s = h.direction.mul(h.step_size)
        ys = y.dot(s)
        if ys > 1e-10:
            if len(h.steps) == self.history_size:
                del h.steps[0], h.changes[0], h.rho[0]
            h.steps.append(s)
            h.changes.append(y)
            h.rho.append(1.0 / ys)
            h.scale = ys / y.dot(y)

    @torch.no_grad()
    def step(self, closure: Closure) -> float:
        """Iterate from the parameter's current value; returns the loss there."""
        h = self.history
        x = self.param.view(-1)
        with torch.enable_grad():
            first = float(closure().detach())
        loss: Scalar = first
        g = self._grad()
        evals = 1
        if g.abs().max() <= 0.0:
            return first
        for n in range(1, self.max_iter + 1):
            h.iterations += 1
            if h.iterations == 1:
                d = g.neg()
                h.steps, h.changes, h.rho, h.scale = [], [], [], 1.0
            else:
                self._remember(g)
                d = self._direction(g)
            h.prev_grad = g.clone()
            first_step: Scalar = min(1.0, 1.0 / g.abs().sum())  # a tensor unless 1.0
            t: Scalar = first_step * self.lr if h.iterations == 1 else self.lr
            h.direction, h.step_size = d, t
            gtd = g.dot(d)
            if gtd > 0.0:  # not a descent direction
                break
            start = x.clone()

            def evaluate(
                step: Scalar, start: torch.Tensor = start, d: torch.Tensor = d
            ) -> tuple[float, torch.Tensor]:
                x.add_(d, alpha=float(step))
                with torch.enable_grad():
                    value = float(closure().detach())
                grad = self._grad()
                x.copy_(start)
                return value, grad

            loss, g, t, used = strong_wolfe(
                evaluate, t, d, float(loss), g, gtd, max_ls=max(0, self.max_eval - evals)
            )
            x.add_(d, alpha=float(t))
            h.step_size = t
            evals += used
            if n == self.max_iter or evals >= self.max_eval or g.abs().max() <= 0.0:
                break
            if d.mul(t).abs().max() <= 0.0:  # the step did not move
                break
        return first
