"""`croc` (issue 28): nmpc's receding-horizon loop around a Crocoddyl + CSQP solve. Registered like nmpc, its
parameters validated; a closed-loop rollout over the warehouse wall with every segment FCL-checked by the
checked loop and every proxy sphere measured against the box; a solve whose plan the loop rejects is followed
by the last plan as a counted fallback; the whole-arm spheres cover the URDF's link cylinders, and the
whole-arm mode keeps every fixture but the table."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

pytest.importorskip("crocoddyl")
pytest.importorskip("mim_solvers")

from twin.collision.scene import PlanningScene
from twin.config import PlannerBlock, load_config
from twin.errors import ConfigError
from twin.planning import RecedingHorizonPlanner, Segment, densify_path, make_context, make_planner, plan_with
from twin.planning.proxy_spheres import clearance, sphere_positions
from twin.planning.receding_params import DEFAULT_ARM_SPHERES, DEFAULT_WHOLE_ARM_TOOL_SPHERES, RecedingParams
from twin.registry import Kind, default_registry
from twin.types import MotionResult
from twin_croc.ocp import HorizonProblem
from twin_nmpc.params import NMPCParams
from twin_nmpc.scenarios import build_scene, check_trajectory, transfer_scenes


@pytest.fixture(scope="module")
def settings():
    return load_config("warehouse")


@pytest.fixture(scope="module")
def ctx(settings):
    return make_context(settings)


@pytest.fixture(scope="module")
def scenes(settings):
    return transfer_scenes(6, 0, settings=settings)


@pytest.fixture(scope="module")
def croc(ctx):
    return make_planner(PlannerBlock(name="croc"), ctx)


def test_croc_is_registered_as_receding_horizon_with_its_extra(croc):
    e = default_registry().entry("croc")
    assert e.kind is Kind.RECEDING_HORIZON and e.extra == "croc" and e.target == "twin_croc.planner:CrocPlanner"
    assert isinstance(croc, RecedingHorizonPlanner) and not croc.jerk_limited
    nmpc = NMPCParams()
    shared = set(RecedingParams.model_fields) - {"limit_jerk"}
    assert {k: getattr(croc.params, k) for k in shared} == {k: getattr(nmpc, k) for k in shared}


@pytest.mark.parametrize(
    ("params", "message"),
    [
        ({"limit_jerk": True}, "no jerk rows"),
        ({"mode": "fast"}, "mode"),
        ({"arm_spheres": [[6, 0, 0, 0, 0.1]]}, "1 to 5"),
    ],
)
def test_bad_parameters_are_config_errors(ctx, params, message):
    with pytest.raises(ConfigError, match=message):
        make_planner(PlannerBlock(name="croc", params=params), ctx)


def test_a_closed_loop_rollout_over_the_wall_keeps_every_sphere_out(croc, scenes, settings, ctx):
    """Through the checked loop (every segment FCL-checked against the whole scene before it runs); the
    executed trajectory's proxy spheres measured against the perceived box and the arm against the table."""
    placed = 0
    for ts in scenes:
        res = plan_with(croc, ts.request, build_scene(settings, ts), ctx)
        if res.trajectory is not None:
            chk = check_trajectory(
                res.trajectory, ts, croc.proxy_spheres, build_scene(settings, ts, with_fixtures=False), ctx.kinematics
            )
            assert chk.ok, (ts.index, chk)
        placed += res.success
        log = res.info["nmpc_solve_log"]
        # warm from the last accepted solve, cold at the start and after a rejected one
        assert [e["warm"] for e in log] == [False] + [not e.get("rejected") for e in log[:-1]]
    assert placed >= len(scenes) - 1, placed


def _reject_every_solve(monkeypatch: pytest.MonkeyPatch) -> None:
    """From now on every solve's plan leaves the joint limits after its first step (the loop rejects it)."""
    real = HorizonProblem.solve

    def through_the_table(self, *a, **k):
        out = real(self, *a, **k)
        qs = out.qs.copy()
        qs[2:, 1] = 10.0
        return replace(out, qs=qs)

    monkeypatch.setattr(HorizonProblem, "solve", through_the_table)


