"""MoveIt PlanningScene / MotionPlanRequest YAML as problem sets (`twin.problems.moveit`): what the files say
arrives in twin's frame with the right sizes, the imported problems plan in `twin compare`, and every file
twin cannot read exactly is refused in one line that names the file, the key and what is accepted.

The YAML under tests/data/moveit/ is written by hand from the moveit_msgs definitions (cell_*: ROS's message
YAML in twin's UR5e cell; mbm_*: MotionBenchMaker's robowflex YAML). Frames are ur_description's: twin's
base frame is its `base_link` turned 180 deg about z, so a point (x, y, z) of the files is (-x, -y, z) here.
"""

from __future__ import annotations

import copy
import json
import logging
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml

from twin.config import load_config
from twin.errors import ConfigError
from twin.problems import load_problem_set, save_problem_set
from twin.problems.moveit import problem_set_from_moveit
from twin.problems.problem_set import BoxShape, CylinderShape, JointGoalSpec, PoseGoalSpec, ProblemSet, SphereShape
from twin.problems.world import planning_scene, settings_for
from twin.transforms import quat_to_matrix

DATA = Path(__file__).resolve().parent / "data" / "moveit"
SCENE = DATA / "cell_scene.yaml"
REQUESTS = [DATA / "cell_request_joint.yaml", DATA / "cell_request_diff.yaml", DATA / "cell_request_position.yaml"]
ARM = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
# the configurations the requests name, in the URDF's joint order (twin frame: TCP down at the points given)
START_0 = [-0.769, -1.4306, 1.9619, -2.1022, -1.5708, 0.8018]  # (-0.45, 0.25, 0.15)
GOAL_0 = [0.2452, -1.4306, 1.9619, -2.1022, -1.5708, 1.816]  # (-0.45, -0.25, 0.15), the wall in between
START_1 = [0.3736, -1.5218, 1.9208, -1.9699, -1.5708, 1.6444]  # the scene's robot state
GOAL_1 = [-0.5786, -1.2384, 1.8023, -2.1347, -1.5708, 1.1922]
TURN = quat_to_matrix([0.0, 0.0, 1.0, 0.0])  # ur_description base_link -> twin base frame


@pytest.fixture(scope="module")
def cell() -> ProblemSet:
    return problem_set_from_moveit(SCENE, REQUESTS)


def _objects(ps: ProblemSet) -> dict[str, list[Any]]:
    return {o.name: list(o.primitives) for o in ps.world.objects}


def _same_pose(prim: BoxShape | CylinderShape | SphereShape, position: list[float], R: np.ndarray) -> None:
    np.testing.assert_allclose(prim.pose.position, position, atol=1e-9)
    np.testing.assert_allclose(prim.pose.matrix()[:3, :3], R, atol=1e-9)


def _rz(deg: float) -> np.ndarray:
    a = math.radians(deg)
    return np.array([[math.cos(a), -math.sin(a), 0.0], [math.sin(a), math.cos(a), 0.0], [0.0, 0.0, 1.0]])


# ---- 1. what the files say arrives --------------------------------------------------------------------
def test_scene_objects_arrive_in_twins_base_frame_with_their_sizes(cell: ProblemSet) -> None:
    objs = _objects(cell)
    assert list(objs) == ["table", "wall", "can", "ball", "rack"]
    assert cell.world.frame == "base_link"
    (table,) = objs["table"]  # in `table_frame`, which fixed_frame_transforms put at (0.30, 0, 0) of base_link
    assert isinstance(table, BoxShape) and table.size == (1.2, 1.6, 0.04)
    _same_pose(table, [-0.30, 0.0, -0.02], TURN)
    (wall,) = objs["wall"]
    assert isinstance(wall, BoxShape) and wall.size == (0.5, 0.04, 0.45)
    _same_pose(wall, [-0.50, 0.0, 0.225], TURN)
    (can,) = objs["can"]  # CYLINDER dimensions are [height, radius]
    assert isinstance(can, CylinderShape) and (can.length, can.radius) == (0.15, 0.04)
    _same_pose(can, [-0.60, 0.42, 0.075], TURN)
    (ball,) = objs["ball"]  # frame `base`: twin's base frame itself
    assert isinstance(ball, SphereShape) and ball.radius == 0.06
    _same_pose(ball, [0.25, 0.45, 0.30], np.eye(3))


