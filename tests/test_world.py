"""The PyBullet world: physical grasps, determinism, object placement, the ArUco plate, arm and gripper.

Headless (DIRECT), seeded. Worlds that never render are built with renderer="tiny" (skips the EGL
plugin, ~0.3 s each).
"""

from __future__ import annotations

import ast
import itertools
import math
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pybullet as pb
import pytest
import ur_analytic_ik

from twin.config import load_config, settings_from_dict
from twin.errors import ConfigError, WorldError
from twin.scene_layout import OBJECT_TEMPLATES, marker_corners_in_base, marker_pose_in_base
from twin.world import World

ROOT = Path(__file__).resolve().parent.parent
TCP_OFFSET_M = 0.135
HOVER_M = 0.15
LIFT_M = 0.20
GRASP_XY = (-0.45, 0.0)
# tcp height for a top-down grasp, low enough for a long finger contact, high enough that the gripper
# body (0.053 m above the tcp) clears the object's top
GRASP_Z = {"cube": 0.0375, "can": 0.070, "bottle": 0.150}
Q_NEAR_FRONT = np.array([0.0, -1.2, 1.5, -1.87, -1.57, 0.0])  # elbow up, reaching -x (the table side)


# ---- helpers --------------------------------------------------------------------------------------
def one_object_settings(cls: str, color: str | None = None, **gripper: Any) -> Any:
    """A table and exactly one object at GRASP_XY, upright, yaw 0 (the region is a 0.2 mm square)."""
    item: dict[str, Any] = {"class": cls}
    if color:
        item["color"] = color
    data: dict[str, Any] = {
        "world": {
            "fixtures": [{"name": "table", "urdf": "urdf/table.urdf", "position": [-0.30, 0.0, 0.0]}],
            "objects": {
                "region_x": [GRASP_XY[0] - 1e-4, GRASP_XY[0] + 1e-4],
                "region_y": [GRASP_XY[1] - 1e-4, GRASP_XY[1] + 1e-4],
                "random_yaw": False,
                "lying_probability": 0.0,
                "items": [item],
            },
        }
    }
    if gripper:
        data["gripper"] = gripper
    return settings_from_dict(data)


def top_down_tcp(p: np.ndarray, yaw: float) -> np.ndarray:
    """(4, 4) tcp pose pointing down (tcp z = -world z), fingers closing along (cos yaw, sin yaw, 0)."""
    c, s = math.cos(yaw), math.sin(yaw)
    T = np.eye(4)
    T[:3, 0] = [c, s, 0.0]
    T[:3, 1] = [s, -c, 0.0]
    T[:3, 2] = [0.0, 0.0, -1.0]
    T[:3, 3] = p
    return T


def ik_near(T_tcp: np.ndarray, q_near: np.ndarray) -> np.ndarray:
    """The analytic IK solution (tool0 = tcp * translate(0, 0, -0.135)) closest to q_near."""
    flange = T_tcp.copy()
    flange[:3, 3] -= TCP_OFFSET_M * T_tcp[:3, 2]
    best = None
    for q in ur_analytic_ik.ur5e.inverse_kinematics(flange):
        q = q_near + (np.asarray(q) - q_near + math.pi) % (2 * math.pi) - math.pi
        if best is None or np.linalg.norm(q - q_near) < np.linalg.norm(best - q_near):
            best = q
    assert best is not None, f"no IK for {T_tcp[:3, 3]}"
    return best


def move_tcp_line(
    world: World, q: np.ndarray, p0: np.ndarray, p1: np.ndarray, yaw: float, duration_s: float
) -> np.ndarray:
    """Straight top-down tcp line with a quintic time law, one joint target per physics step."""
    n = max(1, round(duration_s / world.dt))
    for k in range(1, n + 1):
        s = k / n
        s = 10 * s**3 - 15 * s**4 + 6 * s**5
        q = ik_near(top_down_tcp(p0 + (p1 - p0) * s, yaw), q)
        world.set_joint_targets(q)
        world.step()
    return q


def object_in_tcp(world: World, oid: int) -> np.ndarray:
    """(3,) object centre in the tcp frame."""
    T = world.link_matrix("tcp")
    p, _ = world.object_pose(oid)
    return T[:3, :3].T @ (p - T[:3, 3])


