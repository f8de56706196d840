"""`compiled.rrtconnect` (plugins/twin_compiled): RRT-Connect compiled on the planning model. Its paths must pass
the FCL judge (every one: the model is conservative and each segment is proven free continuously), the same
seed must give the same path, it must search where the straight motion is blocked, and `twin compare` must take
it like any planner."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from twin.collision import PlanningScene
from twin.compare import compare_spec_from_dict, run_comparison
from twin.config import PlannerBlock, Settings, load_config
from twin.planning import limits_from_settings, make_context, make_planner
from twin.robot import Robot
from twin.robot.urdf_model import pose_from_xyz_rpy
from twin.testing import contract_queries
from twin.types import JointGoal, MotionRequest, PoseGoal, Status

ROOT = Path(__file__).resolve().parent.parent


def queries(settings: Settings, scene: PlanningScene, n: int, seed: int) -> list[tuple[np.ndarray, np.ndarray]]:
    """n seeded (start, goal) pairs of the planner contract in `scene` (tool moves over the cell, both ends
    FCL-free), those whose straight joint motion collides first."""
    found = contract_queries(settings, scene, Robot.from_settings(settings).arm, 3 * n, seed)
    found.sort(key=lambda q: q.straight_free)
    return [(q.start, q.goal) for q in found[:n]]


@pytest.fixture(scope="module")
def cells() -> dict[str, tuple[Settings, PlanningScene]]:
    """The RoboCup cell, and the warehouse cell holding a cube (the held box checked too)."""
    s = load_config("robocup")
    w = load_config("warehouse")
    held = PlanningScene.from_settings(w)
    held.attach_box("cube", [0.05] * 3, pose_from_xyz_rpy((0.0, 0.0, 0.03), (0.0, 0.0, 0.0)))
    return {"robocup": (s, PlanningScene.from_settings(s)), "warehouse": (w, held)}


@pytest.mark.parametrize("name", ["robocup", "warehouse"])
def test_every_path_passes_the_judge(cells, name) -> None:
    """Seeded queries in two cells, blocked ones first: every one solved, every trajectory accepted by
    `CheckedPlanner`'s FCL judge (none refused after the model passed it), and free in FCL checked far finer
    than the judge does; where the straight motion is blocked, the path is not it."""
    settings, scene = cells[name]
    planner = make_planner("compiled.rrtconnect", make_context(settings))
    limits = limits_from_settings(settings)
    blocked = 0
    for i, (a, b) in enumerate(queries(settings, scene, 5, seed=7)):
        r = planner.plan(MotionRequest(start=a, goal=JointGoal(b), limits=limits, time_limit_s=10.0, seed=i), scene)
        assert r.status is Status.SUCCESS, (i, r.status, r.reason)
        q = r.trajectory.q
        assert np.allclose(q[0], a) and np.allclose(q[-1], b, atol=1e-6)
        assert scene.check_path(q, resolution_rad=0.002).free
        if not scene.check_path(np.stack([a, b])).free:
            assert r.path is not None and r.path.shape[0] >= 3  # searched: not the straight motion
            blocked += 1
        assert r.info["search_time_s"] > 0 and r.info["final_check_time_s"] > 0
    assert blocked >= 1


def test_same_seed_same_path_another_seed_another(cells) -> None:
    settings, scene = cells["robocup"]
    (a, b), *_ = queries(settings, scene, 1, seed=3)
    limits = limits_from_settings(settings)

    def path(seed: int) -> np.ndarray:
        planner = make_planner("compiled.rrtconnect", make_context(settings))  # a new planner: no state carried
        r = planner.plan(MotionRequest(start=a, goal=JointGoal(b), limits=limits, time_limit_s=10.0, seed=seed), scene)
        assert r.success, r.reason
        return r.path

    first = path(11)
    assert np.array_equal(first, path(11))
    assert not np.array_equal(first, path(12))


def test_pose_goals_plan_to_a_free_ik_solution(cells) -> None:
    settings, scene = cells["robocup"]
    planner = make_planner("compiled.rrtconnect", make_context(settings))
    (a, b), *_ = queries(settings, scene, 1, seed=5)
    from twin.types import Pose

    goal = PoseGoal(Pose.from_matrix(planner.context.kinematics.fk(b)))
    r = planner.plan(MotionRequest(start=a, goal=goal, limits=limits_from_settings(settings), time_limit_s=10.0), scene)
    assert r.success, r.reason
    assert np.allclose(planner.context.kinematics.fk(r.trajectory.q[-1]), planner.context.kinematics.fk(b), atol=1e-6)


def test_bad_starts_and_parameters_are_typed_refusals(cells) -> None:
    settings, scene = cells["robocup"]
    planner = make_planner("compiled.rrtconnect", make_context(settings))
    limits = limits_from_settings(settings)
    (a, b), *_ = queries(settings, scene, 1, seed=9)
    hit = next(q for q in np.random.default_rng(0).uniform(-np.pi, np.pi, (500, 6)) if scene.in_collision(q))
    r = planner.plan(MotionRequest(start=hit, goal=JointGoal(b), limits=limits, time_limit_s=1.0), scene)
    assert r.status is Status.INVALID_START and "in collision" in r.reason
    r = planner.plan(MotionRequest(start=a, goal=JointGoal(hit), limits=limits, time_limit_s=1.0), scene)
    assert r.status is Status.INVALID_GOAL
    from twin.errors import ConfigError

    with pytest.raises(ConfigError, match="range_rad"):
        make_planner(PlannerBlock(name="compiled.rrtconnect", params={"range_rad": -1}), make_context(settings))


def test_compare_takes_it_like_any_planner(tmp_path) -> None:
    data = {
        "name": "compiled",
        "seeds": [0],
        "time_limit_s": 2.0,
        "execute": False,
        "planners": ["compiled.rrtconnect", {"name": "compiled.rrtconnect", "retimer": "ruckig", "label": "c+ruckig"}],
        "scenarios": [
            {
                "name": "wall",
                "scene": str(ROOT / "configs" / "warehouse.yaml"),
                "random": {"count": 2, "goal": "joint", "straight": "blocked"},
            }
        ],
    }
    result = run_comparison(compare_spec_from_dict(data), out_dir=tmp_path / "out", workers=0, plots=False)
    assert len(result.rows) == 4 and all(r["success"] for r in result.rows), [r["reason"] for r in result.rows]
    assert {r["planner"] for r in result.rows} == {"compiled.rrtconnect", "c+ruckig"}
    assert all(r["step_times_s"]["search"] > 0 and "final_check" in r["step_times_s"] for r in result.rows)


def test_ompls_search_shape_also_solves_and_passes_the_judge(cells) -> None:
    """With the dynamic domain and the tree balance off and OMPL's range (the search OMPL's RRTConnect does),
    blocked queries are still solved and judged free: the refinements are options, not what makes it work."""
    settings, scene = cells["robocup"]
    block = PlannerBlock(
        name="compiled.rrtconnect", params={"dynamic_domain_rad": None, "tree_ratio": 0.0, "range_rad": None}
    )
    planner = make_planner(block, make_context(settings))
    limits = limits_from_settings(settings)
    for i, (a, b) in enumerate(queries(settings, scene, 3, seed=13)):
        r = planner.plan(MotionRequest(start=a, goal=JointGoal(b), limits=limits, time_limit_s=10.0, seed=i), scene)
        assert r.status is Status.SUCCESS, (i, r.status, r.reason)
        assert scene.check_path(r.trajectory.q, resolution_rad=0.002).free


def test_an_end_closer_than_the_search_margin_is_left_along_an_fcl_checked_way(cells) -> None:
    """A goal FCL frees and the model (touching at 0.01 mm) frees, but within the search's margin of touching:
    the search could not prove a motion out of it, so the planner leaves it along a way FCL checks and plans
    from there; the trajectory still ends on the goal and passes the judge."""
    settings, scene = cells["robocup"]
    planner = make_planner("compiled.rrtconnect", make_context(settings))
    margin = planner.params.search_margin_m
    model = scene.sphere_model()
    near_model = model.with_touch(margin)
    (a, b), *_ = queries(settings, scene, 1, seed=21)
    rng = np.random.default_rng(4)
    goal = None
    for _ in range(200):  # bisect from the free goal toward a colliding configuration to the margin's band
        hit = rng.uniform(-np.pi, np.pi, 6)
        if not scene.in_collision(hit):
            continue
        lo, hi = b, hit
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if not near_model.in_collision(mid) else (lo, mid)
        if not model.in_collision(hi) and not scene.in_collision(hi):
            goal = hi
            break
    assert goal is not None, "no configuration within the search margin that the model and FCL free"
    limits = limits_from_settings(settings)
    r = planner.plan(MotionRequest(start=a, goal=JointGoal(goal), limits=limits, time_limit_s=10.0, seed=1), scene)
    assert r.status is Status.SUCCESS, r.reason
    assert r.info["escapes"] == 1
    assert np.allclose(r.trajectory.q[-1], goal, atol=1e-6)
    assert scene.check_path(r.trajectory.q, resolution_rad=0.002).free
