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
"""A throwaway third-party twin plugin: a straight joint-space planner with constant velocity, a crashing
receding-horizon planner, and a task that waves the arm and places nothing."""
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
        if not isinstance(request.goal, JointGoal):
            return MotionResult(Status.INVALID_GOAL, "acme.straight takes joint goals only")
        dq = request.goal.q - request.start
        vel = request.limits.max_joint_vel * self.params.speed_fraction
        T = max(float(np.max(np.abs(dq) / vel)), 1e-3)
        t = np.linspace(0.0, T, 50)
        q = request.start + np.outer(t / T, dq)
        qd = np.tile(dq / T, (50, 1))
        return MotionResult(Status.SUCCESS, "", Trajectory(t, q, qd, np.zeros_like(q)))


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


@hookimpl
def twin_register_tasks(registry):
    registry.add_task("acme.wave", "acme_twin_plugin:Wave", description="waves the arm (test plugin)")


@hookimpl
def twin_register_planners(registry):
    registry.add_planner(
        "acme.straight", "acme_twin_plugin:StraightLine", description="straight joint line (test plugin)"
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
