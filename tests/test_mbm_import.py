"""MotionBenchMaker directories as one problem set (`twin problems import-moveit DIR --robot ur5`): every
sceneNNNN.yaml/requestNNNN.yaml pair a problem in its own world (problem-set version 2), MBM's world frame (the
URDF root, 0.9144 m below the UR5's base_link, turned a quarter turn) carried into twin's base frame, the Robotiq
joints ignored, and the set planned by `twin compare` for the UR5, each problem against its own scene.

The fixture is written here in MBM's layout and YAML (not the real files, which bench/bench_mbm.py fetches)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import yaml

from tests.cli_runner import twin
from twin.config import Settings, load_config
from twin.errors import ConfigError
from twin.problems import load_problem_set, problem_set_from_moveit_dir
from twin.problems.problem_set import BoxShape, CylinderShape
from twin.transforms import pose_from_xyz_rpy

ARM = ["shoulder_pan_joint", "shoulder_lift_joint", "elbow_joint", "wrist_1_joint", "wrist_2_joint", "wrist_3_joint"]
ROBOTIQ = [f"robotiq_85_{side}_{part}_joint" for side in ("left", "right") for part in ("knuckle", "inner_knuckle")]
# MBM's UR5: base_link in the world frame; ur_description's base_link is twin's base turned half a turn
WORLD_TO_BASE = pose_from_xyz_rpy((0.0, 0.0, 0.9144), (0.0, 0.0, 1.57)) @ np.diag([-1.0, -1.0, 1.0, 1.0])
START = [0.0, -1.9, 1.9, -1.57, -1.57, 0.0]
GOAL = [1.2, -1.9, 1.9, -1.57, -1.57, 0.0]


def in_world(p_base: list[float]) -> list[float]:
    """A point of twin's base frame in MBM's world frame."""
    return [float(v) for v in (WORLD_TO_BASE @ np.append(p_base, 1.0))[:3]]


def scene(objects: list[dict]) -> dict:
    names = ARM + ROBOTIQ
    return {
        "fixed_frame_transforms": [
            {"transform": {"rotation": [0, 0, 0, 1], "translation": [0, 0, 0]}, "child_frame_id": "world"}
        ],
        "robot_model_name": "ur5_robotiq85",
        "robot_state": {"joint_state": {"position": [0] * len(names), "name": names}},
        "name": "",
        "world": {"collision_objects": objects},
    }


def request(start: list[float], goal: list[float]) -> dict:
    return {
        "group_name": "manipulator",
        "allowed_planning_time": 60,
        "start_state": {"joint_state": {"name": ARM + ROBOTIQ, "position": start + [0.0] * len(ROBOTIQ)}},
        "goal_constraints": [
            {"joint_constraints": [{"joint_name": n, "position": v} for n, v in zip(ARM, goal, strict=True)]}
        ],
    }


@pytest.fixture(scope="module")
def mbm_dir(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """Two problems: 0001 with a post far from the arm (the straight motion is free); 0002 with a wall across
    it. A can in 0001 as table_pick writes objects: an object pose composed with its primitive's."""
    d = tmp_path_factory.mktemp("mbm") / "box_ur5"
    d.mkdir()
    post = {
        "id": "post",
        "primitives": [{"type": "box", "dimensions": [0.05, 0.05, 0.3]}],
        "primitive_poses": [{"position": in_world([0.5, 0.5, 0.15]), "orientation": [0, 0, 0, 1]}],
    }
    can = {
        "id": "Can1",
        "pose": {"position": in_world([-0.2, 0.6, 0.0]), "orientation": [0, 0, 0, 1]},
        "primitives": [{"type": "cylinder", "dimensions": [0.14, 0.03]}],
        "primitive_poses": [{"position": [0, 0, 0.07], "orientation": [0, 0, 0, 1]}],
    }
    # a post (twin's frame) on the arc the TCP sweeps from START to GOAL, 0.2 m from either end
    wall = {
        "id": "wall",
        "primitives": [{"type": "box", "dimensions": [0.06, 0.06, 0.3]}],
        "primitive_poses": [{"position": in_world([-0.227, -0.287, 0.3]), "orientation": [0, 0, 0, 1]}],
    }
    for k, objects in (("0001", [post, can]), ("0002", [wall])):
        (d / f"scene{k}.yaml").write_text(yaml.safe_dump(scene(objects)))
        (d / f"request{k}.yaml").write_text(yaml.safe_dump(request(START, GOAL)))
    return d


