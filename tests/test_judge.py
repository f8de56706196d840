"""The judge (twin.tasks.judge): strict verdicts from ground truth, objects placed by hand and settled by physics.

A bin counts an object only when it rests wholly inside the inner volume (not on the rim, not over a wall,
not beside the bin); a warehouse drop zone only when the cube rests on the table inside its radius.
"""

from __future__ import annotations

import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from twin.config import load_config
from twin.scene_layout import OBJECT_TEMPLATES
from twin.tasks.judge import (
    Verdict,
    bin_verdict,
    judge_in_bin,
    judge_in_zone,
    object_bounds,
)
from twin.tasks.robocup import BinGeometry, bin_geometries, read_bin_geometry
from twin.tasks.robocup.judge import RobocupReferee
from twin.tasks.warehouse.judge import WarehouseReferee
from twin.transforms import pose_from_xyz_rpy
from twin.types import Pose
from twin.world import ObjectState, World

ROOT = Path(__file__).resolve().parent.parent
ROBOCUP = load_config(ROOT / "configs/robocup.yaml")
WAREHOUSE = load_config(ROOT / "configs/warehouse.yaml")
AT_REST = (np.zeros(3), np.zeros(3))


def quat(roll: float = 0.0, pitch: float = 0.0, yaw: float = 0.0) -> np.ndarray:
    T = pose_from_xyz_rpy((0.0, 0.0, 0.0), (roll, pitch, yaw))
    return Pose.from_matrix(T).quat_xyzw


def state(cls: str, position, q=(0.0, 0.0, 0.0, 1.0)) -> ObjectState:
    return ObjectState(
        0,
        cls,
        cls,
        None,
        np.asarray(position, dtype=float),
        np.asarray(q, dtype=float),
        False,
        OBJECT_TEMPLATES[cls].size,
    )


# ---- geometry, no physics ---------------------------------------------------------------------------
def test_bin_geometry_comes_from_the_urdf():
    b = bin_geometries(ROBOCUP)["bin_blue"]
    np.testing.assert_allclose(b.inner_lo, [-0.14, -0.14, 0.01], atol=1e-9)  # 0.30 m outside, 1 cm walls, 1 cm floor
    np.testing.assert_allclose(b.inner_hi, [0.14, 0.14, 0.12], atol=1e-9)  # rims 0.12 m high
    np.testing.assert_allclose(b.pose[:3, 3], [-0.10, 0.45, 0.0])


def test_bounds_are_exact_for_boxes_and_cylinders():
    lo, hi = object_bounds(state("can", [0, 0, 0.033], quat(roll=math.pi / 2, yaw=math.pi / 2)))  # lying along x
    np.testing.assert_allclose(hi - lo, [0.117, 0.066, 0.066], atol=1e-9)
    lo, hi = object_bounds(state("cube", [0, 0, 0], quat(yaw=math.pi / 4)))
    np.testing.assert_allclose(hi - lo, [0.075 * math.sqrt(2), 0.075 * math.sqrt(2), 0.075], atol=1e-9)
    # a cylinder tilted 30 deg about x: height 0.117 cos30 + diameter sin30 along z, exactly
    lo, hi = object_bounds(state("can", [0, 0, 0], quat(roll=math.pi / 6)))
    assert hi[2] - lo[2] == pytest.approx(0.117 * math.cos(math.pi / 6) + 0.066 * math.sin(math.pi / 6), abs=1e-9)
    assert hi[0] - lo[0] == pytest.approx(0.066, abs=1e-9)


def test_the_bin_verdict_follows_the_bins_yaw():
    """A cube turned with a bin turned 45 deg fits in its corner; judged with unturned walls it would not."""
    yaw = math.pi / 4
    b = read_bin_geometry("bin", str(ROOT / "urdf/bin_blue.urdf"), pose_from_xyz_rpy((0.0, 0.0, 0.0), (0.0, 0.0, yaw)))
    local = np.array([0.10, 0.10, 0.01 + 0.0375])  # the cube's corner 2.5 mm inside both inner walls
    c = state("cube", b.world(local), quat(yaw=yaw))
    assert bin_verdict(c, AT_REST, b) == Verdict(True)
    straight = read_bin_geometry("bin", str(ROOT / "urdf/bin_blue.urdf"), np.eye(4))
    assert not bin_verdict(c, AT_REST, straight).placed  # centre at (0, 0.141): beyond the unturned wall
    assert not bin_verdict(state("cube", b.world(local + [0.01, 0, 0]), quat(yaw=yaw)), AT_REST, b).placed