def pick_and_hold(world: World, oid: int, z_grasp: float, yaw: float) -> dict[str, float]:
    """Hover, open, descend, close (force-limited), lift LIFT_M, hold 2 s; measure lift and slip."""
    hover = np.array([*GRASP_XY, z_grasp + HOVER_M])
    grasp = np.array([*GRASP_XY, z_grasp])
    q = ik_near(top_down_tcp(hover, yaw), Q_NEAR_FRONT)
    world.reset_joints(q)
    world.open_gripper()
    world.step(120)
    q = move_tcp_line(world, q, hover, grasp, yaw, 1.0)
    world.step(48)
    world.close_gripper()
    for i in range(360):
        world.step()
        if i > 24 and world.grasp_settled():
            break
    world.step(72)
    z_before = world.object_pose(oid)[0][2]
    opening = world.gripper_opening()
    move_tcp_line(world, q, grasp, grasp + [0.0, 0.0, LIFT_M], yaw, 1.5)
    rel_start = object_in_tcp(world, oid)
    t0 = world.sim_time
    world.step(round(2.0 / world.dt))
    return {
        "lift_m": world.object_pose(oid)[0][2] - z_before,
        "slip_m": float(np.linalg.norm(object_in_tcp(world, oid) - rel_start)),
        "hold_s": world.sim_time - t0,
        "opening_m": opening,
        "grasped": float(world.grasped_object() == oid),
    }


def poses(world: World) -> np.ndarray:
    return np.array([np.r_[o.position, o.orientation_xyzw] for o in world.objects()])


# ---- the one importer of PyBullet ------------------------------------------------------------------
def imports_pybullet(source: str) -> bool:
    """True when the module's code imports pybullet anywhere (top level, in a function, in a TYPE_CHECKING
    block): `import pybullet [as pb]`, `import pybullet_data`, `from pybullet import ...`."""
    for node in ast.walk(ast.parse(source)):
        names = [a.name for a in node.names] if isinstance(node, ast.Import) else []
        if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            names = [node.module]
        if any(n.split(".")[0].startswith("pybullet") for n in names):
            return True
    return False


def test_only_the_world_package_imports_pybullet_and_there_only_its_bullet_module() -> None:
    """The simulator stays behind `twin.world` (CONVENTIONS: Modules), and inside it one module imports it,
    with the banner it prints at import silenced (`twin.world.bullet`)."""
    files = [*(ROOT / "twin").rglob("*.py"), *(ROOT / "plugins").rglob("*.py")]
    importers = sorted(str(f.relative_to(ROOT)) for f in files if imports_pybullet(f.read_text(encoding="utf-8")))
    assert importers == ["twin/world/bullet.py"]
    assert len(files) > 100  # the walk saw the sources


def test_the_pybullet_import_rule_catches_every_form_of_import() -> None:
    """The rule above is not vacuous: each way of importing pybullet is caught, and nothing else is."""
    for code in (
        "import pybullet as pb",
        "import numpy, pybullet",
        "from pybullet import connect",
        "import pybullet_data",
        "def f():\n    import pybullet\n",
        "if TYPE_CHECKING:\n    import pybullet\n",
    ):
        assert imports_pybullet(code), code
    for code in (
        "import numpy as np",
        "from twin.world import World",
        "from .pybullet import x",
        "x = 'import pybullet'",
    ):
        assert not imports_pybullet(code), code


# ---- physical grasp -------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("cls", "yaw", "dx"),
    [
        ("cube", 0.0, 0.0),
        ("cube", 0.35, 0.004),
        ("cube", -0.6, -0.004),
        ("bottle", 0.0, 0.0),
        ("bottle", 0.35, 0.004),
        ("bottle", -0.6, -0.004),
        ("can", 0.0, 0.0),
        ("can", 0.35, 0.004),
        ("can", -0.6, -0.004),
    ],
)
def test_friction_grasp_lifts_object_0_2m_and_slips_under_5mm_in_2s_hold(cls: str, yaw: float, dx: float) -> None:
    settings = one_object_settings(cls, "red" if cls == "cube" else None)
    with World(settings, seed=0, renderer="tiny") as world:
        oid = world.object_ids()[0]
        p, _ = world.object_pose(oid)
        # the object's yaw varies; the gripper is aligned with it, the object sits a few mm off-centre
        world.set_object_pose(oid, p + [dx, 0.0, 0.0], pb.getQuaternionFromEuler([0.0, 0.0, yaw]))
        r = pick_and_hold(world, oid, GRASP_Z[cls], yaw)
        assert pb.getNumConstraints(physicsClientId=world.client_id) == 0  # friction only, nothing attached
    width = OBJECT_TEMPLATES[cls].size[0]
    assert r["grasped"] == 1.0
    assert abs(r["opening_m"] - width) < 0.004, r
    assert abs(r["lift_m"] - LIFT_M) < 0.005, r
    assert r["hold_s"] == pytest.approx(2.0)
    assert r["slip_m"] < 0.005, r


