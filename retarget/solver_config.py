"""Settings of the whole-sequence retargeting solver: schedule, damping and every cost weight.

A mapping file's ``solver`` object overrides any of these fields for its robot
(:func:`retarget.mapping.parse_mapping`); :func:`retarget.costs.default_costs` reads the
weights when it builds the cost terms.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class SolverConfig:
    """Solver settings; the weights multiply the per-keypoint weights of the mapping.

    Temporal weights apply to differences at 20 fps and are rescaled for other rates so that
    the same physical velocity/acceleration costs the same.
    """

    max_iterations: int = 25
    """Iterations when ``levels`` is empty (one level, all frames)."""
    tolerance: float = 0.01
    """Stop a level when an iteration lowers the cost by less than this fraction."""
    damping: float = 1e-4
    """Initial Levenberg-Marquardt damping (per frame)."""
    w_vel_root: float = 0.5
    w_vel_joint: float = 0.1
    w_joint_damping: float = 0.01
    """Weight of ``(damping * speed / torque limit)^2`` per joint and frame (speed in rad/s; the
    MJCF's joint damping and motor limits, :func:`retarget.actuators.damping_share`): the share
    of a motor that its joint's damping takes. The Apollo's torso yaw (damping 200, 120 N m)
    turning with the human's shoulders at 3.6 rad/s needed four times its motor."""
    w_acc_root: float = 100.0
    w_acc_joint: float = 8.0
    exact_acceleration: bool = False
    """Keep the lag-2 acceleration couplings in the banded matrix (2x bandwidth, ~4x solve time)."""
    levels: tuple[tuple[int, int], ...] = ((3, 10), (1, 2))
    """Coarse-to-fine schedule: (solve every k-th frame, iterations at most); () solves all
    frames with max_iterations. The coarse level costs a third of the full one per iteration
    and stops once settled (``coarse_settle_steps``); 10 rather than 5 at most brought the
    packaged robots 0.1-0.4 cm closer (21 motions each) and the AMP humanoid's raised arms,
    sit-down and kneel out of 7-11 cm (2026-12-02, docs/BENCHMARKS.md)."""
    coarse_settle_steps: int = 2
    """A coarse level stops after this many accepted iterations in a row that each lower the
    cost by less than ``tolerance`` (the full-rate level after one). One stopped the AMP
    humanoid's stoop (corpus clip 000000) at its second iteration, its knees straight at their
    range's end (rest pose, the solver's starting point) and a step gaining 0.1 %: 19.9 cm
    from the human; two take it to 2.3 cm."""
    extra_iterations: int = 6
    """Iterations of the local refinement of frames where the self-clearance or body-floor
    terms are still violated by more than CONSTRAINT_TOLERANCE (stiff terms converge more
    slowly); only those frames are solved again."""
    body_floor: bool = True
    """Keep every body's collision geometry above the floor, not only the feet (kneeling)."""
    body_floor_weight: float = 1000.0
    """Weight of that term at the last (full-rate) level; coarser levels use
    ``min(w_body_floor_coarse, body_floor_weight)``: stiff, a knee must not sink while the
    locked feet pull the legs."""
    self_clearance: bool = True
    """Keep the arms clear of the trunk, the legs and each other (:mod:`retarget.selfcollision`)."""
    speed_limits: bool = True
    """Keep every joint within its speed limit between output frames
    (:func:`retarget.actuators.joint_speed_limits`, the ones ``controlmm validate`` checks):
    ``retarget_motion`` solves again with a too-fast joint's velocity term stiffer there
    (:mod:`retarget.speed_rungs`). False tracks the human however fast."""
    self_midpoints: bool = False
    """Keep them clear halfway between consecutive frames too (:mod:`retarget.midpoints`): an
    arm swinging past a hip between two frames would pass through it in the output's frames.
    ``retarget_motion`` solves again with it where its output frames self-collide."""
    pin_iterations: int = 2
    """Gauss-Newton steps that move stance feet onto their locked targets afterwards (0: off)."""
    # Weights of the per-frame cost terms (appended: positional construction keeps its order).
    l_rot: float = 0.2
    """Metres per radian of orientation error (an error of 1 rad costs like 0.2 m)."""
    l_posture: float = 0.1
    """Metres per radian of posture error."""
    w_coupling: float = 1.0e4
    """Weight (per rad^2) of the MJCF's joint couplings (:mod:`retarget.costs.coupling`)."""
    w_floor: float = 100.0
    """Weight of the feet's floor/clearance term (per foot collision point)."""
    w_self: float = 100.0
    """Weight of the self-clearance term (per capsule pair, :mod:`retarget.selfcollision`)."""
    body_clearance: float = 0.002
    """Metres the collision geometry of the non-foot bodies keeps above the floor (knees, hands)."""
    w_body_floor_coarse: float = 100.0
    """Weight of the body-floor term at the coarse levels: a stiff floor from the start would
    lift a straight-legged initial guess off the ground."""
    human_leg_share: float = 1.0
    """How far (0-1) the knee, ankle and toe targets move from the robot-proportioned legs (the
    robot's bone lengths along the human's bones, from the robot's own hips) to the scaled
    human's joint positions (:func:`retarget.targets.fit_limbs_to_human`)."""
    human_arm_share: float = 1.0
    """The same for the elbow and wrist targets (from the robot's own shoulders)."""
    foot_roll: float = 1.0
    """Share (0-1) of the human foot's pitch with which a contact foot rolls over its heel or
    toe (:func:`retarget.foot_targets.feet_targets`; 0: flat while the human's foot is down,
    but for a pitch held longer than :data:`retarget.foot_targets.HELD_PITCH_SECONDS`, which
    rolls fully). G1's mapping sets 0, with ``foot_lift`` 0.5."""
    roll_lock_gain: float = 5.0
    """Further multiplier of a contact foot's lock weight over the frames in which the human's
    foot is down but not flat (heel strikes, toe-offs), where the robot's foot rolls over its
    heel or toe pivot (1: locked no harder than in flat stance); legs of fewer than six joints
    of their own get none (:data:`retarget.foot_targets.FULL_LEG_JOINTS`). On the 21 motions of
    ``benchmarks/retarget_peers.py --clips 20`` the soles slide 12-21 % less on four of the
    six packaged robots for the same fit (docs/BENCHMARKS.md, 2026-12-04)."""
    balance_iterations: int = 3
    """Solves at most with the body moved so that the stance ankles' motors can hold the
    zero-moment point (:mod:`retarget.balance`; 0: off): H1's and T1's ankles are weak for
    their mass, and the human's push-off loads them past their motors."""
    foot_lift: float = 0.0
    """Share (0-1) of the height a contact foot rolling with the human's whole pitch would raise
    its ankle by that a foot rolling less (``foot_roll`` < 1) rises straight up instead
    (:func:`retarget.foot_targets.feet_targets`): it leaves and meets the floor flat while the
    human's heel or toe is still down, without sliding and without the late jump of a foot held
    down to the contact's last frame. No effect at ``foot_roll`` 1. One of the fallbacks of
    :func:`controlmm.pipeline.retarget_checked`."""
    calibrated_iterations: int = 6
    """Iterations of the solve again from a solve whose arms' self-clearance passed its check,
    with margins calibrated on the real geoms of that solve's poses
    (:mod:`retarget.calibrated_margins`; robots with loose enclosures only; 0: off). On G1 and
    the first 20 corpus clips of ``benchmarks/retarget_peers.py`` (rolling feet) the keypoints
    came 3.25 -> 3.11 cm from the human's (about half of it from the iterations alone: 3.18
    with the margins unchanged) with no self-collision; G1 retargets 21-40 % slower
    (docs/BENCHMARKS.md, 2026-12-05)."""