def test_a_directory_of_pairs_is_one_set_with_a_world_per_problem(mbm_dir: Path) -> None:
    ps = problem_set_from_moveit_dir(mbm_dir, robot="ur5")
    assert ps.version == 2 and ps.name == "box_ur5" and not ps.world.objects
    assert [p.id for p in ps.problems] == ["box_ur5#0001", "box_ur5#0002"]
    assert ps.robot.urdf == "urdf/ur5.urdf" and ps.source["overrides"] == ["robot.model=ur5"]
    first, second = (p.world for p in ps.problems)
    assert first is not None and second is not None
    assert [o.name for o in first.objects] == ["post", "Can1"] and [o.name for o in second.objects] == ["wall"]
    (post,) = first.objects[0].primitives
    assert isinstance(post, BoxShape) and np.allclose(post.pose.position, [0.5, 0.5, 0.15], atol=1e-9)
    (can,) = first.objects[1].primitives
    assert isinstance(can, CylinderShape) and np.allclose(can.pose.position, [-0.2, 0.6, 0.07], atol=1e-9)
    assert ps.problems[0].start == pytest.approx(START) and ps.problems[1].time_limit_s == 60.0


def test_a_pair_missing_its_other_half_is_one_line(tmp_path: Path, mbm_dir: Path) -> None:
    d = tmp_path / "cage_ur5"
    d.mkdir()
    (d / "scene0007.yaml").write_text((mbm_dir / "scene0001.yaml").read_text())
    with pytest.raises(ConfigError, match=r"cage_ur5: scene0007.yaml has no request0007.yaml"):
        problem_set_from_moveit_dir(d, robot="ur5")
    with pytest.raises(ConfigError, match="unknown MoveIt robot 'ur6'; known: ur5"):
        problem_set_from_moveit_dir(mbm_dir, robot="ur6")