def test_closing_on_nothing_closes_fully_and_opening_is_symmetric() -> None:
    with World(one_object_settings("cube"), seed=0, renderer="tiny") as world:
        assert world.gripper_opening() == pytest.approx(world.settings.gripper.max_opening_m, abs=1e-6)
        world.close_gripper()
        world.step(round(1.0 / world.dt))
        assert world.gripper_opening() < 1e-3
        assert world.gripper_settled()
        world.set_gripper_opening(0.05)
        world.step(round(1.0 / world.dt))
        left, right = (
            pb.getJointState(world.robot_id, world.link_indices()[n], physicsClientId=world.client_id)[0]
            for n in ("left_finger", "right_finger")
        )
        assert world.gripper_opening() == pytest.approx(0.05, abs=1e-3)
        assert left == pytest.approx(right, abs=2e-4)


# ---- arm ----------------------------------------------------------------------------------------------
def test_joint_targets_are_tracked_and_reset_joints_teleports() -> None:
    with World(one_object_settings("can"), seed=0, renderer="tiny") as world:
        home = np.array(world.settings.robot.home)
        np.testing.assert_allclose(world.joint_positions(), home, atol=1e-9)
        target = home + np.array([0.3, -0.2, 0.25, 0.2, -0.3, 0.5])
        world.set_joint_targets(target)
        world.step(240)
        np.testing.assert_allclose(world.joint_positions(), target, atol=2e-3)
        assert np.abs(world.joint_velocities()).max() < 0.02
        q = home + 0.1
        world.reset_joints(q)
        np.testing.assert_allclose(world.joint_positions(), q, atol=1e-9)
        world.step(48)
        np.testing.assert_allclose(world.joint_positions(), q, atol=2e-3)
        # link frames agree with the analytic forward kinematics of the DH parameters
        T = ur_analytic_ik.ur5e.forward_kinematics(*world.joint_positions())
        T[:3, 3] += TCP_OFFSET_M * T[:3, 2]
        np.testing.assert_allclose(world.link_matrix("tcp"), T, atol=1e-5)


def test_robot_contacts_report_the_table_when_the_tcp_goes_below_it() -> None:
    with World(one_object_settings("can"), seed=0, renderer="tiny") as world:
        table = world.body_ids()["table"]
        q = ik_near(top_down_tcp(np.array([-0.30, -0.25, -0.005]), 0.0), Q_NEAR_FRONT)
        world.reset_joints(q)
        world.step()
        hits = world.robot_contacts()
        assert {c.body_b for c in hits} == {table}
        reference = pb.getContactPoints(bodyA=world.robot_id, bodyB=table, physicsClientId=world.client_id)
        assert len(hits) == len(reference) > 0
        assert min(c.distance for c in world.closest_points(world.robot_id, table, 0.0)) < 0


# ---- determinism ------------------------------------------------------------------------------------
def test_same_seed_gives_identical_object_poses_after_2s_and_other_seeds_differ() -> None:
    settings = load_config("configs/robocup.yaml")
    runs = []
    for seed in (7, 7, 8):
        with World(settings, seed=seed, renderer="tiny") as world:
            world.step(round(2.0 / world.dt))
            assert world.sim_time == pytest.approx(2.0)
            runs.append(poses(world))
    np.testing.assert_array_equal(runs[0], runs[1])
    assert np.abs(runs[0][:, :3] - runs[2][:, :3]).max() > 0.01


def test_reset_returns_to_the_initial_state_bit_for_bit() -> None:
    settings = load_config("configs/robocup.yaml")
    with World(settings, seed=3, renderer="tiny") as fresh:
        fresh.step(480)
        expected = poses(fresh)
    with World(settings, seed=3, renderer="tiny") as world:
        ids = world.body_ids()
        initial = poses(world)
        world.set_joint_targets(np.array(settings.robot.home) + 0.3)
        world.close_gripper()
        world.set_object_pose(world.object_ids()[0], [0.5, 0.0, 0.3], [0, 0, 0, 1])
        world.step(300)
        world.reset()
        assert world.sim_time == 0.0 and world.body_ids() == ids
        np.testing.assert_array_equal(poses(world), initial)
        np.testing.assert_allclose(world.joint_positions(), settings.robot.home)
        world.step(480)
        np.testing.assert_array_equal(poses(world), expected)


