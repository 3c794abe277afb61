"""A mapping for any floating-base humanoid MJCF, inferred from its anatomy (no names read).

``infer_mapping("robot.xml")`` returns the JSON object of a mapping file
(:mod:`retarget.mapping`): :func:`retarget.anatomy.find_anatomy` finds the pelvis, torso,
head, legs and arms; each human joint follows the matching point of the robot:

* hips, knees, ankles / shoulders, elbows, wrists: the joint-group centres of each limb (the
  point nearest to a hip's axes, the knee's anchor, ...), each on the body that carries it;
* pelvis, chest (``spine3``), head and toes: points placed from the hips, shoulders and
  ankles with the HumanML3D skeleton's offsets times the robot's scale
  (:data:`retarget.human.HUMAN_OFFSETS`), the toe kept on the sole;
* ranges: the waist joints, knees and elbows kept where the robot's own geoms leave them
  clear (:mod:`retarget.clear_ranges`);
* weights: the mapping defaults (:data:`retarget.mapping.DEFAULT_WEIGHTS`); the wrist and
  head joints, which the human does not observe, are held near rest by the posture prior.

A legs-only robot maps pelvis, hips, knees, ankles and toes. The scale is ``"auto"``: the
robot's rest hip height above its soles over the human's (:data:`retarget.human.HUMAN_HIP_HEIGHT`).
``controlmm robots map ROBOT.xml --out mapping.json`` writes the object for review.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from retarget.anatomy import Anatomy, Limb, find_anatomy
from retarget.clear_ranges import clear_ranges
from retarget.geoms import collision_geoms, geom_points
from retarget.human import HUMAN_HIP_HEIGHT, HUMAN_OFFSETS
from retarget.mapping import DEFAULT_WEIGHTS, MAPPING_FORMAT, Mapping, parse_mapping
from retarget.rest_frame import rest_turn_note
from retarget.robot_files import ancestors, compile_robot, free_root, robot_mjcf_path, welded_below

SOLE_MARGIN = 0.005
"""The toe point stays this far (m) inside the sole's front edge and above its bottom."""
UNOBSERVED_POSTURE = 0.5
"""Posture weight of the joints the human does not observe (wrists, hands, neck)."""
RIGID_POSTURE = 20.0
"""Posture weight of the joints below a foot or a wrist's body (toes, fingers), past a ball
wrist (an SMPL hand's) or before a ball shoulder (a clavicle's): held at rest, the toes part
of the rigid foot the robot stands on, the fingers clear of each other, the hand in line with
the forearm, the shoulders where the human's are (SMPL's +-180 degree clavicles folded them
into the neck, and the CMU humanoid's into its chest)."""
FIVE_JOINT_LEVELS = [[3, 10], [1, 4]]
"""Solver schedule of robots with fewer than six joints in a leg (they converge more slowly)."""
SMALL_SCALE = 0.4
SMALL_W_SELF = 300.0
"""Self-clearance weight of robots smaller than SMALL_SCALE times the human: the clearance
margins (and the checks' tolerances) are absolute, large against a small robot's links."""


def _point(anatomy: Anatomy, body: int, world: np.ndarray) -> dict:
    return {
        "body": anatomy.model.body(body).name,
        "offset": [round(float(v), 4) for v in anatomy.local(body, world)],
    }


def _sole_front(anatomy: Anatomy, leg: Limb) -> tuple[float, float]:
    """The foot's sole (its link's collision geoms and those of bodies welded below it): its
    front x (m, world) and its bottom z, in the rest pose."""
    m = anatomy.model
    pts = []
    for b in (leg.end_body, *welded_below(m, leg.end_body)):
        for g in collision_geoms(m, b):
            p, r = geom_points(m, g)
            world = anatomy.xpos[b] + p @ anatomy.xmat[b].T
            pts.append(np.c_[world, r])
    if not pts:
        return float(leg.end[0]), anatomy.floor_z
    allp = np.concatenate(pts)
    low = allp[:, 2] - allp[:, 3]
    sole = allp[low <= low.min() + 0.01]
    return float((sole[:, 0] + sole[:, 3]).max()), float(low.min())