def test_primitive_poses_are_composed_with_the_object_pose(cell: ProblemSet) -> None:
    plate, post_a, post_b, knob = _objects(cell)["rack"]
    # object at (0.05, 0.60, 0) of base_link turned 90 deg about z: its x axis is base_link's y
    R = TURN @ _rz(90)
    assert isinstance(plate, BoxShape) and plate.size == (0.30, 0.20, 0.02)
    _same_pose(plate, [-0.05, -0.60, 0.01], R)
    assert isinstance(post_a, CylinderShape) and (post_a.length, post_a.radius) == (0.30, 0.015)
    _same_pose(post_a, [-0.05, -0.72, 0.16], R)
    _same_pose(post_b, [-0.05, -0.48, 0.16], R)
    assert isinstance(knob, SphereShape) and knob.radius == 0.03
    _same_pose(knob, [-0.05, -0.72, 0.34], R)


def test_requests_become_problems_in_the_robots_joint_order(cell: ProblemSet) -> None:
    assert cell.name == "moveit_cell" and [p.id for p in cell.problems] == [f"moveit_cell#{i}" for i in range(3)]
    assert cell.robot.joint_names == ARM and cell.robot.urdf == "urdf/ur5e.urdf" and cell.robot.tcp_frame == "tcp"
    assert cell.robot.gripper_opening_m == pytest.approx(0.085) and "base_link" in cell.robot.static_links
    assert cell.source["config"] == "robocup.yaml" and cell.source["moveit"]["frames"] == "ur_description"
    first, diff, position = cell.problems
    assert first.start == START_0 and first.goal == JointGoalSpec(joints=GOAL_0)  # shuffled names, fingers dropped
    assert first.time_limit_s == 2.0 and first.seed == 0  # allowed_planning_time
    assert diff.start == START_1, "no joints in the request: the scene's robot state"
    assert diff.goal == JointGoalSpec(joints=GOAL_1) and diff.time_limit_s == 1.0  # no allowed_planning_time
    goal = position.goal
    assert isinstance(goal, PoseGoalSpec) and (goal.kind, goal.frame, goal.position_tolerance_m) == (
        "position",
        "tcp",
        0.02,
    )
    np.testing.assert_allclose(goal.pose.position, [-0.45, -0.25, 0.15], atol=1e-12)
    # the orientation a position goal carries is the tcp's at the start (pointing down): IK prefers it
    np.testing.assert_allclose(goal.pose.matrix()[:3, 2], [0.0, 0.0, -1.0], atol=1e-3)


def test_the_set_round_trips_and_its_queries_are_free_and_blocked(cell: ProblemSet, tmp_path: Path) -> None:
    assert load_problem_set(save_problem_set(cell, tmp_path / "moveit.json")) == cell
    scene = planning_scene(cell, settings_for(cell, load_config("robocup")))
    for p in cell.problems:
        assert not scene.in_collision(np.array(p.start)), f"{p.id}: start in collision"
        if isinstance(p.goal, JointGoalSpec):
            assert not scene.in_collision(np.array(p.goal.joints)), f"{p.id}: goal in collision"
            assert not scene.check_path(np.array([p.start, p.goal.joints]), resolution_rad=0.01).free, (
                f"{p.id}: the straight joint motion must hit the wall (a problem to search)"
            )


