"""Predictive sampling over spline knots of foot-space offsets (the controller's planner).

Every ``replan_s`` the sampler rolls out ``samples`` candidate plans from the current state on
the planning model with ``mujoco.rollout`` (a persistent native thread pool; the batch runs in
C, with no Python loop per sample or per step) and keeps the cheapest
(:func:`sim.physics.cost.rollout_cost`). A plan is ``knots`` values of the foot-basis
coordinates (:mod:`sim.physics.reference`) spread evenly over the horizon and linearly
interpolated; the targets are the nominal ones (PD + inverse-dynamics feed-forward) plus the
basis times the interpolated coordinates. Candidate 0 is the previous best plan shifted to the
current time (warm start); the others add Gaussian noise to it. Around the reference's flight
phases (``Reference.flight``) a step rolls out ``flight_samples`` plans instead. This is MuJoCo
MPC's predictive sampling, with the perturbations drawn in foot space rather than joint space.
"""

from __future__ import annotations

import mujoco
import numpy as np
from mujoco import rollout

from sim.physics.actuation import Actuation
from sim.physics.config import PhysicsConfig
from sim.physics.cost import rollout_cost
from sim.physics.model import plan_sensor_start
from sim.physics.reference import Reference

_CTRL = int(mujoco.mjtState.mjSTATE_CTRL)
_MOCAP = int(mujoco.mjtState.mjSTATE_MOCAP_POS) | int(mujoco.mjtState.mjSTATE_MOCAP_QUAT)
FULL_STATE = mujoco.mjtState.mjSTATE_FULLPHYSICS


