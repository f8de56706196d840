"""croc under a lagging controller: the measured state trails the commanded one (a 50 ms lag at dt 0.08 s: the
arm measures ~0.6 of its last step behind), so the solve starts off the plan it made, with the step it was
commanded; near the obstacle wall its rows can then leave no plan within the step and acceleration bounds (CSQP's
QP ran its 1000 ADMM iterations and gave steps of 0.153-0.156 rad against the 0.150 bound), and the last plan's
steps do not pass from there either. The loop brakes to rest and solves again from there
(`RecedingHorizonMPC._recover`) instead of losing the goal ("no feasible plan is left to follow")."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

pytest.importorskip("crocoddyl")
pytest.importorskip("mim_solvers")

from twin.config import PlannerBlock, load_config
from twin.planning import make_context, make_planner
from twin.types import MotionResult
from twin_nmpc.scenarios import build_scene, transfer_scenes

LAG = 0.6  # of the last commanded step: 50 ms of an 80 ms step


def _lagged_run(mode: str, index: int) -> tuple[MotionResult, list[dict[str, Any]], float]:
    """The closed loop on transfer scene `index` with the measured state LAG of a step behind each segment's end;
    its result, its solve log and the largest joint step of any segment."""
    settings = load_config("warehouse")
    ctx = make_context(settings)
    ts = transfer_scenes(5, 0, settings=settings)[index]
    scene = build_scene(settings, ts)
    planner = make_planner(PlannerBlock(name="croc", params={"dt": 0.08, "mode": mode}), ctx)
    planner.reset(ts.request, scene)
    q, biggest = ts.request.start.copy(), 0.0
    for _ in range(300):
        out = planner.step(q)
        if isinstance(out, MotionResult):
            break
        Q = out.trajectory.q
        np.testing.assert_allclose(Q[0], q, atol=1e-12)  # every segment starts at the measured state
        biggest = max(biggest, float(np.abs(np.diff(Q, axis=0)).max()))
        q = Q[-1] - LAG * (Q[-1] - Q[-2])
    assert isinstance(out, MotionResult)
    return out, planner.inner._solve_log, biggest


@pytest.mark.parametrize(("mode", "index"), [("seed", 2), ("seed", 4), ("whole_arm", 2)])
def test_a_lagging_controller_does_not_lose_the_goal(mode: str, index: int) -> None:
    # seed mode, scenes 2 and 4: before, "solve 9 failed (a joint step of 0.156 rad exceeds 0.150 rad) and no
    # feasible plan is left to follow" and "solve 8 failed (... 0.155 rad ...)"
    out, log, biggest = _lagged_run(mode, index)
    assert out.success, out.reason
    assert biggest <= 0.15 + 1e-7  # what was commanded kept the step bound
    # the case is the one meant: some solve from a lagged state was rejected, and the loop went on
    assert any("rejected" in e for e in log)


def test_a_plan_that_runs_into_a_collision_ahead_is_braked_and_solved_again() -> None:
    """Warehouse stress seed 1160 (croc): a warm plan bent the upper arm into the held cube (gripped across two
    edges) a few steps ahead; the loop braked to a stop and ended the goal ("the plan runs into a collision
    (upper_arm_link with cube) within 4 steps; braked to a stop"), and the cube was lost. Now it brakes to rest
    and solves again cold, as for a segment with no free stop. Here such a verdict is forced on a nominal
    transfer (before, the goal ended there; from rest a cold solve may still find no plan, and then it ends)."""
    settings = load_config("warehouse")
    ctx = make_context(settings)
    ts = transfer_scenes(5, 0, settings=settings)[2]
    scene = build_scene(settings, ts)
    planner = make_planner(PlannerBlock(name="croc", params={"dt": 0.08}), ctx)
    planner.reset(ts.request, scene)
    inner = planner.inner
    real, calls = inner._collision_ahead, []

    def ahead(knots: np.ndarray) -> tuple[str, int] | None:
        calls.append(knots)
        return ("upper_arm_link with cube", 4) if len(calls) == 6 else real(knots)  # the arm at speed by then

    inner._collision_ahead = ahead
    q = ts.request.start.copy()
    for _ in range(300):
        out = planner.step(q)
        if isinstance(out, MotionResult):
            break
        q = out.trajectory.q[-1]
    assert len(calls) > 6, "the loop went on after the forced verdict"
    assert isinstance(out, MotionResult) and out.success, out.reason
    assert inner._recoveries == 1
