"""State validity and motion validation for OMPL from the FCL planning scene, and the final trajectory check.

Why this shape: planning cost is (number of configurations checked) x (cost of one check, ~25-40 us in
FCL); the Python callback itself is ~1 us. So the motion validator hands all interpolated states of a
motion to the scene at once (`first_collision`, vectorised kinematics, early exit) and orders them
coarse-to-fine (bisection order), so a colliding motion is usually rejected within the first batch.
A motion's states are spaced at most `resolution_rad` apart in every joint (max-abs norm, not OMPL's
L2 fraction of the space extent, so the spacing does not depend on the sampling bounds).

OMPL 2.0.1's MotionValidator trampoline maps `checkMotion(s1, s2, lastValid)` onto the two-argument
form without filling `lastValid`, so planners that use it (KPIECE, LBKPIECE) see an invalid motion as
invalid from its start: they lose partial extensions, never validity.
"""

from __future__ import annotations

import math
from time import perf_counter
from typing import Any

import numpy as np
import ompl.base as ob

from twin.plugin import PlanningScene, SphereModel

__all__ = [
    "CheckCounter",
    "SceneMotionValidator",
    "bisection_order",
    "state_validity_checker",
]


class CheckCounter:
    """Counts of what the planner asked the scene (reported in MotionResult.info), the first error raised
    inside a callback (OMPL would otherwise swallow it), and two ends after which every new state and
    motion is reported invalid (counted in `expired`): a deadline (perf_counter seconds) and a work limit
    (`check_limit`, on `checks`). Some planners check their termination condition only between long
    batches of checks (FMT*-like batch planners), or not at all inside a loop (AORRTC's connect loop in
    OMPL 2.0.1 can advance forever); a refusal ends those at once. A refusal by work count comes at the
    same point on every run, so a search it ends is repeatable (`twin_ompl.budget`)."""

    __slots__ = ("check_limit", "configs", "deadline", "error", "expired", "iterations", "motions", "states")

    def __init__(self) -> None:
        self.states = 0
        self.motions = 0
        self.configs = 0
        self.error: BaseException | None = None
        self.deadline = math.inf
        self.check_limit = math.inf  # refuse once `checks` reaches this
        self.iterations = 0  # times a work budget's termination condition was asked (twin_ompl.budget)
        self.expired = 0

    @property
    def checks(self) -> int:
        """Configurations checked for collision: states asked about plus the states along checked motions."""
        return self.states + self.configs


_ORDER_CACHE: dict[int, np.ndarray] = {}


def bisection_order(n: int) -> np.ndarray:
    """Fractions k/n, k = 1..n, coarse to fine: n first (the end state), then the midpoints of ever finer
    halvings. Checking in this order finds a collision inside a motion after few configurations."""
    cached = _ORDER_CACHE.get(n)
    if cached is not None:
        return cached
    seen = np.zeros(n + 1, dtype=bool)
    order: list[int] = [n]
    seen[n] = True
    step = 1 << max(0, math.ceil(math.log2(n)) - 1) if n > 1 else 1
    while step >= 1:
        ks = np.arange(step, n, step)
        new = ks[~seen[ks]]
        seen[new] = True
        order.extend(new.tolist())
        step //= 2
    out = np.array(order, dtype=float) / n
    if len(_ORDER_CACHE) < 4096:
        _ORDER_CACHE[n] = out
    return out


def state_validity_checker(scene: PlanningScene | SphereModel, counter: CheckCounter) -> Any:
    """A plain function for `si.setStateValidityChecker`: True when the state is collision-free."""
    in_collision = scene.in_collision

    def is_valid(state: Any) -> bool:
        if perf_counter() > counter.deadline or counter.states + counter.configs >= counter.check_limit:
            counter.expired += 1
            return False
        counter.states += 1
        try:
            return not in_collision(np.array(state[0:6]))
        except BaseException as e:  # noqa: BLE001 - OMPL cannot carry Python exceptions; re-raised after solve
            counter.error = counter.error or e
            return False

    return is_valid


# OMPL ships no type information (`ompl` is ignore_missing_imports), so its base class is Any to mypy
class SceneMotionValidator(ob.MotionValidator):  # type: ignore[misc]
    """Checks the straight joint-space motion s1 -> s2 (s1 assumed valid, as OMPL does) in one batch."""

    def __init__(self, si: Any, scene: PlanningScene | SphereModel, resolution_rad: float, counter: CheckCounter):
        super().__init__(si)
        self.scene = scene
        self.resolution_rad = float(resolution_rad)
        self.counter = counter

    def checkMotion(self, s1: Any, s2: Any, *_: Any) -> bool:  # OMPL's method name
        c = self.counter
        if perf_counter() > c.deadline or c.states + c.configs >= c.check_limit:
            c.expired += 1
            return False
        try:
            return self.motion_free(np.array(s1[0:6]), np.array(s2[0:6]))
        except BaseException as e:  # noqa: BLE001 - see state_validity_checker
            self.counter.error = self.counter.error or e
            return False

    def motion_free(self, a: np.ndarray, b: np.ndarray) -> bool:
        """True when every configuration on a -> b, spaced <= resolution_rad per joint, is free (b included)."""
        d = b - a
        n = max(1, math.ceil(float(np.abs(d).max()) / self.resolution_rad - 1e-9))
        if isinstance(self.scene, SphereModel):  # the planning model: one compiled call, coarse to fine
            self.counter.motions += 1
            self.counter.configs += n  # at most: the compiled call does not say how many it evaluated
            return self.scene.first_collision_on_motion(a, b, self.resolution_rad) is None
        qs = a + bisection_order(n)[:, None] * d
        self.counter.motions += 1
        hit = self.scene.first_collision(qs)
        self.counter.configs += n if hit is None else min(n, (hit // 32 + 1) * 32)
        return hit is None