def test_a_rejected_solve_is_followed_by_the_last_plan_as_a_counted_fallback(ctx, scenes, settings, monkeypatch):
    planner = make_planner(PlannerBlock(name="croc"), ctx)
    ts = scenes[1]
    planner.reset(ts.request, build_scene(settings, ts))
    first = planner.step(ts.request.start)
    assert isinstance(first, Segment) and not first.fallback
    plan = planner._plan.copy()
    _reject_every_solve(monkeypatch)
    out = planner.step(first.trajectory.q[-1])
    assert isinstance(out, Segment) and out.fallback and "joint" in out.info["rejected"]
    assert np.allclose(out.trajectory.q[-1], plan[2])
    res = out
    while not isinstance(res, MotionResult):
        res = planner.step(res.trajectory.q[-1])
    assert res.info["nmpc_fallbacks"] >= 1


def test_a_fallback_from_a_state_off_the_plan_takes_the_plans_steps_from_there(ctx, scenes, settings, monkeypatch):
    """The arm tracks a plan only to within its controller's error: when the step from the measured state to the
    plan's next knot breaks the acceleration bound, the fallback takes the plan's own steps from the measured
    state instead of ending the goal."""
    planner = make_planner(PlannerBlock(name="croc"), ctx)
    ts = scenes[1]
    planner.reset(ts.request, build_scene(settings, ts))
    seg = planner.step(ts.request.start)
    for _ in range(3):  # under way, the arm moving
        seg = planner.step(seg.trajectory.q[-1])
    inner = planner.inner
    plan, idx = inner._plan.copy(), inner._plan_idx
    _, dstep, _ = inner._step_bounds()
    # measured: behind the plan by 3/4 of the acceleration bound on every joint, against the direction of motion
    lag = -0.75 * dstep * np.sign(plan[idx + 1] - plan[idx])
    q = plan[idx] + lag
    assert np.any(np.abs((plan[idx + 1] - q) - inner._dq_prev) > dstep)  # the knot itself is out of reach
    _reject_every_solve(monkeypatch)
    out = planner.step(q)
    assert isinstance(out, Segment) and out.fallback
    np.testing.assert_allclose(out.trajectory.q[-1], q + plan[idx + 1] - plan[idx], atol=1e-12)


@pytest.mark.parametrize("mode", ["whole_arm", "seed"])
def test_croc_starts_with_a_sphere_in_a_box_the_link_is_clear_of_and_takes_it_no_deeper(ctx, settings, mode):
    """whole_arm: its spheres cover the links only with the box margin: a small wall 4 mm from the gripper (FCL)
    overlaps a finger sphere by 6 mm. seed: its spheres are generous (a stop before the warehouse wall under a
    lagging controller left one 1 cm inside the wall's box). The start is not refused in either mode (nmpc, whose
    NLP cannot start inside a box, refuses it); the plan reaches the goal and that sphere never goes deeper into
    the wall than it started."""
    ts = transfer_scenes(1, 0, settings=settings)[0]
    q0 = ts.request.start
    planner = make_planner(PlannerBlock(name="croc", params={"mode": mode}), ctx)
    sph = planner.inner.spheres()
    c, r = sphere_positions(ctx.kinematics, q0, sph)[0, 0], sph[0, 4]  # a fingertip sphere
    out = ctx.kinematics.fk(q0)[:3, 0]  # the finger's outside: along the tcp's -x
    ax = int(np.argmax(np.abs(out)))
    lo, hi = c - 0.012, c + 0.012
    face = c[ax] - np.sign(out[ax]) * (r - 0.006)
    if out[ax] > 0:
        lo[ax], hi[ax] = face - 0.01, face
    else:
        lo[ax], hi[ax] = face, face + 0.01
    scene = build_scene(settings, ts)
    scene.add_box_bounds("wall", lo, hi)
    wall = [("wall", lo, hi)]
    start = clearance(ctx.kinematics, q0[None], sph, wall, margin=0.0).min()
    assert start < -0.005 and not scene.in_collision(q0)
    res = plan_with(planner, ts.request, scene, ctx)
    assert res.success, res.reason
    along = clearance(ctx.kinematics, densify_path(res.trajectory.q, 0.01), sph, wall, margin=0.0)
    assert along.min() >= start - 1e-3
    assert not planner.inner._refuses_sphere_overlap()