class PredictiveSampler:
    """Plans target offsets; call :meth:`plan` at a planning step, then :meth:`offset` per step.

    Args:
        model: the planning model (:func:`sim.physics.model.planning_model`), its timestep
            ``substeps`` x the executed model's.
        act: the actuators; ref: the reference; config: sampler settings and weights.
        substeps: simulation steps per rollout step.
        root_adr: qpos address of the root.
        mocap: ((S+1, nmocap, 3), (S+1, nmocap, 4)) mocap poses per simulation step, or None.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        act: Actuation,
        ref: Reference,
        config: PhysicsConfig,
        substeps: int,
        root_adr: int,
        mocap: tuple[np.ndarray, np.ndarray] | None = None,
    ) -> None:
        self.model, self.act, self.ref, self.config = model, act, ref, config
        self.substeps = substeps
        self.root_adr = root_adr
        self.mocap = mocap
        self.horizon = max(1, int(round(config.horizon_s / (ref.dt * substeps))))
        self.knot_steps = np.linspace(0.0, self.horizon * substeps, config.knots)  # in simulation steps
        self.z_dim = ref.sigma.size
        self.best = np.zeros((config.knots, self.z_dim))
        self.plan_step = 0
        self.rng = np.random.default_rng(config.seed)
        self.wide_until = -1  # steps before this one roll out flight_samples plans (a retry)
        self.pool = rollout.Rollout(nthread=config.threads)
        self.datas = [mujoco.MjData(model) for _ in range(config.threads)]
        self.nstate = mujoco.mj_stateSize(model, FULL_STATE)
        B, H = max(config.samples, config.flight_samples), self.horizon
        self.states = np.empty((B, H, self.nstate))
        self.sensordata = np.empty((B, H, model.nsensordata))
        self.sensor0 = plan_sensor_start(model)
        self.control_spec = _CTRL | (_MOCAP if mocap is not None else 0)
        self.ncontrol = mujoco.mj_stateSize(model, self.control_spec)
        self.rollouts = 0
        # rollout step h covers simulation steps (0..substeps-1) + h * substeps after the plan step
        self._local = np.arange(H) * substeps
        seg = np.clip(np.searchsorted(self.knot_steps, self._local, side="right") - 1, 0, config.knots - 2)
        self._seg = seg
        self._alpha = (self._local - self.knot_steps[seg]) / (self.knot_steps[seg + 1] - self.knot_steps[seg])

    def close(self) -> None:
        """Stop the thread pool."""
        self.pool.close()

    def _shifted(self, elapsed: int) -> np.ndarray:
        """The best plan moved ``elapsed`` simulation steps on (held past its last knot), faded
        towards zero with the time constant ``memory_s``."""
        if elapsed <= 0:
            return self.best
        t = self.knot_steps + elapsed
        moved = np.stack([np.interp(t, self.knot_steps, self.best[:, j]) for j in range(self.z_dim)], axis=1)
        return moved * np.exp(-elapsed * self.ref.dt / self.config.memory_s)

    def plan(self, state: np.ndarray, step: int) -> float:
        """Choose the plan from ``state`` (full physics state of the executed data) at ``step``.

        Returns the chosen plan's cost.
        """
        cfg, ref, H = self.config, self.ref, self.horizon
        wide = ref.flight[min(step, ref.steps)] or step < self.wide_until
        B = max(cfg.samples, cfg.flight_samples) if wide else cfg.samples
        states, sensordata = self.states[:B], self.sensordata[:B]
        warm = self._shifted(step - self.plan_step)
        knots = warm[None] + self.rng.standard_normal((B, cfg.knots, self.z_dim)) * ref.sigma
        knots[0] = warm
        seg, alpha = self._seg, self._alpha[None, :, None]
        z = (1.0 - alpha) * knots[:, seg] + alpha * knots[:, seg + 1]  # (B, H, Z)
        before = np.minimum(step + self._local, ref.steps)
        after = np.minimum(before + self.substeps, ref.steps)
        offsets = np.einsum("hnz,bhz->bhn", ref.basis_at(before), z)
        targets = np.clip(ref.nominal[before][None] + offsets, self.act.target_low, self.act.target_high)
        control = targets
        if self.mocap is not None:
            pos, quat = self.mocap
            extra = np.concatenate([pos[before].reshape(H, -1), quat[before].reshape(H, -1)], axis=1)
            control = np.concatenate([targets, np.broadcast_to(extra, (B, H, extra.shape[1]))], axis=2)
        control = np.ascontiguousarray(control, dtype=np.float64)
        initial = np.ascontiguousarray(np.broadcast_to(state, (B, self.nstate)))
        self.pool.rollout(
            [self.model] * B,
            self.datas,
            initial,
            control,
            control_spec=self.control_spec,
            skip_checks=True,
            nstep=H,
            state=states,
            sensordata=sensordata,
        )
        self.rollouts += B * H
        qpos = states[:, :, 1 : 1 + self.model.nq]
        sensors = sensordata[:, :, self.sensor0 :]
        cost = rollout_cost(qpos, sensors, offsets, ref, after, before, self.root_adr, self.act.qpos_adr, cfg)
        cost = np.where(np.isfinite(cost), cost, np.inf)
        best = int(np.argmin(cost))
        self.best = knots[best]
        self.plan_step = step
        return float(cost[best])

    def restart(self, best: np.ndarray, plan_step: int, retry: int, wide_until: int) -> None:
        """Go back to an earlier plan (``best`` (knots, Z) chosen at ``plan_step``) for retry
        number ``retry``: a noise stream of its own, ``flight_samples`` plans per step until
        ``wide_until`` (a simulation step)."""
        self.best, self.plan_step = best.copy(), plan_step
        self.rng = np.random.default_rng((self.config.seed, retry))
        self.wide_until = wide_until

    def offset(self, step: int) -> np.ndarray:
        """Target offsets (nu,) of the current plan at simulation ``step``."""
        local = float(step - self.plan_step)
        knots = self.knot_steps
        seg = min(max(int(np.searchsorted(knots, local, side="right")) - 1, 0), knots.size - 2)
        alpha = min(max((local - knots[seg]) / (knots[seg + 1] - knots[seg]), 0.0), 1.0)
        z = (1.0 - alpha) * self.best[seg] + alpha * self.best[seg + 1]
        return self.ref.basis_at(np.array([step]))[0] @ z
