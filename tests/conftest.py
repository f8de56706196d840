"""Shared fixtures: a throwaway third-party plugin distribution, installed on sys.path for one test."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

# Written against the plugin API the README documented before `twin.plugin` existed (`from twin import
# hookimpl`, `twin.types`, `twin.planning`): it must keep working. The task `acme.wave` is the newer hook.
ACME_PLUGIN = '''
"""A throwaway third-party twin plugin: a straight joint-space planner within the limits but without a
collision check, one beyond the limits, one that raises on its first plan(), a crashing receding-horizon
planner, and a task that waves the arm and places nothing."""
import numpy as np
from pydantic import BaseModel, ConfigDict, Field

from twin import hookimpl
from twin.types import JointGoal, MotionResult, Status, Trajectory


class StraightLine:
    class Params(BaseModel):
        model_config = ConfigDict(extra="forbid")
        speed_fraction: float = Field(0.5, gt=0, le=1)

    def __init__(self, params, context):
        self.params = params
        self.context = context

    def plan(self, request, scene):
        """A quintic blend from rest to rest, its duration the shortest that keeps `speed_fraction` of every
        joint limit (peak velocity 1.875 d/T, acceleration 5.774 d/T^2, jerk 60 d/T^3)."""
        if not isinstance(request.goal, JointGoal):
            return MotionResult(Status.INVALID_GOAL, "acme.straight takes joint goals only")
        dq = request.goal.q - request.start
        lim, f, d = request.limits, self.params.speed_fraction, np.abs(dq)
        T = max(
            float(np.max(1.875 * d / (f * lim.max_joint_vel))),
            float(np.max(np.sqrt(5.7735 * d / (f * lim.max_joint_acc)))),
            float(np.max(np.cbrt(60.0 * d / (f * lim.max_joint_jerk)))),
            1e-3,
        )
        t = np.linspace(0.0, T, 200)
        u = t / T
        s = 10 * u**3 - 15 * u**4 + 6 * u**5
        sd = (30 * u**2 - 60 * u**3 + 30 * u**4) / T
        sdd = (60 * u - 180 * u**2 + 120 * u**3) / T**2
        return MotionResult(
            Status.SUCCESS,
            "",
            Trajectory(t, request.start + np.outer(s, dq), np.outer(sd, dq), np.outer(sdd, dq)),
        )


class Crash:
    """A receding-horizon planner that ignores the scene: it lowers the shoulder 0.05 rad per segment,
    straight into the table, and would report success at `lift` rad below its start."""

    class Params(BaseModel):
        model_config = ConfigDict(extra="forbid")
        lift: float = Field(1.6, gt=0)

    def __init__(self, params, context):
        self.params = params

    def reset(self, request, scene):
        self.target = request.start + np.array([0.0, self.params.lift, 0.0, 0.0, 0.0, 0.0])

    def step(self, q):
        from twin.planning import Segment

        d = self.target - q
        if np.abs(d).max() < 1e-6:
            arrived = Trajectory(np.zeros(1), q[None], np.zeros((1, 6)), np.zeros((1, 6)))
            return MotionResult(Status.SUCCESS, "arrived", arrived)
        dq = d * min(1.0, 0.05 / np.abs(d).max())
        t = np.array([0.0, 0.25])
        return Segment(Trajectory(t, np.stack([q, q + dq]), np.zeros((2, 6)), np.zeros((2, 6))), 1e-4, {})


class Hasty:
    """Ruckig's time-optimal straight joint line to the goal (a pose goal's nearest collision-free IK
    solution) under the request's limits, those named in `limits` times `factor`: a planner that breaks
    the joint limits and would win every race it were allowed to run."""

    class Params(BaseModel):
        model_config = ConfigDict(extra="forbid")
        limits: list[str] = ["velocity", "acceleration", "jerk"]
        factor: float = Field(3.0, gt=0)

    def __init__(self, params, context):
        self.params = params
        self.kin = context.kinematics

    def plan(self, request, scene):
        import ruckig

        a, goal = np.array(request.start), request.goal
        if isinstance(goal, JointGoal):
            b = np.array(goal.q)
        else:
            sols = self.kin.ik(goal.pose.matrix(), goal.frame)
            sols = sols[~scene.in_collision_batch(sols)] if sols.shape[0] else sols
            if sols.shape[0] == 0:
                return MotionResult(Status.INVALID_GOAL, "no collision-free IK solution of the goal")
            b = sols[int(np.argmin(np.abs(sols - a).max(axis=1)))]
        lim = request.limits
        f = {k: self.params.factor if k in self.params.limits else 1.0 for k in ("velocity", "acceleration", "jerk")}
        if np.abs(b - a).max() < 1e-9:
            still = Trajectory(np.zeros(1), a[None], np.zeros((1, 6)), np.zeros((1, 6)))
            return MotionResult(Status.SUCCESS, "", still)
        otg, inp, out = ruckig.Ruckig(6), ruckig.InputParameter(6), ruckig.Trajectory(6)
        inp.current_position, inp.target_position = a.tolist(), b.tolist()
        inp.max_velocity = (lim.max_joint_vel * f["velocity"]).tolist()
        inp.max_acceleration = (lim.max_joint_acc * f["acceleration"]).tolist()
        inp.max_jerk = (lim.max_joint_jerk * f["jerk"]).tolist()
        otg.calculate(inp, out)
        t = np.linspace(0.0, out.duration, max(2, int(np.ceil(out.duration / 0.002)) + 1))
        q, qd, qdd = (np.array(x) for x in zip(*(out.at_time(float(ti)) for ti in t)))
        q[0], q[-1] = a, b
        qd[0] = qd[-1] = qdd[0] = qdd[-1] = 0.0
        return MotionResult(Status.SUCCESS, "", Trajectory(t, q, qd, qdd))


class Wave:
    """A task: to the capture pose and home again, `times` times; it places nothing."""

    class Params(BaseModel):
        model_config = ConfigDict(extra="forbid")
        times: int = Field(1, ge=1, le=3)

    def __init__(self, params, context):
        self.params = params

    def run(self, cell):
        for _ in range(self.params.times):
            cell.move_joints("capture", np.array(cell.settings.camera.capture_pose))
            cell.move_joints("home", np.array(cell.settings.robot.home))
        return []


class Flaky(Hasty):
    """Hasty within the limits, but its first plan() raises (a bug in a plugin): the rest plan as Hasty."""

    def __init__(self, params, context):
        super().__init__(Hasty.Params(factor=1.0), context)
        self.calls = 0

    def plan(self, request, scene):
        self.calls += 1
        if self.calls == 1:
            return 1 / 0
        return super().plan(request, scene)


@hookimpl
def twin_register_tasks(registry):
    registry.add_task("acme.wave", "acme_twin_plugin:Wave", description="waves the arm (test plugin)")


@hookimpl
def twin_register_planners(registry):
    registry.add_planner(
        "acme.straight", "acme_twin_plugin:StraightLine", description="straight joint line (test plugin)"
    )
    registry.add_planner(
        "acme.hasty", "acme_twin_plugin:Hasty", description="straight line beyond a joint limit (test plugin)"
    )
    registry.add_planner(
        "acme.flaky", "acme_twin_plugin:Flaky", description="raises on its first plan(), then Hasty (test plugin)"
    )
    registry.add_planner(
        "acme.crash", "acme_twin_plugin:Crash", receding_horizon=True, description="drives into the table (test plugin)"
    )
'''


@pytest.fixture
def acme_plugin(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """A temporary distribution `acme-twin-plugin` with a `twin` entry point, put on sys.path."""
    site = tmp_path / "site"
    site.mkdir()
    (site / "acme_twin_plugin.py").write_text(textwrap.dedent(ACME_PLUGIN))
    info = site / "acme_twin_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: acme-twin-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[twin]\nacme = acme_twin_plugin\n")
    monkeypatch.syspath_prepend(str(site))
    from twin.registry import default_registry

    default_registry.cache_clear()
    yield site
    sys.modules.pop("acme_twin_plugin", None)
    default_registry.cache_clear()
