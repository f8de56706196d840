"""The sphere model that clears configurations before FCL (twin.collision.spheres): it must be conservative
(sphere-clear implies FCL-free, above all right at contact), useful (it clears configurations with room
to spare), and invisible (every scene query answers the same with it on and off)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from twin.collision import FixtureSpec, PlanningScene
from twin.collision.spheres import cover
from twin.config import load_config
from twin.robot.urdf_model import pose_from_xyz_rpy

CUBE_M = 0.05

# a fixture with every primitive kind, turned, in the arm's reach (above the table, beside the base)
PRIMITIVES = [  # (xyz, rpy, geometry)
    ("0.35 0.25 0.25", "0.3 0.2 0.5", '<box size="0.2 0.08 0.15"/>'),
    ("-0.3 0.35 0.3", "1.2 0 0.4", '<cylinder radius="0.05" length="0.3"/>'),
    ("-0.35 -0.3 0.35", "0 0 0", '<sphere radius="0.08"/>'),
    ("0.3 -0.35 0.3", "0.7 -0.3 0", '<capsule radius="0.04" length="0.2"/>'),
]
MIXED_URDF = (
    '<robot name="mixed"><link name="body">'
    + "".join(f'<collision><origin xyz="{x}" rpy="{r}"/><geometry>{g}</geometry></collision>' for x, r, g in PRIMITIVES)
    + "</link></robot>"
)


def scenes(tmp: Path) -> dict[str, PlanningScene]:
    """The RoboCup cell, the warehouse cell holding a cube (padded by 5 mm, as the OMPL planners plan),
    and a cell with a box, cylinder, sphere and capsule, with the gripper half closed."""
    out: dict[str, PlanningScene] = {}
    s = load_config("robocup")
    out["robocup"] = PlanningScene.from_settings(s)
    w = load_config("warehouse")
    wh = PlanningScene.from_settings(w)  # the wall (known: false) as a box
    wh.attach_box("cube", [CUBE_M] * 3, pose_from_xyz_rpy((0.0, 0.01, 0.0), (0.0, 0.0, 0.3)))
    out["warehouse"] = wh.padded(0.005)
    urdf = tmp / "mixed.urdf"
    urdf.write_text(MIXED_URDF)
    mixed = PlanningScene(
        s.resolve(s.robot.urdf),
        fixtures=[FixtureSpec("mixed", urdf, np.eye(4))],
        reference_configs=[s.robot.home],
        padding_m=0.002,
    )
    mixed.set_gripper_opening(0.5 * mixed.max_opening_m)
    out["mixed"] = mixed
    return out


@pytest.fixture(scope="module")
def cells(tmp_path_factory: pytest.TempPathFactory) -> dict[str, PlanningScene]:
    return scenes(tmp_path_factory.mktemp("spheres"))


def fcl_only(scene: PlanningScene, qs: np.ndarray) -> np.ndarray:
    was = scene.sphere_filter
    scene.sphere_filter = False
    try:
        return scene.in_collision_batch(qs)
    finally:
        scene.sphere_filter = was


def random_configs(scene: PlanningScene, n: int, seed: int) -> np.ndarray:
    """Configurations over the joint limits, elbow within +-pi (beyond it the arm folds into itself)."""
    rng = np.random.default_rng(seed)
    lim = np.array([[-2 * math.pi, 2 * math.pi]] * 6)
    lim[2] = (-math.pi, math.pi)
    return rng.uniform(lim[:, 0], lim[:, 1], size=(n, 6))


def contact_configs(scene: PlanningScene, n: int, seed: int) -> np.ndarray:
    """Up to n configurations just inside a collision: FCL bisection (40 halvings, < 1e-11 rad) between a
    free and a colliding configuration drawn near each other, keeping the colliding end."""
    rng = np.random.default_rng(seed)
    qs = random_configs(scene, 4 * n, seed)
    hit = fcl_only(scene, qs)
    free, coll = qs[~hit], qs[hit]
    out = []
    for a in free[:n]:
        b = coll[rng.integers(len(coll))]
        b = a + (b - a) * rng.uniform(0.05, 1.0)  # often a short segment: contact near a free posture
        if not fcl_only(scene, b[None])[0]:
            continue
        lo, hi = a, b
        for _ in range(40):
            mid = 0.5 * (lo + hi)
            if fcl_only(scene, mid[None])[0]:
                hi = mid
            else:
                lo = mid
        out.append(hi)
    return np.array(out)


@settings(max_examples=60, deadline=None)
@given(
    kind=st.sampled_from(["box", "cylinder", "sphere", "capsule"]),
    a=st.floats(0.002, 0.3),
    b=st.floats(0.002, 0.5),
    c=st.floats(0.002, 0.3),
    seed=st.integers(0, 2**31 - 1),
)
def test_a_cover_encloses_its_primitive(kind: str, a: float, b: float, c: float, seed: int) -> None:
    """Points all over the primitive (surface, edges, corners and inside) lie in at least one sphere."""
    size = {"box": (a, b, c), "cylinder": (a, b), "capsule": (a, b), "sphere": (a,)}[kind]
    spheres = cover(kind, size)
    rng = np.random.default_rng(seed)
    u = rng.uniform(-1.0, 1.0, size=(4000, 3))
    u[:1000] = np.sign(u[:1000])  # box corners / cylinder rims
    u[1000:2000, 0] = np.sign(u[1000:2000, 0])  # faces
    if kind == "box":
        p = u * 0.5 * np.array(size)
    elif kind in ("cylinder", "capsule"):
        ang = math.pi * u[:, 0]
        rad = a * np.sqrt(np.abs(u[:, 1]))
        rad[:2000] = a  # the rim and the side
        p = np.column_stack([rad * np.cos(ang), rad * np.sin(ang), 0.5 * b * u[:, 2]])
        if kind == "capsule":  # and the caps' hemispheres
            d = rng.normal(size=(1000, 3))
            d *= a / np.linalg.norm(d, axis=1, keepdims=True)
            d[:, 2] = np.abs(d[:, 2])
            p = np.vstack([p, d + [0, 0, 0.5 * b], -d - [0, 0, 0.5 * b]])
    else:
        d = rng.normal(size=(4000, 3))
        p = d * (a * rng.uniform(0, 1, (4000, 1)) ** (1 / 3) / np.linalg.norm(d, axis=1, keepdims=True))
        p[:500] = d[:500] * (a / np.linalg.norm(d[:500], axis=1, keepdims=True))
    gap = np.linalg.norm(p[:, None, :] - spheres[None, :, :3], axis=2) - spheres[None, :, 3]
    assert gap.min(axis=1).max() <= 1e-12


@pytest.mark.parametrize("name", ["robocup", "warehouse", "mixed"])
def test_sphere_clear_implies_fcl_free(cells: dict[str, PlanningScene], name: str) -> None:
    """Thousands of seeded configurations, most of them touching or near something, and configurations
    a hair inside a contact (self or environment): none is cleared by the spheres while FCL finds a
    collision. And the spheres are worth having: they clear most configurations with 1 cm to spare."""
    scene = cells[name]
    qs = np.vstack([random_configs(scene, 3000, seed=7), contact_configs(scene, 300, seed=8)])
    clear = scene.sphere_clear(qs)
    hit = fcl_only(scene, qs)
    assert not np.any(clear & hit), qs[clear & hit][:3]
    assert hit.sum() > 1000  # the sample reaches collisions (a test that cannot fail is no test)
    roomy = np.array([scene.min_distance(q).distance > 0.01 for q in qs[~hit][:600]])
    assert clear[~hit][:600][roomy].mean() > 0.9


@pytest.mark.parametrize("name", ["robocup", "warehouse", "mixed"])
def test_every_query_answers_the_same_with_the_filter_off(cells: dict[str, PlanningScene], name: str) -> None:
    scene = cells[name]
    qs = random_configs(scene, 1500, seed=11)
    ref = fcl_only(scene, qs)
    assert np.array_equal(scene.in_collision_batch(qs), ref)
    assert [scene.in_collision(q) for q in qs[:200]] == ref[:200].tolist()
    first = int(np.argmax(ref))
    assert scene.first_collision(qs) == first
    free = qs[~ref]
    assert scene.first_collision(free) is None
    # a path through free configurations: the same verdict and the same first hit
    path = free[:40]
    on = scene.check_path(path, resolution_rad=0.01)
    scene.sphere_filter = False
    try:
        off = scene.check_path(path, resolution_rad=0.01)
    finally:
        scene.sphere_filter = True
    assert on.free == off.free and on.segment == off.segment
    assert (on.q is None and off.q is None) or np.array_equal(on.q, off.q)


def test_the_model_follows_scene_edits(cells: dict[str, PlanningScene]) -> None:
    """A box added or removed, an object attached or dropped, the fingers moved: the sphere answers stay
    conservative (no stale copy of the old scene)."""
    w = load_config("warehouse")
    scene = PlanningScene.from_settings(w)
    qs = random_configs(scene, 800, seed=3)

    def conservative() -> None:
        assert not np.any(scene.sphere_clear(qs) & fcl_only(scene, qs))

    conservative()
    scene.add_box_bounds("wall", (-0.6, 0.35, 0.0), (0.6, 0.45, 0.8))
    before = scene.sphere_clear(qs).sum()
    conservative()
    scene.attach_box("long", (0.3, 0.04, 0.04), pose_from_xyz_rpy((0.0, 0.0, 0.05), (0.0, 0.0, 0.0)))
    conservative()
    assert scene.sphere_clear(qs).sum() < before  # the held bar takes room
    scene.set_gripper_opening(0.0)
    conservative()
    scene.detach()
    scene.remove("wall")
    conservative()


@pytest.mark.parametrize("cell_name", ["robocup", "warehouse"])
def test_a_planner_plans_the_same_paths_with_the_filter_on_and_off_and_run_to_run(cell_name: str) -> None:
    """The filter changes what a check costs, never its answer: RRT-Connect, seeded, returns bit-identical
    trajectories with it on, off, and on again (blocked queries, so it searches)."""
    pytest.importorskip("ompl")
    from twin.config import PlannerBlock
    from twin.planning import make_planner, plan_with
    from twin.types import MotionRequest
    from twin_ompl.scenarios import QueryCell

    cell = QueryCell(cell_name)
    planner = make_planner(PlannerBlock(name="ompl.rrtconnect"), cell.ctx)
    runs = []
    for on in (True, False, True):
        cell.scene.sphere_filter = on
        out = []
        for k, (start, goal, _) in enumerate(cell.queries(3, seed=5, straight="blocked")):
            res = plan_with(
                planner, MotionRequest(start, goal, cell.limits, time_limit_s=5.0, seed=k), cell.scene, cell.ctx
            )
            assert res.success, res.reason
            out.append((res.trajectory.q, res.info["states_checked"], res.info["configs_checked"]))
        runs.append(out)
    for other in runs[1:]:
        for (qa, sa, ca), (qb, sb, cb) in zip(runs[0], other, strict=True):
            assert np.array_equal(qa, qb) and (sa, ca) == (sb, cb)


def test_the_kernels_compile_once_whatever_arrays_they_are_handed(cells: dict[str, PlanningScene]) -> None:
    """numba compiles a new specialisation for every new argument layout (read-only, strided, float32), and
    compiling takes seconds: inside a planner's time limit that is a timeout. The scene and the kinematics
    hand the kernels one layout only, whatever the caller passes."""
    from twin.collision.sphere_kernel import flag_configurations
    from twin.robot.kinematics import dh_frames
    from twin.robot.kinematics_kernel import dh_frames_into

    scene = cells["robocup"]
    qs = random_configs(scene, 12, seed=1)
    frozen = qs.copy()
    frozen.flags.writeable = False
    for arg in (qs, frozen, qs[::2], np.asfortranarray(qs), qs.astype(np.float32)):
        scene.in_collision_batch(arg)
        scene.first_collision(arg)
        scene.in_collision(arg[0])
        dh_frames(arg)
    assert len(flag_configurations.signatures) == 1
    assert len(dh_frames_into.signatures) == 1


@pytest.mark.parametrize("step", [0.002, 0.02])
@pytest.mark.parametrize("name", ["robocup", "warehouse", "mixed"])
def test_dense_paths_into_contact_answer_as_fcl(cells: dict[str, PlanningScene], name: str, step: float) -> None:
    """Conservative advancement (configurations close to a cleared one are cleared without evaluation) on
    dense paths, as the final checks walk them: from free configurations into a contact a hair deep, 2 and
    20 mrad apart. Every configuration's answer and the first hit are FCL's."""
    scene = cells[name]
    contacts = contact_configs(scene, 80, seed=21)
    rng = np.random.default_rng(22)
    free = random_configs(scene, 400, seed=23)
    free = free[~fcl_only(scene, free)]
    assert len(contacts) >= 10
    for q1 in contacts[:20]:
        q0 = free[rng.integers(len(free))]
        n = int(np.ceil(np.abs(q1 - q0).max() / step))
        path = q0 + np.linspace(0.0, 1.0, n + 1)[:, None] * (q1 - q0)
        path[-1] = q1
        ref = fcl_only(scene, path)
        assert ref[-1]  # the path ends in the contact
        assert np.array_equal(scene.in_collision_batch(path), ref)
        assert scene.first_collision(path) == int(np.argmax(ref))


@pytest.mark.parametrize("name", ["robocup", "warehouse", "mixed"])
def test_no_point_of_the_robot_moves_farther_than_the_reach_bound(cells: dict[str, PlanningScene], name: str) -> None:
    """The bounds conservative advancement relies on: between two configurations no point of any part (here:
    every cover sphere's centre and every box corner of every part) moves farther than sum_k |dq_k| reach_k,
    and no point of a self pair's part moves, seen from the other part, farther than that sum over the joints
    between the two."""
    scene = cells[name]
    body = scene._body
    rng = np.random.default_rng(31)
    qs = random_configs(scene, 300, seed=32)
    moved_q = qs + rng.normal(scale=0.05, size=qs.shape) * rng.uniform(0, 1, size=(300, 1))
    worst, worst_pair = 0.0, 0.0
    for a, b in zip(qs, moved_q, strict=True):
        pa, pb = (_part_points(scene, q) for q in (a, b))
        w = np.abs(b - a) * body.reach
        moved = np.concatenate(pa) - np.concatenate(pb)
        worst = max(worst, float(np.linalg.norm(moved, axis=1).max() / w.sum()))
        # a self pair: the points of one part seen from the other's frame move only through the joints between
        Fa, Fb = body.chain.frames_one(a), body.chain.frames_one(b)
        for p, (i, k) in enumerate(zip(body.pa.tolist(), body.pb.tolist(), strict=True)):
            bound = float(body.pair_moves[p] @ w)
            Ti = [F[body.object_frame[i]] @ body.obj_const[i] for F in (Fa, Fb)]
            rel = [(P[k] - T[:3, 3]) @ T[:3, :3] for P, T in zip((pa, pb), Ti, strict=True)]
            shift = float(np.linalg.norm(rel[0] - rel[1], axis=1).max())
            assert shift <= bound + 1e-12, (p, shift, bound)
            if bound > 0:
                worst_pair = max(worst_pair, shift / bound)
    assert worst <= 1.0
    assert worst > 0.3 and worst_pair > 0.3  # and the bounds are not loose by orders of magnitude


def _part_points(scene: PlanningScene, q: np.ndarray) -> list[np.ndarray]:
    """Per robot part, the world positions of its cover spheres' centres and its bounding-box corners at q."""
    body = scene._body
    F = body.chain.frames_one(q)
    out = []
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
    for o, f in enumerate(body.object_frame.tolist()):
        T = F[f] @ body.obj_const[o]
        lo, hi = body.sph_start[o], body.sph_start[o + 1]
        out.append(
            np.vstack(
                [
                    body.sph[lo:hi, :3] @ F[f][:3, :3].T + F[f][:3, 3],
                    (corners * body.obj_dims[o]) @ T[:3, :3].T + T[:3, 3],
                ]
            )
        )
    return out
