"""The planning model (twin.collision.planning_model): the sphere cover alone decides, touching = in collision.
It must never call free what FCL calls in collision (random configurations, configurations a hair inside a
contact, a held object, every primitive kind, padding), its motion check must answer as its configurations
do, and the exact escape from a start it refuses must be judged by FCL."""

from __future__ import annotations

import itertools
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tests.test_spheres import contact_configs, fcl_only, random_configs, scenes
from twin.collision import PlanningScene, SphereModel
from twin.collision.planning_model import OVERSHOOT_BOUND_M, leave_cover
from twin.errors import InvalidRequestError


@pytest.fixture(scope="module")
def cells(tmp_path_factory: pytest.TempPathFactory) -> dict[str, PlanningScene]:
    return scenes(tmp_path_factory.mktemp("planning-model"))


@pytest.mark.parametrize("name", ["robocup", "warehouse", "mixed"])
def test_the_model_never_calls_free_what_fcl_calls_colliding(cells: dict[str, PlanningScene], name: str) -> None:
    """Random configurations and configurations a hair (< 1e-11 rad) inside a contact: every one FCL finds in
    collision the model finds touching. The model is useful too: it frees most of what FCL frees."""
    scene = cells[name]
    model = scene.sphere_model()
    qs = np.vstack([random_configs(scene, 1500, seed=3), contact_configs(scene, 60, seed=4)])
    exact = fcl_only(scene, qs)
    touching = model.in_collision_batch(qs)
    assert not np.any(exact & ~touching), qs[exact & ~touching][:3]
    assert exact.any() and (~exact).any()
    assert np.mean(~touching[~exact]) > 0.8  # the cover refuses few of FCL's free configurations
    one_by_one = np.array([model.in_collision(q) for q in qs[:100]])
    assert np.array_equal(one_by_one, touching[:100])


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), name=st.sampled_from(["robocup", "warehouse", "mixed"]))
def test_a_motion_is_free_only_when_all_its_configurations_are(
    cells: dict[str, PlanningScene], seed: int, name: str
) -> None:
    """The compiled motion check (coarse to fine, early exit) against the configurations it stands for, checked
    one by one: free exactly when every one is; and FCL finds none of a free motion's configurations colliding."""
    scene = cells[name]
    model = scene.sphere_model()
    rng = np.random.default_rng(seed)
    a = random_configs(scene, 1, seed)[0]
    b = a + rng.uniform(-0.6, 0.6, 6)
    res = 0.02
    n = max(1, math.ceil(float(np.abs(b - a).max()) / res - 1e-9))
    along = a + (np.arange(1, n + 1) / n)[:, None] * (b - a)
    each = model.in_collision_batch(along)
    hit = model.first_collision_on_motion(a, b, res)
    assert (hit is None) == (not each.any())
    if hit is not None:
        assert each[round(hit * n) - 1]
    else:
        assert not fcl_only(scene, along).any()


def test_the_held_object_and_the_opening_are_in_the_snapshot(cells: dict[str, PlanningScene]) -> None:
    """A model is its scene as it was: holding a cube (warehouse), configurations where only the cube touches
    are refused by the model made while it was held; FCL agrees on every refusal it must make."""
    scene = cells["warehouse"]
    held = scene.sphere_model()
    name = scene.detach()
    try:
        empty = scene.sphere_model()
        qs = random_configs(scene, 3000, seed=9)
        assert np.sum(held.in_collision_batch(qs) & ~empty.in_collision_batch(qs)) > 0
    finally:
        scene.attach_box(name, [0.05] * 3, _held_pose())
    assert not np.any(fcl_only(scene, qs) & ~held.in_collision_batch(qs))


def _held_pose() -> np.ndarray:
    from twin.robot.urdf_model import pose_from_xyz_rpy

    return pose_from_xyz_rpy((0.0, 0.01, 0.0), (0.0, 0.0, 0.3))