def test_overrides_name_time_limit_seed_and_twin_frames() -> None:
    ps = problem_set_from_moveit(SCENE, REQUESTS[:1], name="mine", time_limit_s=0.5, seed=7, frames="twin")
    assert [(p.id, p.time_limit_s, p.seed) for p in ps.problems] == [("mine#0", 0.5, 7)]
    (wall,) = _objects(ps)["wall"]  # base_link is twin's own base frame: nothing turns
    _same_pose(wall, [0.50, 0.0, 0.225], np.eye(3))


def test_a_motionbenchmaker_scene_with_named_primitives(caplog: pytest.LogCaptureFixture) -> None:
    scene, request = DATA / "mbm_scene.yaml", DATA / "mbm_request.yaml"
    with pytest.raises(ConfigError, match=r"robotiq_85_left_knuckle_joint.*ignore_joints"):
        problem_set_from_moveit(scene, [request])  # another robot model's gripper joints: named, not guessed
    with caplog.at_level(logging.WARNING, logger="twin"):
        ps = problem_set_from_moveit(scene, [request], ignore_joints=["robotiq_85_*"])
    assert "allowed_collision_matrix: entries for the objects ['Can1'] ignored" in caplog.text
    assert ps.name == "mbm_scene" and ps.problems[0].id == "mbm_scene#0"  # `name: ""`: the file's stem
    assert ps.problems[0].time_limit_s == 60.0
    assert ps.problems[0].goal == JointGoalSpec(joints=[0.6, -1.2, 1.3, -1.7, -1.5708, 0.6])  # no tolerances: exact
    objs = _objects(ps)
    assert list(objs) == ["Can1", "base", "side_back", "side_cap"]
    (can,) = objs["Can1"]
    assert isinstance(can, CylinderShape) and (can.length, can.radius) == (0.14, 0.03)
    _same_pose(can, [-0.55, 0.0, 0.09], TURN)
    (cap,) = objs["side_cap"]  # [0, 0.383, 0, 0.924] is a unit quaternion to 3 digits: normalised
    _same_pose(cap, [-0.60, 0.0, 0.65], TURN @ quat_to_matrix([0.0, 0.383, 0.0, 0.924]))
    scene_ = planning_scene(ps, settings_for(ps, load_config("robocup")))
    goal = ps.problems[0].goal
    assert isinstance(goal, JointGoalSpec)
    assert not scene_.in_collision(np.array(ps.problems[0].start)) and not scene_.in_collision(np.array(goal.joints))


def test_pose_goals_and_frames_given_by_fixed_frame_transforms() -> None:
    scene = {
        "fixed_frame_transforms": [  # world is 0.5 m above base_link and turned 90 deg about z
            {
                "header": {"frame_id": "base_link"},
                "child_frame_id": "world",
                "transform": {"translation": [0, 0, 0.5], "rotation": [0, 0, math.sqrt(0.5), math.sqrt(0.5)]},
            }
        ],
        "world": {
            "collision_objects": [
                {
                    "header": {"frame_id": "/world"},  # ROS 1's leading slash
                    "id": "box",
                    "primitives": [{"type": "BOX", "dimensions": [0.1, 0.2, 0.3]}],
                    "primitive_poses": [{"position": {"x": 0.4}}],  # absent fields: 0, absent orientation: identity
                }
            ]
        },
    }
    quat = [1.0, 0.0, 0.0, 0.0]  # tool0 pointing down (180 deg about x) in base_link
    request = {
        "start_state": {"joint_state": {"name": ARM, "position": START_0}},
        "goal_constraints": [
            {
                "position_constraints": [
                    {
                        "header": {"frame_id": "base_link"},
                        "link_name": "tool0",
                        "constraint_region": {
                            "primitives": [{"type": 2, "dimensions": [0.0001]}],
                            "primitive_poses": [{"position": [0.4, 0.2, 0.3], "orientation": [0, 0, 0, 1]}],
                        },
                    }
                ],
                "orientation_constraints": [
                    {
                        "header": {"frame_id": "base_link"},
                        "link_name": "tool0",
                        "orientation": quat,
                        "absolute_x_axis_tolerance": 0.01,
                        "absolute_y_axis_tolerance": 0.01,
                        "absolute_z_axis_tolerance": 0.01,
                    }
                ],
            }
        ],
    }
    ps = problem_set_from_moveit(scene, [request])
    (box,) = _objects(ps)["box"]
    # (0.4, 0, 0) in world is (0, 0.4, 0.5) in base_link, (0, -0.4, 0.5) in twin's frame
    _same_pose(box, [0.0, -0.4, 0.5], TURN @ _rz(90))
    assert ps.name == "moveit" and ps.source["moveit"]["scene"] == "<scene>"
    goal = ps.problems[0].goal
    assert isinstance(goal, PoseGoalSpec) and (goal.kind, goal.frame, goal.position_tolerance_m) == (
        "pose",
        "flange",
        None,
    )
    np.testing.assert_allclose(goal.pose.position, [-0.4, -0.2, 0.3], atol=1e-12)
    np.testing.assert_allclose(goal.pose.matrix()[:3, :3], TURN @ quat_to_matrix(quat), atol=1e-12)