def test_a_moving_object_is_not_placed():
    b = bin_geometries(ROBOCUP)["bin_blue"]
    c = state("cube", b.world(np.array([0.0, 0.0, 0.01 + 0.0375])))
    assert bin_verdict(c, AT_REST, b).placed
    v = bin_verdict(c, (np.array([0.0, 0.0, -0.2]), np.zeros(3)), b)
    assert not v.placed and "moving" in v.reason


# ---- physics: place by hand, let it settle, judge ------------------------------------------------------
@pytest.fixture(scope="module")
def robocup_world():
    with World(ROBOCUP, seed=0, renderer="tiny") as world:
        yield world


def place(world: World, cls: str, local_xyz, q, bin_: BinGeometry, settle_s: float = 1.5) -> int:
    """Put the scene's object of class `cls` at a point given in the bin's frame; let physics settle it."""
    oid = next(o.id for o in world.objects() if o.cls == cls)
    world.set_object_pose(oid, bin_.world(np.asarray(local_xyz, dtype=float)), q)
    world.step(round(settle_s / world.dt))
    return oid


def test_inside_the_bin_is_placed_on_the_rim_or_beside_it_is_not(robocup_world):
    world = robocup_world
    bins = bin_geometries(ROBOCUP)
    blue, green = bins["bin_blue"], bins["bin_green"]
    cube = OBJECT_TEMPLATES["cube"].size[0] / 2
    # inside, on the floor
    oid = place(world, "cube", [0.03, -0.02, 0.011 + cube], quat(yaw=0.3), blue)
    assert judge_in_bin(world, oid, blue) == Verdict(True)
    assert "outside bin_green" in judge_in_bin(world, oid, green).reason  # the other bin does not count it
    # balanced on the rim's corner (its centre over the corner where two walls meet)
    oid = place(world, "cube", [0.145, 0.145, 0.121 + cube], quat(), blue)
    assert world.object_state(oid).position[2] > 0.12  # physics left it up there
    v = judge_in_bin(world, oid, blue)
    assert not v.placed and "rests on the rim of bin_blue" in v.reason, v
    # on the table beside the bin
    oid = place(world, "cube", [0.0, 0.15 + 0.06, cube + 0.001], quat(), blue)
    v = judge_in_bin(world, oid, blue)
    assert not v.placed and v.reason == "it is outside bin_blue", v
    # a bottle standing on the floor may rise above the rims (197 mm in a 120 mm bin): it is in the bin
    oid = place(world, "bottle", [-0.05, 0.05, 0.011 + 0.197 / 2], quat(), blue)
    assert judge_in_bin(world, oid, blue) == Verdict(True)


def test_half_over_a_wall_is_not_placed(robocup_world):
    """A can lying across a wall, half in the bin and half out, balanced on the rim."""
    world = robocup_world
    blue = bin_geometries(ROBOCUP)["bin_blue"]
    oid = place(world, "can", [0.145, 0.0, 0.121 + 0.033], quat(roll=math.pi / 2, yaw=math.pi / 2), blue)
    lo, hi = object_bounds(world.object_state(oid), np.linalg.inv(blue.pose))
    assert lo[0] < 0.14 < hi[0]  # it does straddle the wall
    v = judge_in_bin(world, oid, blue)
    assert not v.placed and "bin_blue" in v.reason and ("rim" in v.reason or "over the inner walls" in v.reason), v
    # a bottle leaning out over the wall from inside: its foot on the floor, its neck beyond the rim
    oid = place(world, "bottle", [0.0, 0.07, 0.011 + 0.105], quat(roll=-0.45), blue)  # tipping towards +y
    lo, hi = object_bounds(world.object_state(oid), np.linalg.inv(blue.pose))
    assert lo[2] < 0.03 and hi[1] > 0.15, (lo, hi)
    v = judge_in_bin(world, oid, blue)
    assert not v.placed and "over the inner walls of bin_blue" in v.reason, v


