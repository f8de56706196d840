"""Allowed-collision rules: which robot parts the planning scene tests against each other.

Self-collision exclusions (`excluded_pairs`), computed from the URDF:
1. links of one rigid body (joined by fixed joints only, e.g. wrist_3_link + tool0 + gripper_base);
2. rigid bodies joined directly by one joint (base/shoulder, shoulder/upper_arm, ..., wrist_2/wrist_3
   body, gripper_base body/fingers): their housings touch by construction;
3. pairs in contact (signed distance <= 1 mm) at a reference configuration: all zeros and the given
   postures (the home posture for a scene from settings), each with the gripper fully open and closed
   (this adds left_finger/right_finger, which touch when closed);
4. any pairs the caller adds (`extra_excluded_pairs`, e.g. from an SRDF-like "never collide" list).
The held object is never tested against the rigid body it is attached to (wrist_3 .. tcp) nor the
fingers. (Links rigidly fixed to the world are never tested against the environment; that rule lives in
the scene, which knows what moves.)

Why a module of its own: the rules depend on the robot model only, so they are computed once and a
copy of a scene (`PlanningScene.padded`) reuses them instead of measuring the reference postures again.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import fcl
import numpy as np

from twin.collision.fcl_shapes import DISTANCE_REQUEST, fcl_geometry, fcl_transform, primitive_shapes
from twin.errors import ConfigError
from twin.robot.gripper import gripper_stroke_m
from twin.robot.urdf_model import RobotModel

__all__ = [
    "CONTACT_TOL_M",
    "HELD",
    "CollisionRules",
    "contact_pairs",
    "gripper_links",
    "rigid_body_links",
    "structural_pairs",
]

log = logging.getLogger("twin")

CONTACT_TOL_M = 1e-3  # rule 3: "in contact" at a reference configuration, m
HELD = "\0held"  # node name of the held object in the self-collision pair list

Pair = tuple[str, str]


def rigid_body_links(model: RobotModel, link: str) -> set[str]:
    """Links rigidly joined to `link` (same rigid parent), `link` included."""
    root = model.rigid_parent(link)
    return {ln for ln in model.link_names if model.rigid_parent(ln) == root}


def gripper_links(model: RobotModel) -> set[str]:
    """Links moved by a gripper joint (the fingers and anything below them)."""
    out: set[str] = set()
    for gj in model.gripper_joints:
        start = model.joints[gj].child
        for ln in model.link_names:
            cur: str | None = ln
            while cur is not None and cur != start:
                cur = model.parent_link(cur)
            if cur == start:
                out.add(ln)
    return out


def _geometry_links(model: RobotModel) -> list[str]:
    return [ln for ln in model.link_names if model.links[ln].shapes]


def structural_pairs(model: RobotModel) -> set[Pair]:
    """Rules 1 and 2: links of one rigid body, and rigid bodies joined directly by one joint."""
    body = {ln: model.rigid_parent(ln) for ln in model.link_names}
    out: set[Pair] = set()
    for a, b in itertools.combinations(_geometry_links(model), 2):
        ba, bb = body[a], body[b]
        pa, pb = model.parent_link(ba), model.parent_link(bb)
        if ba == bb or (pa is not None and body[pa] == bb) or (pb is not None and body[pb] == ba):
            out.add((a, b))
    return out


def contact_pairs(
    model: RobotModel,
    reference_configs: Sequence[np.ndarray],
    openings: Sequence[float],
    *,
    skip: Iterable[Pair] = (),
    tol_m: float = CONTACT_TOL_M,
) -> set[Pair]:
    """Rule 3: link pairs whose shapes are within `tol_m` (signed distance) at any of the (6,) reference
    configurations with any of the finger openings (m). Pairs in `skip` (either order) are not measured."""
    shapes = primitive_shapes(model)
    done = set(skip) | {(b, a) for a, b in skip}
    out: set[Pair] = set()
    if not reference_configs:
        return out
    qs = np.array([np.asarray(q, dtype=float) for q in reference_configs])
    for w in openings:
        L = model.link_pose_array(qs, finger_opening=w)
        for Lq in L:
            poses = [Lq[model.link_index[s.link]] @ s.origin for s in shapes]
            objs = [
                fcl.CollisionObject(fcl_geometry(s.kind, s.size), fcl_transform(T))
                for s, T in zip(shapes, poses, strict=True)
            ]
            for i, k in itertools.combinations(range(len(shapes)), 2):
                a, b = shapes[i].link, shapes[k].link
                if a == b or (a, b) in done:
                    continue
                if fcl.distance(objs[i], objs[k], DISTANCE_REQUEST, fcl.DistanceResult()) <= tol_m:
                    out.add((a, b))
                    done |= {(a, b), (b, a)}
                    log.debug("self-collision exclusion (contact at a reference posture): %s - %s", a, b)
    return out


@dataclass(frozen=True)
class CollisionRules:
    """Which robot parts are tested against each other.

    excluded_pairs: robot link pairs never tested, each ordered as in `RobotModel.link_names`.
    held_excluded: robot links the held object is never tested against.
    """

    excluded_pairs: frozenset[Pair]
    held_excluded: frozenset[str]

    @classmethod
    def from_model(
        cls,
        model: RobotModel,
        *,
        tcp_link: str,
        reference_configs: Iterable[Sequence[float]] = (),
        extra_excluded_pairs: Iterable[Pair] = (),
    ) -> CollisionRules:
        """Rules 1-4 for `model` (module docstring); the all-zeros posture is always a reference.
        Raises ConfigError when an extra pair names a link the model does not have."""
        refs = [np.zeros(len(model.arm_joints))] + [np.asarray(r, dtype=float) for r in reference_configs]
        excl = structural_pairs(model)
        excl |= contact_pairs(model, refs, (0.0, gripper_stroke_m(model)), skip=excl)
        pos = model.link_index
        excl = {(a, b) if pos[a] < pos[b] else (b, a) for a, b in excl}
        for a, b in extra_excluded_pairs:
            if a not in pos or b not in pos:
                raise ConfigError(f"excluded pair ({a!r}, {b!r}) names a link that {model.source} does not have")
            excl.add((a, b) if pos[a] < pos[b] else (b, a))
        held = rigid_body_links(model, tcp_link) | gripper_links(model)
        return cls(frozenset(excl), frozenset(held))

    def allows(self, a: str, b: str) -> bool:
        """True when robot parts `a` and `b` (link names, or HELD for the held object) are tested."""
        if a == b:
            return False
        if HELD in (a, b):
            return (b if a == HELD else a) not in self.held_excluded
        return (a, b) not in self.excluded_pairs and (b, a) not in self.excluded_pairs

    def allowed_self_pairs(self, model: RobotModel) -> list[Pair]:
        """Robot link pairs with geometry that are tested against each other, in link order."""
        return [(a, b) for a, b in itertools.combinations(_geometry_links(model), 2) if self.allows(a, b)]