def infer_mapping(robot: str | Path, anatomy: Anatomy | None = None) -> dict:
    """The JSON object of a mapping for the humanoid MJCF ``robot`` (see the module docstring).

    ``"robot"`` holds the MJCF's absolute path. Raises ControlMMError (one line) for an MJCF
    that does not compile, has no floating base, a joint the retargeter cannot move (a ball
    joint that closes no loop: a ball shoulder; :func:`retarget.robot_files.compile_robot`) or no two
    legs.
    """
    path = robot_mjcf_path(robot)
    model = compile_robot(path)
    a = anatomy if anatomy is not None else find_anatomy(model, f"robot MJCF '{path.name}'")
    m = a.model
    hips = np.mean([leg.root for leg in a.legs.values()], axis=0)
    scale = (hips[2] - a.floor_z) / HUMAN_HIP_HEIGHT
    off = {k: scale * np.array(v) for k, v in HUMAN_OFFSETS.items()}
    kp: dict[str, dict] = {"pelvis": _point(a, a.pelvis, hips + off["pelvis"])}
    for side, leg in a.legs.items():
        kp[f"{side}_hip"] = _point(a, leg.root_body, leg.root)
        kp[f"{side}_knee"] = _point(a, leg.middle_body, leg.middle)
        kp[f"{side}_ankle"] = _point(a, leg.end_body, leg.end)
        front, bottom = _sole_front(a, leg)
        toe = leg.end + off["toe"]
        toe[0] = min(toe[0], front - SOLE_MARGIN)
        toe[2] = max(toe[2], bottom + SOLE_MARGIN)
        kp[f"{side}_foot"] = _point(a, leg.end_body, toe)
    posture: dict[str, float] = {"default": 0.02}
    for leg in a.legs.values():  # toe links: part of the foot
        for j in range(m.njnt):
            body = int(m.jnt_bodyid[j])
            if body != leg.end_body and leg.end_body in ancestors(m, body) and m.joint(j).name:
                posture[m.joint(j).name] = RIGID_POSTURE
    if a.arms and a.torso is not None:
        shoulders = np.mean([arm.root for arm in a.arms.values()], axis=0)
        kp["spine3"] = _point(a, a.torso, shoulders + off["spine3"])
        kp["head"] = _point(a, a.head if a.head is not None else a.torso, shoulders + off["head"])
        for side, arm in a.arms.items():
            kp[f"{side}_shoulder"] = _point(a, arm.root_body, arm.root)
            kp[f"{side}_elbow"] = _point(a, arm.middle_body, arm.middle)
            kp[f"{side}_wrist"] = _point(a, arm.end_body, arm.end)
            hand = [  # joints below the wrist's body (a hand's fingers)
                j
                for j in range(m.njnt)
                if int(m.jnt_bodyid[j]) != arm.end_body and arm.end_body in ancestors(m, int(m.jnt_bodyid[j]))
            ]
            for j in arm.end_joints:
                if m.joint(j).name:
                    posture[m.joint(j).name] = RIGID_POSTURE if j in arm.beyond else UNOBSERVED_POSTURE
            for j in hand:
                if m.joint(j).name:
                    posture[m.joint(j).name] = RIGID_POSTURE
            for j in arm.before:  # a clavicle: the human's barely moves
                if m.joint(j).name:
                    posture[m.joint(j).name] = RIGID_POSTURE
        if a.head is not None:
            for j in range(m.njnt):
                body = int(m.jnt_bodyid[j])
                if body in ancestors(m, a.head) and body != a.torso and a.torso in ancestors(m, body):
                    if m.joint(j).name:
                        posture[m.joint(j).name] = UNOBSERVED_POSTURE
    for joint, spec in kp.items():
        pw, sw, ow = DEFAULT_WEIGHTS.get(joint, (0.5, 1.0, 0.0))
        spec["position_weight"] = pw
        if joint != "pelvis":
            spec["segment_weight"] = sw
        if ow > 0:
            spec["orientation_weight"] = ow
    short_legs = any(len(leg.joints) < 6 for leg in a.legs.values())
    solver: dict = {"levels": FIVE_JOINT_LEVELS} if short_legs else {}
    if scale < SMALL_SCALE:
        solver["w_self"] = SMALL_W_SELF
    out: dict = {
        "format": MAPPING_FORMAT,
        "description": (
            f"Inferred from the kinematic tree and geometry of {path.name} "
            f"({'legs and arms' if a.arms else 'legs only'}); review the bodies and offsets."
        ),
        "robot": str(path),
        "scale": "auto",
        "keypoints": kp,
        "posture_weights": posture,
    }
    if a.arms:
        out["arm_abduction"] = 0.2
    ranges = clear_ranges(a)
    if ranges:  # rounded inwards
        out["ranges"] = {
            n: [math.ceil(lo * 1e4) / 1e4, math.floor(hi * 1e4) / 1e4] for n, (lo, hi) in ranges.items()
        }
    if solver:
        out["solver"] = solver
    return out


def auto_mapping(robot: str | Path) -> Mapping:
    """The inferred :class:`Mapping` of a humanoid MJCF (source: the MJCF's path)."""
    path = robot_mjcf_path(robot)
    mapping = parse_mapping(infer_mapping(path), source=str(path), base_dir=path.parent)
    return mapping


def mapping_file_text(mapping: dict, out: str | Path) -> str:
    """The JSON text of an inferred mapping to be written at ``out``, one keypoint a line: the
    MJCF path relative to the file's folder (as mapping files resolve it) when the MJCF lies
    in that folder or below, else absolute."""
    data = dict(mapping)
    try:
        relative = os.path.relpath(data["robot"], Path(out).resolve().parent)
    except ValueError:  # another drive (Windows): keep the absolute path
        relative = data["robot"]
    if not relative.startswith(".."):
        data["robot"] = relative
    lines = ["{"]
    items = list(data.items())
    for i, (key, value) in enumerate(items):
        comma = "," if i < len(items) - 1 else ""
        if key == "keypoints":
            lines.append('  "keypoints": {')
            kps = list(value.items())
            for k, (joint, spec) in enumerate(kps):
                sep = "," if k < len(kps) - 1 else ""
                lines.append(f"    {_json(joint)}: {_json(spec)}{sep}")
            lines.append("  }" + comma)
        else:
            lines.append(f"  {_json(key)}: {_json(value)}{comma}")
    lines.append("}")
    return "\n".join(lines) + "\n"


def _json(value: object) -> str:
    return json.dumps(value)


def describe_mapping(mapping: dict) -> str:
    """A few lines saying which robot point each human joint follows (for review)."""
    lines = [f"{Path(mapping['robot']).name}: scale {mapping.get('scale', 'auto')}"]
    model = compile_robot(mapping["robot"])
    root = free_root(model)
    note = rest_turn_note(model, root) if root is not None else None
    if note:
        lines.append(f"  {note}")
    width = max(len(j) for j in mapping["keypoints"])
    for joint, spec in mapping["keypoints"].items():
        where = spec.get("body") or spec.get("site")
        offset = ", ".join(f"{v:+.3f}" for v in spec.get("offset", (0.0, 0.0, 0.0)))
        lines.append(f"  {joint:<{width}}  {where}  offset ({offset}) m")
    return "\n".join(lines)