def test_an_object_still_falling_is_not_placed_until_it_rests(robocup_world):
    world = robocup_world
    blue = bin_geometries(ROBOCUP)["bin_blue"]
    oid = place(world, "spam", [0.0, 0.0, 0.09], quat(), blue, settle_s=0.1)  # dropped from 4 cm, still falling
    v = judge_in_bin(world, oid, blue)
    assert not v.placed and "still moving" in v.reason
    world.step(round(1.5 / world.dt))
    assert judge_in_bin(world, oid, blue).placed


def test_the_robocup_referee_names_the_stage_of_every_failure():
    with World(ROBOCUP, seed=0, renderer="tiny") as world:
        referee = RobocupReferee(world, ROBOCUP)
        blue = referee.bins["bin_blue"]
        cubes = [o for o in world.objects() if o.cls == "cube"]
        world.set_object_pose(cubes[0].id, blue.world(np.array([0.0, 0.0, 0.05])), quat())

        # what the task records about an object it released
        done = SimpleNamespace(
            error=None, done=True, cycle_time_s=12.0, first_estimate=cubes[1].position.copy(), true_ids={cubes[1].id}
        )
        out = {o.id: o for o in referee.outcomes([done])}
    assert out[cubes[0].name].placed and out[cubes[0].name].error is None  # placed, even if nobody saw it
    released = out[cubes[1].name]
    assert not released.placed and released.error.startswith("place: released, but it is outside bin_blue")
    assert released.cycle_time_s == 12.0 and released.pose_error_m == pytest.approx(0.0, abs=1e-3)
    others = [o for o in out.values() if o.id not in (cubes[0].name, cubes[1].name)]
    assert others and all(o.error == "perception: never seen on the table" for o in others)


def test_an_object_seen_again_elsewhere_after_a_failure_keeps_its_first_failure():
    # nmpc braked a transfer, the recovery let the marker go, it fell beside the base plate where no grasp
    # reaches: to the task a new target, whose descent is refused. The object's failure is nmpc's
    with World(ROBOCUP, seed=0, renderer="tiny") as world:
        referee = RobocupReferee(world, ROBOCUP)
        obj = world.objects()[0]

        def target(error, stage, planner):
            return SimpleNamespace(
                error=error,
                failure="collision",
                stage=stage,
                planner=planner,
                done=False,
                cycle_time_s=1.0,
                first_estimate=obj.position.copy(),
                true_ids={obj.id},
            )

        dropped = target("transfer: nmpc: collision: braked to a stop", "transfer", "nmpc")
        out = {
            o.id: o
            for o in referee.outcomes([dropped, target("descent: toppra.movel: collision", "descent", "toppra.movel")])
        }
    o = out[obj.name]
    assert (o.stage, o.planner) == ("transfer", "nmpc")
    assert o.error == "transfer: nmpc: collision: braked to a stop; then: descent: toppra.movel: collision"
    assert o.cycle_time_s == 2.0


# ---- warehouse --------------------------------------------------------------------------------------
def test_warehouse_cube_in_its_zone_beside_it_and_on_another_cube():
    with World(WAREHOUSE, seed=0, renderer="tiny") as world:
        referee = WarehouseReferee(world, WAREHOUSE)
        zones, r = WAREHOUSE.task.warehouse.drop_zones, WAREHOUSE.task.warehouse.drop_radius_m
        by_color = {o.color: o.id for o in world.objects()}
        red, black, blue = by_color["red"], by_color["black"], by_color["blue"]
        z = zones["red"]
        world.set_object_pose(red, [z[0], z[1], 0.0255], quat(yaw=0.4))
        world.set_object_pose(blue, [zones["blue"][0], zones["blue"][1] + r + 0.03, 0.0255], quat())
        world.step(240)
        assert judge_in_zone(world, red, z, r) == Verdict(True)
        v = judge_in_zone(world, blue, zones["blue"], r)
        assert not v.placed and "cm from its drop zone's centre" in v.reason
        # the black cube in the red zone and the red cube on top of it: the red one does not rest on the table
        world.set_object_pose(black, [z[0], z[1], 0.0255], quat())
        world.set_object_pose(red, [z[0], z[1], 0.0765], quat())
        world.step(240)
        assert world.object_state(red).position[2] > 0.07  # it stayed on top
        v = judge_in_zone(world, red, z, r)
        assert not v.placed and "does not rest on the table" in v.reason
        out = {o.color: o for o in referee.outcomes([])}
    assert not out["red"].placed and out["red"].error == "perception: never seen on the table"
    assert not out["black"].placed  # on the table, but in the red zone, not its own
