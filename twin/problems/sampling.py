"""Seeded random motion queries in a scene: `RandomQueries` (what to draw), `sample_query` (one draw),
`straight_free` (whether a query's straight joint motion is collision-free).

Below `twin.compare`: a compare scenario's `random:` block and `twin problems export` draw the same
queries from here, so an exported problem set holds exactly the queries that scenario plans.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Literal

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, field_validator

from twin.errors import ConfigError
from twin.types import Pose

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.robot.kinematics import URArm

__all__ = ["RandomQueries", "sample_query", "straight_free"]

_SAMPLE_TRIES = 2000  # draws for one valid configuration
_PAIR_TRIES = 300  # valid (start, goal) pairs tried for a `straight: blocked|free` condition


class RandomQueries(BaseModel):
    """Seeded random queries: `count` per seed, start and goal with the TCP pointing down at a random
    yaw (+-90 deg) inside a box (base frame, m), at least `min_clearance_m` from the environment and
    `min_travel_m` apart. The start takes the IK branch nearest the home posture, the goal the IK
    solution nearest the start.

    `goal`: the goal configuration (`joint`), the TCP pose reached exactly (`pose`), or the TCP position
    within `position_tolerance_m` with the orientation free (`position`: what receding-horizon planners
    such as `nmpc`, which track a position, can be compared on).

    `straight` says how hard a query is: `blocked` keeps only queries whose straight joint motion from
    the start to the goal configuration collides (so a planner has to search), `free` only those where
    it does not, `any` takes what comes. The goal is drawn in `goal_region_*` when given (else in the
    same box as the start): narrow passages, such as into a bin from beside another one.

    The default box is the work area in front of the arm, over the table; in the warehouse scene it
    straddles the obstacle wall, so straight-line planners meet it.
    """

    model_config = ConfigDict(extra="forbid", frozen=True)

    count: int = Field(ge=1, le=10_000)
    goal: Literal["joint", "pose", "position"] = "joint"
    position_tolerance_m: float = Field(0.03, gt=0, le=0.1)  # `goal: position` only: the TCP within this
    straight: Literal["free", "blocked", "any"] = "any"
    region_x: tuple[float, float] = (-0.65, -0.25)
    region_y: tuple[float, float] = (-0.35, 0.35)
    region_z: tuple[float, float] = (0.05, 0.40)
    goal_region_x: tuple[float, float] | None = None
    goal_region_y: tuple[float, float] | None = None
    goal_region_z: tuple[float, float] | None = None
    min_clearance_m: float = Field(0.02, ge=0)
    min_travel_m: float = Field(0.10, ge=0)

    @field_validator("region_x", "region_y", "region_z", "goal_region_x", "goal_region_y", "goal_region_z")
    @classmethod
    def _ordered(cls, v: tuple[float, float] | None) -> tuple[float, float] | None:
        if v is not None and not v[0] <= v[1]:
            raise ValueError(f"range must be [min, max] with min <= max, got {list(v)}")
        return v


def _box(random: dict[str, Any], prefix: str) -> tuple[np.ndarray, np.ndarray]:
    rx, ry, rz = (random.get(f"{prefix}region_{a}") or random[f"region_{a}"] for a in "xyz")
    return np.array([rx[0], ry[0], rz[0]]), np.array([rx[1], ry[1], rz[1]])


def _region_text(random: dict[str, Any], prefix: str = "") -> str:
    lo, hi = _box(random, prefix)
    return " ".join(f"{a}=[{lo[i]:g}, {hi[i]:g}]" for i, a in enumerate("xyz"))


def sample_query(
    random: dict[str, Any],
    rng: np.random.Generator,
    *,
    scene: PlanningScene,
    kin: URArm,
    home: np.ndarray,
    resolution_rad: float = 0.01,
) -> dict[str, Any]:
    """A random query (as a QuerySpec dict): start and goal with the TCP pointing down at a random yaw
    (+-90 deg), the start in `region_*` on the IK branch nearest `home`, the goal in `goal_region_*`
    (default: the same box) on the IK solution nearest the start, both clear of the environment and of
    the arm itself; with `straight: blocked|free`, pairs are drawn until the straight joint motion between
    them collides (or does not), checked every `resolution_rad`.

    Raises ConfigError when the region yields no valid configuration in a few thousand draws, or no pair
    with the asked straight motion in a few hundred valid pairs.
    """
    start_box, goal_box = _box(random, ""), _box(random, "goal_")
    want = random.get("straight", "any")

    def one(box: tuple[np.ndarray, np.ndarray], near: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
        p = rng.uniform(box[0], box[1])
        yaw = float(rng.uniform(-0.5 * math.pi, 0.5 * math.pi))  # a parallel gripper is symmetric under pi
        T = Pose.from_xyz_rpy(p, (math.pi, 0.0, yaw)).matrix()
        sols = kin.ik(T)
        if sols.shape[0] == 0:
            return None
        q = sols[int(np.argmin(np.linalg.norm(sols - near, axis=1)))]
        if scene.in_collision(q) or scene.min_distance(q, include_self=False).distance < random["min_clearance_m"]:
            return None
        return q, np.array([*p, math.pi, 0.0, yaw])

    def no_query(what: str) -> ConfigError:
        return ConfigError(
            f"no collision-free random {what} in region {_region_text(random, 'goal_' if what == 'goal' else '')} "
            f"after {_SAMPLE_TRIES} draws; widen it or lower min_clearance_m (now {random['min_clearance_m']:g})"
        )

    for _ in range(_PAIR_TRIES):
        start = None
        for _ in range(_SAMPLE_TRIES):
            start = one(start_box, home)
            if start is not None:
                break
        if start is None:
            raise no_query("start")
        goal = None
        for _ in range(_SAMPLE_TRIES):
            goal = one(goal_box, start[0])
            if goal is not None and np.linalg.norm(goal[1][:3] - start[1][:3]) >= random["min_travel_m"]:
                break
            goal = None
        if goal is None:
            raise no_query("goal")
        if want == "any":
            break
        free = scene.check_path(np.stack([start[0], goal[0]]), resolution_rad=resolution_rad).free
        if free == (want == "free"):
            break
    else:
        where = _region_text(random)
        if any(random.get(f"goal_region_{a}") for a in "xyz"):
            where += f" to goal region {_region_text(random, 'goal_')}"
        raise ConfigError(
            f"random queries in {where}: none of {_PAIR_TRIES} collision-free pairs has a {want} straight joint "
            f"motion; move the regions (blocked: start and goal on either side of an obstacle) or use straight: any"
        )
    out: dict[str, Any] = {
        "start": start[0].tolist(),
        "goal": None,
        "goal_pose": None,
        "frame": "tcp",
        "orientation_free": False,
        "position_tolerance_m": None,
    }
    if random["goal"] == "joint":
        out["goal"] = goal[0].tolist()
    elif random["goal"] == "position":
        out["goal_pose"] = goal[1].tolist()
        out["orientation_free"], out["position_tolerance_m"] = True, random["position_tolerance_m"]
    else:
        out["goal_pose"] = goal[1].tolist()
    return out


def straight_free(query: dict[str, Any], *, scene: PlanningScene, kin: URArm, resolution_rad: float) -> bool | None:
    """Whether the straight joint motion from the query's start to its goal is collision-free (checked
    every `resolution_rad`); for a pose goal, to the IK solution nearest the start. None when a pose goal
    has no IK solution."""
    start = np.asarray(query["start"], dtype=float)
    if query.get("goal") is not None:
        goal = np.asarray(query["goal"], dtype=float)
    else:
        x, y, z, r, p, yw = query["goal_pose"]
        sols = kin.ik(Pose.from_xyz_rpy((x, y, z), (r, p, yw)).matrix(), query.get("frame", "tcp"))
        if sols.shape[0] == 0:
            return None
        goal = sols[int(np.argmin(np.linalg.norm(sols - start, axis=1)))]
    return bool(scene.check_path(np.stack([start, goal]), resolution_rad=resolution_rad).free)