# ur_description's UR5e chain (UniversalRobots/Universal_Robots_ROS2_Description urdf/ur_macro.xacro with
# config/ur5e/default_kinematics.yaml; ros-industrial/universal_robot noetic's is the same): (joint, parent,
# child, xyz, rpy), movable joints about z
PI = math.pi
UR_DESCRIPTION = [
    ("base_link-base_link_inertia", "base_link", "base_link_inertia", (0, 0, 0), (0, 0, PI)),
    ("shoulder_pan_joint", "base_link_inertia", "shoulder_link", (0, 0, 0.1625), (0, 0, 0)),
    ("shoulder_lift_joint", "shoulder_link", "upper_arm_link", (0, 0, 0), (PI / 2, 0, 0)),
    ("elbow_joint", "upper_arm_link", "forearm_link", (-0.425, 0, 0), (0, 0, 0)),
    ("wrist_1_joint", "forearm_link", "wrist_1_link", (-0.3922, 0, 0.1333), (0, 0, 0)),
    ("wrist_2_joint", "wrist_1_link", "wrist_2_link", (0, -0.0997, 0), (PI / 2, 0, 0)),
    ("wrist_3_joint", "wrist_2_link", "wrist_3_link", (0, 0.0996, 0), (PI / 2, PI, PI)),
    ("wrist_3-flange", "wrist_3_link", "flange", (0, 0, 0), (0, -PI / 2, -PI / 2)),
    ("flange-tool0", "flange", "tool0", (0, 0, 0), (PI / 2, 0, PI / 2)),
    ("base_link-base_fixed_joint", "base_link", "base", (0, 0, 0), (0, 0, PI)),
]


def test_ur_descriptions_base_link_is_twins_base_frame_turned_half_a_turn() -> None:
    """Why `frames="ur_description"` turns base_link: the same joint angles put ur_description's tool0 at
    twin's tool0 pose in its frame `base`, and turned 180 deg about z in its base_link."""
    from twin.robot.urdf_model import RobotModel

    def joint(name: str, parent: str, child: str, xyz: tuple[float, ...], rpy: tuple[float, ...]) -> str:
        kind = "fixed" if "-" in name else "revolute"
        limit = '<axis xyz="0 0 1"/><limit lower="-7" upper="7" effort="1" velocity="1"/>' if kind == "revolute" else ""
        return (
            f'<joint name="{name}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
            f'<origin xyz="{" ".join(map(str, xyz))}" rpy="{" ".join(map(str, rpy))}"/>{limit}</joint>'
        )

    links = {"base_link"} | {j[2] for j in UR_DESCRIPTION}
    ros = RobotModel.from_string(
        '<robot name="ur5e">'
        + "".join(f'<link name="{n}"/>' for n in sorted(links))
        + "".join(joint(*j) for j in UR_DESCRIPTION)
        + "</robot>"
    )
    ours = RobotModel.from_urdf(Path(__file__).resolve().parents[1] / "urdf" / "ur5e.urdf")
    qs = np.random.default_rng(0).uniform(-3.0, 3.0, (20, 6))
    theirs, mine = ros.link_pose_array(qs), ours.link_pose_array(qs)
    tool_ros, base_ros = theirs[:, ros.link_index["tool0"]], theirs[:, ros.link_index["base"]]
    tool_twin = mine[:, ours.link_index["tool0"]]
    np.testing.assert_allclose(np.linalg.inv(base_ros) @ tool_ros, tool_twin, atol=1e-12)
    turn = np.diag([-1.0, -1.0, 1.0, 1.0])
    np.testing.assert_allclose(tool_ros, turn @ tool_twin, atol=1e-12)


