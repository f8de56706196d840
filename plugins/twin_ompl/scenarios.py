"""Seeded motion queries in the reference scenes, shared by the OMPL tests and `bench/bench_ompl.py`.

RoboCup: table to table or into a bin, below its rim. Warehouse: carrying a 50 mm cube from behind the wall
to in front of it (or back), both below the wall's top, with the wall as perception would report it.

`straight="blocked"` keeps only queries whose straight joint motion collides (to each of the nearest goal
configurations): what a planner must search for, so a success rate measured on them measures the planner
rather than the straight line. `"free"` keeps the others, `"any"` takes every query.
"""

from __future__ import annotations

import math
from typing import Any, Literal

import numpy as np

from twin.plugin import (
    JointGoal,
    PlanningScene,
    Pose,
    PoseGoal,
    Settings,
    limits_from_settings,
    load_config,
    make_context,
)

__all__ = ["CUBE_M", "QueryCell", "Straight", "top_down"]

Straight = Literal["any", "free", "blocked"]

TOP_DOWN = np.diag([1.0, -1.0, -1.0])
CUBE_M = 0.05


def top_down(x: float, y: float, z: float, yaw: float) -> np.ndarray:
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, :3] = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ TOP_DOWN
    T[:3, 3] = (x, y, z)
    return T


class QueryCell:
    """Settings, FCL scene (perceived obstacle boxes added, the cube held in the warehouse), context."""

    def __init__(self, name: str):
        self.name = name
        self.settings: Settings = load_config(name)
        self.scene = PlanningScene.from_settings(self.settings)  # the obstacles as boxes, as compare plans
        if name == "warehouse":
            self.scene.attach_box("cube", [CUBE_M] * 3, np.eye(4))
        self.ctx = make_context(self.settings)
        self.kin = self.ctx.kinematics
        self.limits = limits_from_settings(self.settings)
        self.home = np.array(self.settings.robot.home)

    def ik_near_home(self, T: np.ndarray) -> np.ndarray | None:
        sols = self.kin.ik(T, all_wraps=False)
        if sols.shape[0] == 0:
            return None
        for q in sols[np.argsort(np.abs(sols - self.home).max(axis=1))][:2]:
            if not self.scene.in_collision(q):
                return q
        return None

    def goal_configs(self, start: np.ndarray, goal: Any) -> np.ndarray:
        """The goal as configurations: a joint goal, or every collision-free IK solution, nearest first."""
        if isinstance(goal, JointGoal):
            return np.asarray(goal.q)[None]
        sols = self.kin.ik(goal.pose.matrix(), goal.frame)
        sols = sols[~self.scene.in_collision_batch(sols)] if sols.shape[0] else sols
        return sols[np.argsort(np.abs(sols - start).max(axis=1))][:64]

    def blocked(self, start: np.ndarray, goals: np.ndarray) -> bool:
        """True when the straight joint motion to each of the (up to) 3 nearest goal configurations collides,
        checked at the scene config's collision resolution."""
        res = self.settings.collision.check_resolution_rad
        return not any(self.scene.check_path(np.stack([start, g]), resolution_rad=res).free for g in goals[:3])

    def queries(self, n: int, seed: int, straight: Straight | bool = "any") -> list[tuple[np.ndarray, Any, np.ndarray]]:
        """`n` seeded queries (start (6,), goal, goal configurations (k, 6) nearest first), alternating joint
        and pose goals. `straight`: "blocked" / "free" / "any" (True means "blocked", False "any")."""
        if isinstance(straight, bool):
            straight = "blocked" if straight else "any"
        if straight not in ("any", "free", "blocked"):
            raise ValueError(f"straight must be 'any', 'free' or 'blocked', got {straight!r}")
        rng = np.random.default_rng(seed)

        def yaw() -> float:
            return float(rng.uniform(-math.pi, math.pi))

        out: list[tuple[np.ndarray, Any, np.ndarray]] = []
        draws = 0
        while len(out) < n:
            draws += 1
            if draws > 500 * max(n, 1):
                raise RuntimeError(f"{self.name}: only {len(out)} of {n} {straight} queries in {draws - 1} draws")
            if self.name == "warehouse":
                Ta = top_down(rng.uniform(-0.66, -0.55), rng.uniform(0.10, 0.32), rng.uniform(0.05, 0.15), yaw())
                Tb = top_down(rng.uniform(-0.34, -0.26), rng.uniform(0.10, 0.36), rng.uniform(0.05, 0.15), yaw())
            else:
                Ta = top_down(rng.uniform(-0.62, -0.30), rng.uniform(-0.30, 0.30), rng.uniform(0.03, 0.30), yaw())
                if rng.random() < 0.6:
                    side = 1.0 if rng.random() < 0.5 else -1.0
                    Tb = top_down(
                        rng.uniform(-0.19, -0.01), side * rng.uniform(0.40, 0.50), rng.uniform(0.05, 0.10), yaw()
                    )
                else:
                    Tb = top_down(rng.uniform(-0.62, -0.30), rng.uniform(-0.30, 0.30), rng.uniform(0.03, 0.30), yaw())
            if rng.random() < 0.5:
                Ta, Tb = Tb, Ta
            a, b = self.ik_near_home(Ta), self.ik_near_home(Tb)
            if a is None or b is None:
                continue
            goal = PoseGoal(Pose.from_matrix(Tb)) if len(out) % 2 else JointGoal(b)
            goals = self.goal_configs(a, goal)
            if goals.shape[0] == 0 or (straight != "any" and self.blocked(a, goals) != (straight == "blocked")):
                continue
            out.append((a, goal, goals))
        return out