def test_a_reset_world_captures_what_a_new_world_captures_bit_for_bit() -> None:
    """After captures (one prefetched), steps and a noisy controller's draws, `reset()` starts the sensor noise
    and the controller noise over: the first capture of a reset world is the first capture of a new one."""
    from twin.perception.capture import capture_frame, prefetch_next_capture

    settings = load_config(
        "robocup",
        overrides=[
            "camera.width=160",
            "camera.height=120",
            "camera.noise.scale=3",
            "robot.tracking_noise_rad=0.002",
            "robot.tracking_time_constant_s=0.02",
        ],
    )
    assert settings.camera.noise.enabled and settings.camera.mount == "wrist"

    def first_capture(world: World) -> list[np.ndarray]:
        cap = capture_frame(world, settings, settle_s=0.1)
        return [cap.frame.depth_m, cap.frame.rgb, cap.q, cap.T_base_camera_nominal, poses(world)]

    with World(settings, seed=3, renderer="tiny") as fresh:
        expected = first_capture(fresh)
        second = first_capture(fresh)  # the same pose again: only the noise differs
    assert not np.array_equal(expected[0], second[0]) and not np.array_equal(expected[2], second[2])
    with World(settings, seed=3, renderer="tiny") as world:
        first_capture(world)
        world.step(50)
        first_capture(world)
        prefetch_next_capture(world, settings)
        world.reset()
        got = first_capture(world)
    for a, b in zip(expected, got, strict=True):
        np.testing.assert_array_equal(a, b)


# ---- placement -------------------------------------------------------------------------------------
def test_objects_never_overlap_at_spawn_and_centres_lie_in_the_region_over_20_seeds() -> None:
    settings = load_config("configs/robocup.yaml")
    cfg = settings.world.objects
    lying_seen = 0
    for seed in range(20):
        with World(settings, seed=seed, renderer="tiny") as world:
            objs = world.objects()
            assert sorted(o.cls for o in objs) == sorted(
                ["bottle", "can", "spam", "marker", "cube", "cube", "cube", "cube"]
            )
            for o in objs:
                assert cfg.region_x[0] <= o.position[0] <= cfg.region_x[1]
                assert cfg.region_y[0] <= o.position[1] <= cfg.region_y[1]
                lying_seen += o.lying
            for a, b in itertools.combinations(world.object_ids(), 2):
                close = pb.getClosestPoints(a, b, cfg.min_gap_m - 1e-3, physicsClientId=world.client_id)
                assert not close, f"seed {seed}: objects {a} and {b} closer than min_gap_m"
            ids = world.body_ids()
            for name in ("robot", "aruco_plate", "bin_blue", "bin_green"):
                for o in objs:
                    assert not pb.getClosestPoints(ids[name], o.id, 0.0, physicsClientId=world.client_id), (
                        f"seed {seed}: {o.name} touches {name}"
                    )
    assert 0.15 < lying_seen / 160 < 0.45  # lying_probability 0.3


@pytest.mark.parametrize("p_lying", [0.0, 1.0])
def test_lying_probability_0_gives_all_upright_and_1_all_lying(p_lying: float) -> None:
    data = load_config("configs/robocup.yaml").model_dump(by_alias=True)
    data["world"]["objects"]["lying_probability"] = p_lying
    settings = settings_from_dict(data)
    for seed in range(3):
        with World(settings, seed=seed, renderer="tiny") as world:
            for o in world.objects():
                z_axis = np.array(pb.getMatrixFromQuaternion(o.orientation_xyzw.tolist())).reshape(3, 3)[:, 2]
                tmpl = OBJECT_TEMPLATES[o.cls]
                assert o.lying is (p_lying == 1.0)
                assert abs(z_axis[2]) == pytest.approx(0.0 if o.lying else 1.0, abs=1e-6)
                assert o.position[2] == pytest.approx(tmpl.height(o.lying) / 2, abs=1e-6)  # resting on the table


