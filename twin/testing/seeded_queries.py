"""The seeded starts and goals the check asks: found in the scene itself, so the same seed gives the same
queries for every planner, and a plugin's own tests can reuse them."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twin.errors import TwinError
from twin.types import JointGoal, Pose, PoseGoal

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.config import Settings
    from twin.robot.kinematics import URArm

__all__ = ["Query", "contract_queries"]

_CLEARANCE_M = 0.02  # queries' starts and goals are at least this far from anything


@dataclass(frozen=True, eq=False)
class Query:
    """A collision-free start (6,) and goal configuration (6,), rad; `straight_free`: whether the straight
    joint motion between them is free (False: a planner has to search)."""

    start: np.ndarray
    goal: np.ndarray
    straight_free: bool
    label: str


def _top_down(p: np.ndarray, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = np.array([[c, s, 0.0], [s, -c, 0.0], [0.0, 0.0, -1.0]])  # tool z down, turned by yaw
    T[:3, 3] = p
    return T


class _Sampler:
    """Collision-free top-down configurations in the scene's reach, on the IK branch nearest `home`."""

    def __init__(self, scene: PlanningScene, kin: URArm, home: np.ndarray, rng: np.random.Generator):
        self.scene, self.kin, self.home, self.rng = scene, kin, home, rng

    def pose(self) -> tuple[np.ndarray, float]:
        r = self.rng.uniform(0.30, 0.70)
        a = self.rng.uniform(0.5 * math.pi, 1.5 * math.pi)  # in front of the arm (the work area lies at -x)
        p = np.array([r * math.cos(a), r * math.sin(a), self.rng.uniform(0.03, 0.30)])
        return p, float(self.rng.uniform(-0.5 * math.pi, 0.5 * math.pi))

    def config(self, T: np.ndarray, near: np.ndarray) -> np.ndarray | None:
        sols = self.kin.ik(T, all_wraps=False)
        if sols.shape[0] == 0:
            return None
        q = sols[int(np.argmin(np.abs(sols - near).max(axis=1)))]
        if self.scene.in_collision(q) or self.scene.min_distance(q, include_self=False).distance < _CLEARANCE_M:
            return None
        return q

    def free(self, a: np.ndarray, b: np.ndarray, resolution_rad: float) -> bool:
        return bool(self.scene.check_path(np.stack([a, b]), resolution_rad=resolution_rad).free)

    def line_free(self, a: np.ndarray, Tb: np.ndarray) -> bool:
        """Whether the tool can move on the straight line from its pose at `a` to `Tb` (yaw turning
        evenly) without colliding or jumping IK branches, checked every 1 cm."""
        Ta = self.kin.fk(a, "tcp")
        n = max(2, math.ceil(float(np.linalg.norm(Tb[:3, 3] - Ta[:3, 3])) / 0.01) + 1)
        ya, yb = math.atan2(Ta[1, 0], Ta[0, 0]), math.atan2(Tb[1, 0], Tb[0, 0])
        dy = math.remainder(yb - ya, 2 * math.pi)
        q, qs = a, []
        for s in np.linspace(0.0, 1.0, n)[1:]:
            sols = self.kin.ik(_top_down(Ta[:3, 3] + s * (Tb[:3, 3] - Ta[:3, 3]), ya + s * dy), all_wraps=False)
            if sols.shape[0] == 0:
                return False
            nxt = sols[int(np.argmin(np.abs(sols - q).max(axis=1)))]
            if np.abs(nxt - q).max() > 0.3:
                return False
            q = nxt
            qs.append(q)
        return not bool(self.scene.in_collision_batch(np.array(qs)).any())


def contract_queries(
    settings: Settings, scene: PlanningScene, kin: URArm, n: int, seed: int, *, blocked: bool = True
) -> list[Query]:
    """`n` seeded queries in `scene`: a move of at least 0.2 m of tool travel whose straight joint motion and
    straight tool line are free; with `blocked`, one whose straight joint motion collides (a sampling planner
    must search); a short move (8-15 cm, a small turn, the same IK branch: a Cartesian line's query); then
    free or blocked moves of at least 0.2 m. Deterministic for a given scene and seed; raises TwinError when
    the scene offers no such queries."""
    rng = np.random.default_rng(seed)
    home = np.asarray(settings.robot.home, dtype=float)
    res = settings.collision.check_resolution_rad
    s = _Sampler(scene, kin, home, rng)
    out: list[Query] = []
    for _ in range(4000):
        if len(out) >= n:
            return out
        p, yaw = s.pose()
        a = s.config(_top_down(p, yaw), home)
        if a is None:
            continue
        short = 2 if blocked else 1
        if len(out) == short:
            d = rng.uniform(0.08, 0.15)
            h = rng.uniform(0.0, 2 * math.pi)
            pb = p + np.array([d * math.cos(h), d * math.sin(h), rng.uniform(-0.03, 0.03)])
            b = s.config(_top_down(pb, yaw + rng.uniform(-0.3, 0.3)), a)
            if b is None or np.abs(b - a).max() > 1.0 or not s.free(a, b, res) or not s.line_free(a, kin.fk(b, "tcp")):
                continue
            out.append(Query(a, b, True, "short move, straight joint motion free"))
            continue
        pb, yb = s.pose()
        b = s.config(_top_down(pb, yb), a)
        if b is None or np.linalg.norm(pb - p) < 0.2:
            continue
        free = s.free(a, b, res)
        if len(out) < short and free != (len(out) == 0):  # the first free, the second blocked
            continue
        if len(out) == 0 and not s.line_free(a, _top_down(pb, yb)):  # free for a Cartesian line as well
            continue
        out.append(Query(a, b, free, "straight joint motion " + ("free" if free else "blocked")))
    raise TwinError(
        f"found only {len(out)} of {n} collision-free queries in the scene (seed {seed}); is the work area blocked?"
    )


def _goal(kind: str, q: np.ndarray, kin: URArm) -> JointGoal | PoseGoal:
    """The goal configuration `q` as a goal of `kind`: the joints, the tool pose, or the tool position
    (orientation free, within 3 cm: what a task's transfer asks for)."""
    if kind == "joint":
        return JointGoal(q)
    pose = Pose.from_matrix(kin.fk(q, "tcp"))
    if kind == "pose":
        return PoseGoal(pose)
    return PoseGoal(pose, position_tolerance_m=0.03, orientation_tolerance_rad=None)


def _served_goal(kinds: tuple[str, ...], T: np.ndarray, q: np.ndarray | None, kind: str) -> JointGoal | PoseGoal | None:
    if kind not in kinds:
        return None
    if kind == "joint":
        return None if q is None else JointGoal(q)
    if kind == "pose":
        return PoseGoal(Pose.from_matrix(T))
    return PoseGoal(Pose.from_matrix(T), position_tolerance_m=0.03, orientation_tolerance_rad=None)
