"""What the plugin itself returned, recorded inside its CheckedPlanner: every rule is judged on the plugin's
own output as well as on what the runs get, and only a stand-in for the plugin can see the former."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.types import MotionRequest, MotionResult, Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene

__all__: list[str] = []


@dataclass(eq=False)
class _Call:
    """One call into the plugin: `what` (plan, reset, step), its wall time, and its output or exception."""

    what: str
    elapsed_s: float
    output: Any = None
    error: BaseException | None = None


class _Recorder:
    """Stands in for the plugin inside its CheckedPlanner and records every call and what it returned."""

    def __init__(self, inner: Any):
        self._inner = inner
        self.calls: list[_Call] = []

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__"):
            raise AttributeError(attr)
        return getattr(self._inner, attr)

    def _call(self, what: str, fn: Callable[[], Any]) -> Any:
        t0 = time.perf_counter()
        try:
            out = fn()
        except Exception as e:
            self.calls.append(_Call(what, time.perf_counter() - t0, error=e))
            raise
        self.calls.append(_Call(what, time.perf_counter() - t0, output=out))
        return out

    def plan(self, request: MotionRequest, scene: PlanningScene) -> Any:
        return self._call("plan", lambda: self._inner.plan(request, scene))

    def reset(self, request: MotionRequest, scene: PlanningScene) -> Any:
        return self._call("reset", lambda: self._inner.reset(request, scene))

    def step(self, q: np.ndarray) -> Any:
        return self._call("step", lambda: self._inner.step(q))


class _TimingPlant:
    """The kinematic plant (`twin.planning.KinematicPlant`), timing each checked step: from the state read
    to the checked segment handed over."""

    def __init__(self, q: np.ndarray):
        self.q = np.asarray(q, dtype=float).copy()
        self.step_times: list[float] = []
        self._t: float | None = None

    def measured_q(self) -> np.ndarray:
        self._t = time.perf_counter()
        return self.q

    def run(self, traj: Trajectory) -> str | None:
        if self._t is not None:
            self.step_times.append(time.perf_counter() - self._t)
        self.q = traj.q[-1].copy()
        return None


@dataclass(eq=False)
class _Outcome:
    """One request, asked once: what the plugin returned (`calls`) and what the runs got (`result`)."""

    label: str
    purpose: str  # "query", "unreachable", "colliding_goal", "invalid_start", "repeat"
    request: MotionRequest
    calls: list[_Call]
    result: MotionResult | None
    error: BaseException | None  # raised out of the checked call (by the plugin or by CheckedPlanner)
    wall_s: float
    checked_step_times: list[float] = field(default_factory=list)

    @property
    def raw_error(self) -> BaseException | None:
        return next((c.error for c in self.calls if c.error is not None), None)

    @property
    def segments(self) -> list[Any]:
        return [
            c.output
            for c in self.calls
            if c.what == "step" and c.output is not None and not isinstance(c.output, MotionResult)
        ]

    @property
    def raw_result(self) -> MotionResult | None:
        """The plugin's own final answer: plan()'s result, or the MotionResult a step() ended with."""
        for c in self.calls:
            if c.what in ("plan", "step") and isinstance(c.output, MotionResult):
                return c.output
        return None

    def raw_trajectories(self) -> list[Trajectory]:
        """Every trajectory the plugin returned: a one-shot result's, or each segment's."""
        out = [s.trajectory for s in self.segments if isinstance(getattr(s, "trajectory", None), Trajectory)]
        r = self.raw_result
        if r is not None and r.success and r.trajectory is not None and not self.segments:
            out.append(r.trajectory)
        return out

    def raw_motion(self) -> Trajectory | None:
        """The motion the plugin commanded as one trajectory (segments joined as `drive` joins them)."""
        trajs = self.raw_trajectories()
        if not trajs:
            return None
        return trajs[0] if len(trajs) == 1 else _join(trajs)

    def to_json(self) -> dict[str, Any]:
        raw = self.raw_result
        return {
            "label": self.label,
            "purpose": self.purpose,
            "goal_kind": self.request.goal.kind,
            "raw_status": None if raw is None else raw.status.value,
            "raw_segments": len(self.segments),
            "raw_error": None if self.raw_error is None else f"{type(self.raw_error).__name__}: {self.raw_error}",
            "status": None if self.result is None else self.result.status.value,
            "reason": None if self.result is None else self.result.reason,
            "error": None if self.error is None else f"{type(self.error).__name__}: {self.error}",
            "wall_time_s": self.wall_s,
        }


def _join(pieces: list[Trajectory]) -> Trajectory:
    t, q, qd, qdd = [pieces[0].t - pieces[0].t[0]], [pieces[0].q], [pieces[0].qd], [pieces[0].qdd]
    offset = float(t[0][-1])
    for p in pieces[1:]:
        if p.t.shape[0] < 2:
            continue
        t.append(p.t[1:] - p.t[0] + offset)
        q.append(p.q[1:])
        qd.append(p.qd[1:])
        qdd.append(p.qdd[1:])
        offset = float(t[-1][-1])
    return Trajectory(np.concatenate(t), np.concatenate(q), np.concatenate(qd), np.concatenate(qdd))
