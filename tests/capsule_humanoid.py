"""A capsule humanoid MJCF written for the tests, three ways, as humanoid files are written.

``capsule_humanoid_xml(style)`` writes one 1.7 m humanoid (a three-link spine, a head,
two-joint clavicles, ball shoulders and hips, knees and elbows of three and two hinges at one
point as SMPL humanoids have, hands with a finger and a thumb link (the thumb turned 90
degrees lies in the finger, as the CMU humanoid's can), feet with a toe link; capsules and
spheres only, no actuators):

* ``"plain"``: +Z up, facing +X, the root at identity (as the Menagerie robots are);
* ``"turned"``: the root body's frame Y up and the robot facing -Y in the world, as the
  dm_control CMU humanoid is written: every position, segment and joint axis below the root
  is given in that rotated frame;
* ``"lying"``: the whole robot written Y up with the root at identity, as SMPL humanoids
  are: in MuJoCo's Z-up world it lies along +Y, facing +Z.

All three are one robot: retargeting must treat them alike.
"""

from __future__ import annotations

import numpy as np

Vec = tuple[float, float, float]


def _rot_x(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def _rot_z(deg: float) -> np.ndarray:
    c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _quat(rot: np.ndarray) -> np.ndarray:
    w = np.sqrt(max(1.0 + np.trace(rot), 1e-12)) / 2
    return np.array(
        [
            w,
            (rot[2, 1] - rot[1, 2]) / (4 * w),
            (rot[0, 2] - rot[2, 0]) / (4 * w),
            (rot[1, 0] - rot[0, 1]) / (4 * w),
        ]
    )


def _limb(
    side: str,
    sign: float,
    forearm_roll: bool = False,
    clavicle_drop: float = 0.0,
    rigid_hand: str = "",
    clavicle_yaw: bool = False,
) -> tuple[list, list]:
    """(arm, leg) bodies of one side: (name, pos, joints [(name, axis, range)], geoms) nested;
    ``forearm_roll``, ``clavicle_drop``, ``rigid_hand``, ``clavicle_yaw``: see
    :func:`capsule_humanoid_xml`."""
    s = sign
    finger = (
        "fingers_" + side,
        (0, 0, -0.08),
        [("fingers_" + side, (0, 1, 0), (0, 90))],
        [("capsule", (0, 0, -0.01, 0, 0, -0.06), 0.015)],
        [],
    )
    thumb = (
        "thumb_" + side,
        (0.04, 0, -0.04),
        [("thumb_" + side, (0, 1, 0), (0, 90))],
        [("capsule", (0, 0, 0, 0.03, 0, -0.03), 0.012)],
        [],
    )
    hand = (
        "hand_" + side,
        (0, 0, -0.26),
        [("hand_x_" + side, (1, 0, 0), (-60, 60)), ("hand_y_" + side, (0, 1, 0), (-60, 60))],
        [("sphere", (0, 0, -0.04), 0.04)],
        [finger, thumb],
    )
    if rigid_hand == "inline":  # a 24 cm mitten without joints, attached where the wrist is
        hand = ("hand_" + side, (0, 0, -0.26), [], [("capsule", (0, 0, -0.02, 0, 0, -0.2), 0.04)], [])
    elif rigid_hand == "aside":  # attached 10 cm in front of the forearm, reaching back below it
        hand = ("hand_" + side, (0.1, 0, -0.2), [], [("capsule", (0, 0, 0, -0.1, 0, -0.2), 0.04)], [])
    forearm = (
        "forearm_" + side,
        (0, 0, -0.29),
        [("elbow_" + side, (0, 1, 0), (-150, 0)), ("elbow_twist_" + side, (0, 0, 1), (-90, 90))],
        [("capsule", (0, 0, -0.03, 0, 0, -0.22), 0.033)],
        [hand],
    )
    if forearm_roll:  # the hand rigid on a link that rolls about the forearm 8 cm past the elbow
        roll = (
            "forearm_roll_" + side,
            (0, 0, -0.08),
            [("forearm_roll_" + side, (0, 0, 1), (-90, 90))],
            [("capsule", (0, 0, -0.02, 0, 0, -0.14), 0.033)],
            [(hand[0], (0, 0, -0.18), [], hand[3], hand[4])],
        )
        forearm = (
            "forearm_" + side,
            (0, 0, -0.29),
            [("elbow_" + side, (0, 1, 0), (-150, 0))],
            [("capsule", (0, 0, -0.03, 0, 0, -0.06), 0.033)],
            [roll],
        )
    upper = (
        "upperarm_" + side,
        (0, s * 0.17, -clavicle_drop),
        [
            (f"shoulder_{a}_" + side, ax, (-170, 170))
            for a, ax in (("x", (1, 0, 0)), ("y", (0, 1, 0)), ("z", (0, 0, 1)))
        ],
        [("capsule", (0, 0, -0.04, 0, 0, -0.24), 0.04)],
        [forearm],
    )
    clavicle_axes = ((0, 0, 1), (1, 0, 0)) if not clavicle_drop or clavicle_yaw else ((0, 1, 0), (1, 0, 0))
    clavicle = (
        "clavicle_" + side,
        (0, s * 0.05, 0.25 + clavicle_drop),
        [
            ("clavicle_" + side, clavicle_axes[0], (-20, 20)),
            ("clavicle_x_" + side, clavicle_axes[1], (-20, 20)),
        ],
        [("capsule", (0, s * 0.03, 0, 0, s * 0.1, 0), 0.035)],
        [upper],
    )
    toes = (
        "toes_" + side,
        (0.12, 0, -0.04),
        [("toes_" + side, (0, 1, 0), (-30, 30))],
        [("sphere", (0.02, 0, 0), 0.03)],
        [],
    )
    foot = (
        "foot_" + side,
        (0, 0, -0.42),
        [("ankle_y_" + side, (0, 1, 0), (-50, 50)), ("ankle_x_" + side, (1, 0, 0), (-30, 30))],
        [("capsule", (-0.05, 0, -0.04, 0.1, 0, -0.04), 0.03)],
        [toes],
    )
    shin = (
        "shin_" + side,
        (0, 0, -0.42),
        [
            ("knee_" + side, (0, 1, 0), (0, 150)),
            ("knee_x_" + side, (1, 0, 0), (-5, 5)),
            ("knee_z_" + side, (0, 0, 1), (-5, 5)),
        ],
        [("capsule", (0, 0, -0.05, 0, 0, -0.36), 0.05)],
        [foot],
    )
    thigh = (
        "thigh_" + side,
        (0, s * 0.09, -0.05),
        [
            (f"hip_{a}_" + side, ax, rng)
            for a, ax, rng in (
                ("x", (1, 0, 0), (-60, 60)),
                ("y", (0, 1, 0), (-130, 30)),
                ("z", (0, 0, 1), (-60, 60)),
            )
        ],
        [("capsule", (0, 0, -0.05, 0, 0, -0.36), 0.06)],
        [shin],
    )
    return [clavicle], [thigh]


STYLES = ("plain", "turned", "lying")
_LAID = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
"""Forward (+X) -> +Z, left (+Y) -> +X, up (+Z) -> +Y: a Y-up humanoid facing +Z."""


def capsule_humanoid_xml(
    style: str = "turned",
    forearm_roll: bool = False,
    bare_forearms: bool = False,
    clavicle_drop: float = 0.0,
    rigid_hand: str = "",
    clavicle_yaw: bool = False,
) -> str:
    """The MJCF text (see the module docstring); ``forearm_roll``: the arms end as the older
    G1's do, an elbow, then a link that only rolls about the forearm 8 cm past it and carries
    the hand (no wrist joint); ``bare_forearms``: the forearms, hands, fingers and thumbs carry
    no geometry, only their masses (an inertial where their geom's centre was);
    ``clavicle_drop``: the clavicle joints this far (m) above the shoulder, which stays where
    it is, turning the clavicle forward and sideways (Atlas's is 25 cm above its shoulder-roll
    hinge), not about the hanging arm; ``rigid_hand``: hands without joints or fingers, a
    mitten 24 cm long (GMR's T1 file, its wrist joints left out): ``"inline"`` attached on the
    forearm's line 26 cm past the elbow, ``"aside"`` attached 10 cm in front of that line and
    reaching back below the forearm (ToddlerBot's hand hangs off a gear 34 degrees aside);
    ``clavicle_yaw``: with ``clavicle_drop``, the first clavicle joint turns about the vertical,
    the hanging arm's own direction (loco-mujoco's Atlas: its clavicle's yaw)."""
    # world: where the file puts an intended (Z up, facing +X) vector; root_rot: the root
    # body's frame; local: the intended vector in the root's frame.
    world = {"plain": np.eye(3), "turned": _rot_z(-90), "lying": _LAID}[style]
    root_rot = world @ _rot_x(90) if style == "turned" else np.eye(3)
    local = root_rot.T @ world

    def vec(v: tuple[float, ...]) -> str:
        out = np.concatenate([local @ np.asarray(v[i : i + 3], dtype=float) for i in range(0, len(v), 3)])
        return " ".join(f"{x:.6g}" for x in out)

    def body(spec: tuple, indent: str) -> str:
        name, pos, joints, geoms, children = spec
        lines = [f'{indent}<body name="{name}" pos="{vec(pos)}">']
        for jname, axis, (lo, hi) in joints:
            lines.append(f'{indent}  <joint name="{jname}" axis="{vec(axis)}" range="{lo} {hi}"/>')
        for gtype, where, size in geoms:
            if bare_forearms and name.split("_")[0] in ("forearm", "hand", "fingers", "thumb"):
                centre = np.reshape(where, (-1, 3)).mean(axis=0)
                inertia = 'mass="0.3" diaginertia="1e-3 1e-3 1e-3"'
                lines.append(f'{indent}  <inertial pos="{vec(tuple(centre))}" {inertia}/>')
                continue
            attr = "fromto" if gtype == "capsule" else "pos"
            lines.append(f'{indent}  <geom type="{gtype}" {attr}="{vec(where)}" size="{size}"/>')
        lines += [body(c, indent + "  ") for c in children]
        lines.append(f"{indent}</body>")
        return "\n".join(lines)

    arms, legs = zip(
        *(
            _limb(side, s, forearm_roll, clavicle_drop, rigid_hand, clavicle_yaw)
            for side, s in (("l", 1.0), ("r", -1.0))
        ),
        strict=True,
    )
    head = (
        "head",
        (0, 0, 0.3),
        [("neck_x", (1, 0, 0), (-45, 45)), ("neck_y", (0, 1, 0), (-45, 45))],
        [("sphere", (0, 0, 0.1), 0.1)],
        [],
    )
    chest = (
        "chest",
        (0, 0, 0.15),
        [(f"chest_{a}", ax, (-30, 30)) for a, ax in (("x", (1, 0, 0)), ("y", (0, 1, 0)), ("z", (0, 0, 1)))],
        [("capsule", (0, -0.09, 0.1, 0, 0.09, 0.1), 0.08)],
        [head, *[a[0] for a in arms]],
    )
    lowerback = (
        "lowerback",
        (0, 0, 0.1),
        [("spine_x", (1, 0, 0), (-30, 30)), ("spine_y", (0, 1, 0), (-30, 30))],
        [("capsule", (0, -0.07, 0.05, 0, 0.07, 0.05), 0.075)],
        [chest],
    )
    children = "\n".join(body(c, "      ") for c in (lowerback, *[leg[0] for leg in legs]))
    w, x, y, z = _quat(root_rot)
    x0, y0, z0 = world @ np.array([0.0, 0.0, 0.96])
    return f"""<mujoco model="capsule_humanoid_{style}">
  <compiler angle="degree"/>
  <default><geom friction="0.8"/><joint damping="1" armature="0.01"/></default>
  <worldbody>
    <body name="root" pos="{x0:.6g} {y0:.6g} {z0:.6g}" quat="{w:.9g} {x:.9g} {y:.9g} {z:.9g}">
      <freejoint name="root"/>
      <geom type="capsule" fromto="{vec((0, -0.09, 0, 0, 0.09, 0))}" size="0.08"/>
{children}
    </body>
  </worldbody>
</mujoco>
"""