def _surface(kind: str, size: tuple[float, ...]) -> np.ndarray:
    """(m, 4) homogeneous points on a primitive's surface, in its own frame."""
    if kind == "cylinder":
        r, length = size
        a, z = np.meshgrid(np.linspace(0, 2 * np.pi, 24), np.linspace(-length / 2, length / 2, 15))
        pts = np.stack([r * np.cos(a), r * np.sin(a), z], axis=-1).reshape(-1, 3)
    else:  # box: a grid over its volume's bounding faces (corners and edges included)
        g = [np.linspace(-e / 2, e / 2, 7) for e in size]
        pts = np.stack(np.meshgrid(*g, indexing="ij"), axis=-1).reshape(-1, 3)
    return np.hstack([pts, np.ones((pts.shape[0], 1))])


def test_the_whole_arm_spheres_cover_every_link_beyond_the_base_at_any_gripper_opening(ctx):
    """Points on every collision shape from the shoulder to the fingertips (fingers open and closed), at random
    configurations, each lie within one whole-arm sphere grown by the 1 cm box margin (what keeps the link out
    of a box)."""
    scene = PlanningScene.from_settings(load_config("robocup"))
    planner = make_planner(PlannerBlock(name="croc", params={"mode": "whole_arm"}), ctx).inner
    sph = planner.spheres()
    rng = np.random.default_rng(0)
    shapes = [s for s in scene._body.shapes if s.link != "base_link"]
    assert {s.link for s in shapes} >= {"upper_arm_link", "forearm_link", "wrist_2_link", "left_finger"}
    for opening in (0.0, scene.max_opening_m):
        scene.set_gripper_opening(opening)
        for _ in range(4):
            q = rng.uniform(-np.pi, np.pi, 6)
            poses, centres = scene.link_poses(q), sphere_positions(ctx.kinematics, q, sph)[0]
            for s in shapes:
                pts = (poses[s.link] @ s.origin @ _surface(s.kind, s.size).T).T[:, :3]
                d = np.linalg.norm(pts[:, None] - centres[None], axis=-1) - sph[None, :, 4] - 0.01
                assert d.min(axis=1).max() <= 1e-6, (s.link, opening, d.min(axis=1).max())


def test_the_whole_arm_mode_keeps_every_fixture_but_the_table(ctx):
    robocup = load_config("robocup")
    rctx = make_context(robocup)
    planner = make_planner(PlannerBlock(name="croc", params={"mode": "whole_arm"}), rctx).inner
    scene = PlanningScene.from_settings(robocup)
    planner._scene = scene
    names = {n.split("[")[0] for n, _, _ in planner._boxes()}
    assert names == set(scene.environment_shapes()) - {"table"}
    assert planner.spheres().shape[0] == len(DEFAULT_WHOLE_ARM_TOOL_SPHERES) + len(DEFAULT_ARM_SPHERES)


def test_check_planner_takes_planner_parameters_and_the_whole_arm_mode_keeps_the_contract():
    from cli_runner import twin

    r = twin("check-planner", "croc", "--param", "mode=whole_arm")
    assert r.returncode == 0 and "croc: keeps every rule" in r.stdout, (r.stdout, r.stderr)
    bad = twin("check-planner", "croc", "--param", "mode=fast")
    assert bad.returncode == 2 and "parameter 'mode'" in bad.stderr and "Traceback" not in bad.stderr