# ---- 2. the imported problems plan ----------------------------------------------------------------------
def test_the_imported_set_plans_with_every_builtin_planner(cell: ProblemSet, tmp_path: Path) -> None:
    from twin.compare import compare_spec_from_dict, run_comparison

    path = save_problem_set(cell, tmp_path / "moveit.json")
    planners = ["ruckig.movej", "seed.quintic_movej", "toppra.movel", "seed.slerp_movel", "ompl.rrtconnect"]
    planners += ["ompl.bitstar", "nmpc"]  # nmpc: position goals only, so it plans moveit_cell#2
    spec = compare_spec_from_dict(
        {"name": "moveit", "planners": planners, "scenarios": [{"name": "moveit", "problems": str(path)}]},
        base_dir=tmp_path,
    )
    result = run_comparison(spec, out_dir=tmp_path / "out", workers=0, plots=False)
    rows = [json.loads(line) for line in result.results_path.read_text().splitlines()]
    assert len(rows) == 3 * 6 + 1, "every planner on every problem it can reach"
    assert not [(r["planner"], r["case"], r["reason"]) for r in rows if r["status"] == "error"]
    assert all(r["success"] for r in rows if r["planner"].startswith("ompl.")), [
        (r["planner"], r["case"], r["reason"]) for r in rows if r["planner"].startswith("ompl.") and not r["success"]
    ]
    straight = [r for r in rows if r["case"] != "moveit#2" and not r["planner"].startswith(("ompl.", "nmpc"))]
    assert straight and not any(r["success"] for r in straight), "the wall blocks straight lines: a result, no error"


# ---- 3. what twin cannot read exactly -------------------------------------------------------------------
def _scene() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(SCENE.read_text())
    return data


def _request() -> dict[str, Any]:
    data: dict[str, Any] = yaml.safe_load(REQUESTS[0].read_text())
    return data


def _bad_scene(path: str, value: Any) -> dict[str, Any]:
    """The cell scene with the value at the dotted `path` (list indices as numbers) replaced."""
    data = _scene()
    *head, last = [int(p) if p.isdigit() else p for p in path.split(".")]
    node: Any = data
    for p in head:
        node = node[p]
    node[last] = copy.deepcopy(value)
    return data


def _goal(**constraints: Any) -> dict[str, Any]:
    req = _request()
    req["goal_constraints"] = [constraints]
    return req


