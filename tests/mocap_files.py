"""Small files of recorded-motion formats built from the real HumanML3D sample's joints (tests only).

The name tables are written out here, independently of ``controlmm.motion.formats.naming``, so a
wrong name in the library fails the tests.
"""

from __future__ import annotations

import numpy as np

from controlmm.motion.skeleton import JOINT_INDEX

_SIDES = (("left", "Left"), ("right", "Right"))


def _hips_style(toe: str, spines: tuple[str, str, str], collar: str = "Shoulder") -> dict[str, str]:
    names = {"pelvis": "Hips", "neck": "Neck", "head": "Head"}
    names.update(zip(("spine1", "spine2", "spine3"), spines, strict=True))
    for side, word in _SIDES:
        names.update(
            {
                f"{side}_hip": f"{word}UpLeg",
                f"{side}_knee": f"{word}Leg",
                f"{side}_ankle": f"{word}Foot",
                f"{side}_foot": f"{word}{toe}",
                f"{side}_collar": f"{word}{collar}",
                f"{side}_shoulder": f"{word}Arm",
                f"{side}_elbow": f"{word}ForeArm",
                f"{side}_wrist": f"{word}Hand",
            }
        )
    return names


LAFAN1 = _hips_style("Toe", ("Spine", "Spine1", "Spine2"))
MIXAMO = {k: f"mixamorig:{v}" for k, v in _hips_style("ToeBase", ("Spine", "Spine1", "Spine2")).items()}
CMU = _hips_style("ToeBase", ("Spine", "SpineMid", "Spine1"))
CMU_INSERT = {"LowerBack": "spine1", "LHipJoint": "left_hip", "RHipJoint": "right_hip", "Neck1": "head"}
CMU_METRES_PER_UNIT = 0.0254 / 0.45
CUSTOM = {k: f"J_{k.upper()}" for k in JOINT_INDEX}  # a skeleton no family knows


def hand_joints(joints: np.ndarray, wrist: str, count: int, seed: int) -> np.ndarray:
    """``count`` plausible finger joints (T, count, 3): fixed offsets of 2-9 cm from the wrist along
    the forearm direction."""
    rng = np.random.default_rng(seed)
    w = joints[:, JOINT_INDEX[wrist]]
    e = joints[:, JOINT_INDEX[wrist.replace("wrist", "elbow")]]
    along = (w - e) / np.linalg.norm(w - e, axis=-1, keepdims=True)
    reach = rng.uniform(0.02, 0.09, count)
    side = rng.normal(0.0, 0.015, (count, 3))
    return w[:, None] + along[:, None] * reach[None, :, None] + side[None]


def smplh(joints: np.ndarray) -> np.ndarray:
    """SMPL-H body-first layout (T, 52, 3): 22 body joints, 15 left-hand, 15 right-hand joints."""
    return np.concatenate(
        [joints, hand_joints(joints, "left_wrist", 15, 1), hand_joints(joints, "right_wrist", 15, 2)], axis=1
    )


def smplx(joints: np.ndarray) -> np.ndarray:
    """SMPL-X layout (T, 55, 3): 22 body joints, jaw, eyes, then 15 + 15 hand joints."""
    head = joints[:, JOINT_INDEX["head"]]
    face = np.stack([head + (0, -0.05, 0.06), head + (0.03, 0.04, 0.08), head + (-0.03, 0.04, 0.08)], axis=1)
    return np.concatenate([joints, face, smplh(joints)[:, 22:]], axis=1)


def smplh_depth_first(joints: np.ndarray) -> np.ndarray:
    """The 52 SMPL-H joints in the depth-first (PHC / InterMimic) order."""
    body = smplh(joints)
    j = JOINT_INDEX
    order = [j["pelvis"]]
    for side in ("left", "right"):
        order += [j[f"{side}_hip"], j[f"{side}_knee"], j[f"{side}_ankle"], j[f"{side}_foot"]]
    order += [j["spine1"], j["spine2"], j["spine3"], j["neck"], j["head"]]
    for side, start in (("left", 22), ("right", 37)):
        order += [j[f"{side}_collar"], j[f"{side}_shoulder"], j[f"{side}_elbow"], j[f"{side}_wrist"]]
        order += list(range(start, start + 15))
    return body[:, order]


def z_up(joints: np.ndarray) -> np.ndarray:
    """Y-up positions turned Z up the AMASS way: (x, y, z) -> (x, -z, y)."""
    return np.stack([joints[..., 0], -joints[..., 2], joints[..., 1]], axis=-1)