def test_leave_cover_leaves_a_start_closer_than_the_overshoot_on_an_exactly_checked_way(
    cells: dict[str, PlanningScene],
) -> None:
    """A start FCL calls free that the cover calls touching (within the overshoot of something): `leave_cover` finds
    a configuration the model frees, every configuration on the way FCL-free; a start that is really in
    collision has no escape."""
    scene = cells["robocup"]
    model = scene.sphere_model()
    qs = contact_configs(scene, 80, seed=12)
    exact_free = lambda q: not fcl_only(scene, np.asarray(q)[None])[0]  # noqa: E731
    found = 0
    rng = np.random.default_rng(1)
    for q in qs:
        # back off the contact a little: FCL-free, yet inside the cover's overshoot
        free = next((p for p in (q + rng.normal(0, 2e-3, 6) for _ in range(20)) if exact_free(p)), None)
        if free is None or not model.in_collision(free):
            continue
        out = leave_cover(free, random_configs(scene, 1, seed=found)[0], model, exact_free, 0.01)
        if out is None:
            continue
        found += 1
        assert not model.in_collision(out)
        steps = np.linspace(0.0, 1.0, 30)[:, None]
        assert not fcl_only(scene, free + steps * (out - free)).any()
    assert found >= 3
    assert leave_cover(qs[0], qs[1], model, exact_free, 0.01) is None  # in collision itself: no way out starts free


def test_bad_input_is_a_typed_error(cells: dict[str, PlanningScene]) -> None:
    model: SphereModel = cells["robocup"].sphere_model()
    with pytest.raises(InvalidRequestError, match="6 joint angles"):
        model.in_collision(np.zeros(5))
    with pytest.raises(InvalidRequestError, match="finite"):
        model.in_collision(np.full(6, np.nan))
    with pytest.raises(InvalidRequestError, match="resolution_rad"):
        model.motion_free(np.zeros(6), np.ones(6), 0.0)
    assert 0.002 <= OVERSHOOT_BOUND_M <= 0.01


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 10_000), name=st.sampled_from(["robocup", "warehouse", "mixed"]))
def test_a_motion_the_continuous_check_frees_is_free_in_fcl_at_any_resolution(
    cells: dict[str, PlanningScene], seed: int, name: str
) -> None:
    """Conservative advancement proves a whole straight motion free, not its samples: FCL finds none of 2000
    configurations along a freed motion colliding, and a motion FCL finds colliding somewhere is never freed."""
    scene = cells[name]
    model = scene.sphere_model()
    rng = np.random.default_rng(seed)
    a = random_configs(scene, 1, seed)[0]
    b = a + rng.uniform(-1.0, 1.0, 6)
    along = a + np.linspace(0.0, 1.0, 2000)[:, None] * (b - a)
    exact = fcl_only(scene, along)
    t = model.first_touch_continuous(a, b)
    if t is None:
        assert not exact.any()
    else:
        assert 0.0 <= t <= 1.0
    if exact.any():
        assert t is not None


@settings(max_examples=15, deadline=None)
@given(seed=st.integers(0, 10_000), name=st.sampled_from(["robocup", "warehouse", "mixed"]))
def test_a_polyline_proven_free_is_free_in_fcl_everywhere(
    cells: dict[str, PlanningScene], seed: int, name: str
) -> None:
    """The one-pass continuous check of a polyline (a trajectory's samples): a polyline it proves free has no
    FCL collision anywhere (checked 20 points a segment), and one with an FCL collision is never proven past
    the segment where it collides."""
    scene = cells[name]
    model = scene.sphere_model()
    rng = np.random.default_rng(seed)
    a = random_configs(scene, 1, seed)[0]
    qs = a + np.cumsum(rng.uniform(-0.05, 0.05, (60, 6)), axis=0)
    dense = np.vstack([p + np.linspace(0.0, 1.0, 20)[:, None] * (q - p) for p, q in itertools.pairwise(qs)])
    exact = fcl_only(scene, dense)
    first = model.first_unproven_segment(qs)
    if first is None:
        assert not exact.any()
    if exact.any():
        assert first is not None and first <= np.flatnonzero(exact)[0] // 20