SPHERE_REGION = {"primitives": [{"type": 2, "dimensions": [0.01]}], "primitive_poses": [{"position": [0.4, 0, 0.3]}]}
BAD_SCENES = {
    "mesh": (
        "world.collision_objects.1.meshes",
        [{"triangles": [{"vertex_indices": [0, 1, 2]}], "vertices": [{"x": 0}, {"x": 1}, {"y": 1}]}],
        r"<scene>: world\.collision_objects\.1\.meshes: meshes are not supported \(allowed: box, sphere, cylinder",
    ),
    "cone": (
        "world.collision_objects.2.primitives.0.type",
        4,
        r"collision_objects\.2\.primitives\.0\.type: unsupported primitive 'cone' \(allowed: box, sphere, cylinder\)",
    ),
    "cone by name": (
        "world.collision_objects.2.primitives.0.type",
        "cone",
        r"unsupported primitive 'cone'",
    ),
    "unknown type": ("world.collision_objects.2.primitives.0.type", 9, r"unknown primitive type 9"),
    "cylinder dims": (
        "world.collision_objects.2.primitives.0.dimensions",
        [0.15],
        r"primitives\.0\.dimensions: a cylinder needs 2 positive dimensions \[height, radius\], got \[0\.15\]",
    ),
    "unknown frame": (
        "world.collision_objects.1.header.frame_id",
        "camera_link",
        r"collision_objects\.1\.header\.frame_id: unknown frame 'camera_link': poses must be in the robot base frame "
        r"\(known here: base, base_link, table_frame, world",
    ),
    "remove": ("world.collision_objects.1.operation", 1, r"operation 'remove' is not supported"),
    "poses missing": ("world.collision_objects.1.primitive_poses", [], r"0 poses for 1 primitives"),
    "bad quaternion": (
        "world.collision_objects.1.primitive_poses.0.orientation",
        {"x": 0.0, "y": 0.0, "z": 0.5, "w": 0.5},
        r"orientation: must be a unit quaternion \[x, y, z, w\], its norm is 0\.7071",
    ),
    "text for a number": (
        "world.collision_objects.1.primitive_poses.0.position.x",
        "far",
        r"position\.x: must be a number, got str 'far'",
    ),
    "octomap": ("world.octomap.octomap.data", [0, 1, 2], r"world\.octomap\.octomap\.data: an octomap is not supported"),
    "attached": (
        "robot_state.attached_collision_objects",
        [{"link_name": "tool0", "object": {"id": "held"}}],
        r"robot_state\.attached_collision_objects: attached collision objects are not supported",
    ),
    "padding": ("link_padding.1.padding", 0.02, r"link_padding\.1\.padding: link_padding of link 'shoulder_link'"),
}


@pytest.mark.parametrize("case", list(BAD_SCENES))
def test_a_scene_twin_cannot_read_exactly_is_one_line(case: str) -> None:
    path, value, message = BAD_SCENES[case]
    with pytest.raises(ConfigError, match=message) as e:
        problem_set_from_moveit(_bad_scene(path, value), REQUESTS[:1])
    assert "\n" not in str(e.value)


PANDA = [f"panda_joint{i}" for i in range(1, 8)]
BAD_REQUESTS = {
    "other robot": (
        {**_request(), "start_state": {"joint_state": {"name": PANDA, "position": [0.0] * 7}}},
        r"<request 0>: start_state\.joint_state: joints \['panda_joint1', .*\] are not joints of urdf/ur5e\.urdf",
    ),
    "names and positions": (
        {**_request(), "start_state": {"joint_state": {"name": ARM, "position": [0.0] * 5}}},
        r"start_state\.joint_state: 6 joint names with 5 positions",
    ),
    "beyond a limit": (
        {**_request(), "start_state": {"joint_state": {"name": ARM, "position": [0, 0, 3.5, 0, 0, 0]}}},
        r"start_state\.joint_state\.position\.2: elbow_joint = 3\.5 is outside its limits \[-3\.14159, 3\.14159\]",
    ),
    "no goal": (
        {k: v for k, v in _request().items() if k != "goal_constraints"},
        r"<request 0>: goal_constraints: missing or empty: a motion plan request needs a goal",
    ),
    "partial joint goal": (
        _goal(joint_constraints=[{"joint_name": n, "position": 0.0} for n in ARM[:4]]),
        r"goal_constraints\.0\.joint_constraints: no goal position for joints \['wrist_2_joint', 'wrist_3_joint'\]",
    ),
    "box goal region": (
        _goal(
            position_constraints=[
                {
                    "link_name": "tool0",
                    "constraint_region": {
                        "primitives": [{"type": 1, "dimensions": [0.1, 0.1, 0.1]}],
                        "primitive_poses": [{}],
                    },
                }
            ]
        ),
        r"constraint_region\.primitives\.0\.type: the goal region must be a sphere",
    ),
    "goal link": (
        _goal(position_constraints=[{"link_name": "panda_hand", "constraint_region": SPHERE_REGION}]),
        r"position_constraints\.0\.link_name: goal link 'panda_hand' is not supported \(allowed: tool0, tcp\)",
    ),
    "orientation only": (
        _goal(orientation_constraints=[{"link_name": "tool0", "orientation": [0, 0, 0, 1]}]),
        r"goal_constraints\.0: 0 position and 1 orientation constraints",
    ),
    "visibility": (
        _goal(visibility_constraints=[{"target_radius": 0.1}]),
        r"goal_constraints\.0\.visibility_constraints: visibility constraints are not supported",
    ),
    "path constraints": (
        {**_request(), "path_constraints": {"orientation_constraints": [{"link_name": "tool0"}]}},
        r"path_constraints\.orientation_constraints: path constraints are not supported",
    ),
}