def test_crowded_region_raises_world_error_naming_the_region() -> None:
    data = one_object_settings("bottle").model_dump(by_alias=True)
    data["world"]["objects"]["items"] = [{"class": "bottle", "count": 5}]
    with pytest.raises(WorldError, match="cannot place 5 objects"):
        World(settings_from_dict(data), seed=0, renderer="tiny")


def test_unknown_colour_is_a_config_error() -> None:
    with pytest.raises(ConfigError, match="unknown colour 'mauve'"):
        World(one_object_settings("cube", "mauve"), seed=0, renderer="tiny")


# ---- configs ---------------------------------------------------------------------------------------
def test_warehouse_scene_has_the_static_obstacle_and_four_coloured_cubes() -> None:
    settings = load_config("configs/warehouse.yaml")
    with World(settings, seed=0, renderer="tiny") as world:
        objs = world.objects()
        assert sorted(o.color for o in objs) == ["black", "blue", "green", "red"]
        assert {o.cls for o in objs} == {"warehouse_cube"}
        obstacle = world.body_ids()["obstacle"]
        lo, hi = pb.getAABB(obstacle, -1, physicsClientId=world.client_id)
        np.testing.assert_allclose(np.array(hi) - np.array(lo), [0.12, 0.30, 0.20], atol=3e-3)
        world.step(240)
        pos, _ = pb.getBasePositionAndOrientation(obstacle, physicsClientId=world.client_id)
        np.testing.assert_allclose(pos, [-0.42, 0.24, 0.10], atol=1e-9)  # a fixture: it never moves
        for o in world.objects():
            assert o.position[2] == pytest.approx(0.025, abs=1e-3)


# ---- ArUco plate -----------------------------------------------------------------------------------
def test_marker_plate_exists_and_ground_truth_pose_matches_the_nominal_layout() -> None:
    settings = load_config("configs/robocup.yaml")
    with World(settings, seed=0, renderer="tiny") as world:
        ids = world.body_ids()
        assert "aruco_plate" in ids and "aruco_marker" in ids
        T = world.marker_pose()
        np.testing.assert_allclose(T, marker_pose_in_base(settings), atol=1e-6)
        _, plate_top = pb.getAABB(ids["aruco_plate"], -1, physicsClientId=world.client_id)
        assert 0.0 < T[2, 3] - (plate_top[2] - 1e-3) < 1e-3  # on the plate's top face (AABB has 1 mm margin)
        np.testing.assert_allclose(T[:3, 2], [0, 0, 1], atol=1e-9)  # flat, facing up
        assert -0.30 < T[0, 3] < -0.08  # in front of the base, between the robot and the objects


def test_rendered_marker_is_detected_with_corners_at_their_nominal_pixels() -> None:
    settings = load_config("configs/warehouse.yaml")
    W, H = 640, 480
    with World(settings, seed=0, renderer="tiny") as world:
        view = pb.computeViewMatrix([-0.9, -0.5, 0.7], [-0.16, 0.0, 0.0], [0, 0, 1])
        proj = pb.computeProjectionMatrixFOV(42, W / H, 0.05, 4.0)
        img = pb.getCameraImage(W, H, view, proj, renderer=pb.ER_TINY_RENDERER, physicsClientId=world.client_id)
    rgb = np.reshape(np.asarray(img[2], dtype=np.uint8), (H, W, 4))[:, :, :3]
    params = cv2.aruco.DetectorParameters()
    params.cornerRefinementMethod = cv2.aruco.CORNER_REFINE_SUBPIX
    dictionary = cv2.aruco.getPredefinedDictionary(getattr(cv2.aruco, settings.aruco.dictionary))
    corners, ids, _ = cv2.aruco.ArucoDetector(dictionary, params).detectMarkers(cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY))
    assert ids is not None and ids.ravel().tolist() == [settings.aruco.id]
    # project the nominal corners (TL, TR, BR, BL) with the same camera
    V = np.array(view).reshape(4, 4).T
    P = np.array(proj).reshape(4, 4).T
    X = np.c_[marker_corners_in_base(settings), np.ones(4)]
    clip = (P @ V @ X.T).T
    ndc = clip[:, :3] / clip[:, 3:]
    nominal = np.c_[(ndc[:, 0] + 1) / 2 * W - 0.5, (1 - ndc[:, 1]) / 2 * H - 0.5]
    assert np.abs(corners[0][0] - nominal).max() < 2.0  # pixels, same corner order