def test_the_set_plans_each_problem_in_its_own_world(mbm_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "mbm.json"
    r = twin("problems", "import-moveit", str(mbm_dir), "--robot", "ur5", "--out", str(out))
    assert r.returncode == 0, r.stderr
    assert "2 problems, 2 in their own scenes (1.5 objects on average)" in r.stdout
    assert load_problem_set(out).version == 2
    from twin.compare import compare_spec_from_dict, run_comparison

    spec = {
        "planners": ["ruckig.movej", "ompl.rrtconnect"],
        "scenarios": [
            {
                "name": "mbm",
                "scene": "robocup",
                "overrides": ["robot.model=ur5"],
                "problems": str(out),
                "time_limit_s": 2,
            }
        ],
    }
    result = run_comparison(compare_spec_from_dict(spec), out_dir=tmp_path / "o", workers=0, plots=False)
    rows = {(row["planner"], row["case"]): row for row in result.rows}
    # the same start and goal: free in problem 1's world, blocked by the wall of problem 2's
    assert rows["ruckig.movej", "mbm#0"]["success"] and rows["ruckig.movej", "mbm#0"]["straight_free"]
    assert not rows["ruckig.movej", "mbm#1"]["success"] and rows["ruckig.movej", "mbm#1"]["straight_free"] is False
    assert "wall" in rows["ruckig.movej", "mbm#1"]["reason"]
    assert rows["ompl.rrtconnect", "mbm#1"]["success"], rows["ompl.rrtconnect", "mbm#1"]["reason"]
    assert math.isclose(rows["ompl.rrtconnect", "mbm#0"]["metrics"]["goal_error_m"], 0.0, abs_tol=1e-3)


# ---- MBM's own collision model: a spheres-only UR5 whose root is the world frame ----------------------------
HALF_PI = "1.570796325"  # as ur_description writes it
# (joint, parent, child, xyz, rpy, axis): ur_description's UR5 before 2020 (base_link turned a half turn from
# the controller's base), under a world link 0.9144 m below it, as MBM's ur5_spherized.urdf has it
UR5_OLD = [
    ("offset_joint", "offset_link", "base_link", "0 0 0.9144", "0 0 1.57", None),
    ("shoulder_pan_joint", "base_link", "shoulder_link", "0 0 0.089159", "0 0 0", "0 0 1"),
    ("shoulder_lift_joint", "shoulder_link", "upper_arm_link", "0 0.13585 0", f"0 {HALF_PI} 0", "0 1 0"),
    ("elbow_joint", "upper_arm_link", "forearm_link", "0 -0.1197 0.425", "0 0 0", "0 1 0"),
    ("wrist_1_joint", "forearm_link", "wrist_1_link", "0 0 0.39225", f"0 {HALF_PI} 0", "0 1 0"),
    ("wrist_2_joint", "wrist_1_link", "wrist_2_link", "0 0.093 0", "0 0 0", "0 0 1"),
    ("wrist_3_joint", "wrist_2_link", "wrist_3_link", "0 0 0.09465", "0 0 0", "0 1 0"),
    ("tool0_joint", "wrist_3_link", "tool0", "0 0.0823 0", f"-{HALF_PI} 0 0", None),
    ("hand_joint", "tool0", "hand", "0 0 0", "0 0 0", None),
]
SPHERES = {  # link: (x y z, radius) in the link frame
    "base_link": [("0 0 0.03", 0.08)],
    "shoulder_link": [("0 0 0", 0.07)],
    "upper_arm_link": [("0 0 0.1", 0.06), ("0 0 0.3", 0.06)],
    "forearm_link": [("0 0 0.1", 0.05), ("0 0 0.3", 0.05)],
    "wrist_1_link": [("0 0 0", 0.045)],
    "wrist_2_link": [("0 0 0", 0.045)],
    "wrist_3_link": [("0 0 0", 0.04)],
    "hand": [("0 0 0.05", 0.04), ("0 0 0.12", 0.03)],
}


def spherized_urdf(path: Path, *, elbow_z: float = 0.425) -> Path:
    """A UR5 of spheres only, no finger joints and no tcp link, in MBM's frames."""
    links = ["offset_link"] + [j[2] for j in UR5_OLD]
    out = ['<robot name="ur5_spheres">']
    for link in links:
        cols = "".join(
            f'<collision><origin xyz="{xyz}"/><geometry><sphere radius="{r}"/></geometry></collision>'
            for xyz, r in SPHERES.get(link, [])
        )
        out.append(f'<link name="{link}">{cols}</link>')
    for name, parent, child, xyz, rpy, axis in UR5_OLD:
        xyz = xyz.replace("0.425", str(elbow_z)) if name == "elbow_joint" else xyz
        kind = "fixed" if axis is None else "revolute"
        body = f'<parent link="{parent}"/><child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/>'
        if axis is not None:
            body += f'<axis xyz="{axis}"/><limit lower="-6.2832" upper="6.2832" effort="150" velocity="3.15"/>'
        out.append(f'<joint name="{name}" type="{kind}">{body}</joint>')
    path.write_text("\n".join([*out, "</robot>", ""]))
    return path


def ur5_settings(urdf: Path) -> Settings:
    return load_config("robocup", ["robot.model=ur5", f"robot.urdf={urdf}"])


def test_a_spheres_only_model_rooted_in_the_world_is_placed_on_the_arm(tmp_path: Path) -> None:
    from twin.collision import PlanningScene
    from twin.robot.kinematics import URArm

    scene = PlanningScene.from_settings(ur5_settings(spherized_urdf(tmp_path / "ur5_spheres.urdf")))
    assert scene.model.root == "offset_link" and scene.max_opening_m == 0.0
    # the root is MBM's world frame, where twin's base puts it (to the file's rounding of pi/2)
    assert np.allclose(scene.model.root_pose, np.linalg.inv(WORLD_TO_BASE), atol=1e-8)
    arm = URArm(model="ur5")
    rng = np.random.default_rng(7)
    for q in rng.uniform(-math.pi, math.pi, (5, 6)):
        poses = scene.link_poses(q)
        assert np.allclose(poses["tool0"], arm.fk(q, "flange"), atol=1e-6)
        assert np.allclose(poses["tcp"], arm.fk(q), atol=1e-6)  # no tcp link: the arm's TCP is added
    # the hand's far sphere is where the DH kinematics put it: a small box there collides, 1 m away not
    q = np.array(START)
    hand = arm.fk(q, "flange") @ np.array([0.0, 0.0, 0.12, 1.0])
    assert not scene.in_collision(q)
    scene.add_box("probe", [0.02, 0.02, 0.02], pose_from_xyz_rpy(hand[:3], (0, 0, 0)))
    hit = scene.min_distance(q)
    assert hit.distance < 0 and hit.robot_part == "hand" and hit.other == "probe"
    scene.remove("probe")
    scene.add_box("probe", [0.02, 0.02, 0.02], pose_from_xyz_rpy(hand[:3] + [0.0, 0.0, 1.0], (0, 0, 0)))
    assert not scene.in_collision(q)


def test_a_model_that_is_not_the_arm_is_refused_in_one_line(tmp_path: Path) -> None:
    from twin.collision import PlanningScene

    wrong = spherized_urdf(tmp_path / "ur5_long.urdf", elbow_z=0.435)
    with pytest.raises(ConfigError, match=r"is not the arm of robot.model ur5: joint elbow_joint: its axis is 10 mm"):
        PlanningScene.from_settings(ur5_settings(wrong))


def test_the_set_plans_with_a_spheres_only_model_of_the_same_arm(mbm_dir: Path, tmp_path: Path) -> None:
    """A set imported for twin's UR5 plans with another collision model of the UR5 (no physics: no fingers)."""
    from twin.compare import compare_spec_from_dict, run_comparison

    urdf = spherized_urdf(tmp_path / "ur5_spheres.urdf")
    out = tmp_path / "mbm.json"
    assert twin("problems", "import-moveit", str(mbm_dir), "--robot", "ur5", "--out", str(out)).returncode == 0
    scenario = {"name": "mbm", "scene": "robocup", "problems": str(out), "time_limit_s": 2}
    spec = {
        "planners": ["ruckig.movej", "ompl.rrtconnect"],
        "execute": False,
        "scenarios": [{**scenario, "overrides": ["robot.model=ur5", f"robot.urdf={urdf}"]}],
    }
    result = run_comparison(compare_spec_from_dict(spec), out_dir=tmp_path / "o", workers=0, plots=False)
    rows = {(row["planner"], row["case"]): row for row in result.rows}
    assert rows["ruckig.movej", "mbm#0"]["success"], rows["ruckig.movej", "mbm#0"]["reason"]
    assert not rows["ruckig.movej", "mbm#1"]["success"] and "wall" in rows["ruckig.movej", "mbm#1"]["reason"]
    assert rows["ompl.rrtconnect", "mbm#1"]["success"], rows["ompl.rrtconnect", "mbm#1"]["reason"]
    # executing needs twin's gripper in the URDF: one line before anything runs
    with pytest.raises(ConfigError, match=r"has no left_finger_joint, .*: it plans but cannot run in physics"):
        run_comparison(compare_spec_from_dict({**spec, "execute": True}), out_dir=tmp_path / "o1", workers=0)
    # another arm's config refuses the set: its robot is the UR5
    spec["scenarios"] = [{**scenario, "overrides": ["robot.model=ur10e"]}]
    with pytest.raises(ConfigError, match=r"is not the scene config's robot 'urdf/ur10e\.urdf'"):
        run_comparison(compare_spec_from_dict(spec), out_dir=tmp_path / "o2", workers=0, plots=False)