@pytest.mark.parametrize("case", list(BAD_REQUESTS))
def test_a_request_twin_cannot_read_exactly_is_one_line(case: str) -> None:
    request, message = BAD_REQUESTS[case]
    with pytest.raises(ConfigError, match=message) as e:
        problem_set_from_moveit(SCENE, [request])
    assert "\n" not in str(e.value)


def test_a_start_state_is_merged_over_the_scenes_robot_state() -> None:
    request = {**_request(), "start_state": {"joint_state": {"name": ARM[:5], "position": START_0[:5]}}}
    ps = problem_set_from_moveit(SCENE, [request])  # as MoveIt applies a state diff
    assert ps.problems[0].start == START_0[:5] + START_1[5:]
    scene = {k: v for k, v in _scene().items() if k != "robot_state"}
    with pytest.raises(
        ConfigError, match=r"<request 0>: start_state: no start position for joints \['wrist_3_joint'\]"
    ):
        problem_set_from_moveit(scene, [request])


def test_file_mistakes_name_the_file(tmp_path: Path) -> None:
    broken = tmp_path / "broken.yaml"
    broken.write_text("world:\n  collision_objects: [\n    - id: a\n")
    cases = {
        tmp_path / "nope.yaml": r"MoveIt scene file .*nope\.yaml does not exist",
        broken: r"broken\.yaml: not valid YAML at line \d+, column \d+",
        tmp_path: r"MoveIt scene file .* is not a file",
    }
    for path, message in cases.items():
        with pytest.raises(ConfigError, match=message) as e:
            problem_set_from_moveit(path, REQUESTS[:1])
        assert "\n" not in str(e.value)
    with pytest.raises(ConfigError, match=r"MoveIt request 0 file .*nope\.yaml does not exist"):
        problem_set_from_moveit(SCENE, [tmp_path / "nope.yaml"])
    listed = tmp_path / "list.yaml"
    listed.write_text("- 1\n- 2\n")
    with pytest.raises(ConfigError, match=r"list\.yaml: the top level must be a mapping"):
        problem_set_from_moveit(SCENE, [listed])
    with pytest.raises(ConfigError, match=r"no motion plan requests"):
        problem_set_from_moveit(SCENE, [])


def test_what_is_ignored_is_said(caplog: pytest.LogCaptureFixture) -> None:
    req = _request()
    req["goal_constraints"] = [req["goal_constraints"][0], req["goal_constraints"][0]]
    for c in req["goal_constraints"][0]["joint_constraints"]:
        c["tolerance_above"] = 0.05
    req["goal_constraint"] = []  # a typo
    with caplog.at_level(logging.WARNING, logger="twin"):
        ps = problem_set_from_moveit(SCENE, [req])
    assert ps.problems[0].goal == JointGoalSpec(joints=GOAL_0), "the centre of a wide goal region"
    assert "2 goal regions; the first is used" in caplog.text
    assert "twin plans to the centre of the goal region" in caplog.text
    assert "unknown keys ['goal_constraint'] ignored" in caplog.text
