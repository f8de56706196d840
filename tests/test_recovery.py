"""Surviving a world that is not what the task was told (issue 13): a knocked wrist camera is measured, a
blocked grasp is turned where the object allows it, and a protective stop can be backed out of."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.camera import true_camera_pose
from twin.config import load_config
from twin.perception.aruco import transform_error
from twin.perception.capture import capture_frame
from twin.tasks.cell import Cell, StageFailed, top_down
from twin.tasks.robocup.calibration import calibrate_hand_eye
from twin.tasks.robocup.perception import ObjectEstimate
from twin.tasks.robocup.task import _clear_grasp_yaw, _reach_capture_pose
from twin.world import World

pytest.importorskip("open3d")

RENDERER = "tiny"


def test_the_robocup_task_measures_a_knocked_wrist_camera_from_the_base_marker():
    """The camera sits 1 cm / 1 deg off its configured hand-eye transform; trusting the config puts the
    camera 1 cm off at the capture pose, the task's marker view at the start of the run within 3 mm."""
    s = load_config(
        "robocup", overrides=["camera.extrinsic_error.translation_m=0.01", "camera.extrinsic_error.rotation_deg=1"]
    )
    assert s.perception.extrinsics == "aruco"
    with World(s, seed=3, renderer=RENDERER) as world:
        cell = Cell(s, world)
        hand_eye = calibrate_hand_eye(cell, _reach_capture_pose)
        assert hand_eye.outcome.status == "measured" and hand_eye.outcome.views == 1
        cell.move_joints("capture", np.asarray(s.camera.capture_pose))
        cap = capture_frame(world, s, move=False)
        T_true = true_camera_pose(s.camera, world.seed, world.link_matrix("tool0"))
        dt_used, dr_used = transform_error(hand_eye.camera_pose(s, cap, cell.kin), T_true)
        dt_config, _ = transform_error(cap.T_base_camera_nominal, T_true)
    assert dt_config > 0.0099  # its 1 cm (to round-off: 10.000008 mm at 240 Hz, 9.999989 at 480)
    assert dt_used < 0.003 and dr_used < 0.2, (dt_used, dr_used)
    with World(
        load_config("robocup", overrides=["perception.extrinsics=kinematics"]), seed=3, renderer=RENDERER
    ) as world:
        not_asked = calibrate_hand_eye(Cell(world.settings, world), _reach_capture_pose)
        assert not_asked.outcome.status == "configured" and not_asked.outcome.views == 0  # no marker view


def _estimate(cls: str, orientation: str, xy: tuple[float, float], z_grasp: float) -> ObjectEstimate:
    position = np.array([xy[0], xy[1], z_grasp])
    grasp = np.array([xy[0], xy[1], z_grasp, 0.0, math.pi, 0.0, 0.085])
    return ObjectEstimate(
        cls, None, cls, 1.0, orientation, orientation, position, 0.0, grasp, "icp", 0.001, 500, 0.1, None
    )


def test_a_standing_cylinder_is_gripped_at_the_least_wrist_turn_unless_a_neighbour_is_in_the_way():
    """Any yaw grips a standing can, so its perceived yaw does not matter; the task takes the least wrist
    turn, and with a standing marker where a finger would go there, a yaw that keeps the gripper 1 cm
    clear. A lying can grips only at its perceived yaw, so that one stays (its descent then fails the
    planner's check, as it should)."""
    s = load_config("robocup", overrides=["world.objects.items=[]"])
    xy, z = (-0.45, -0.05), 0.07
    with World(s, seed=0, renderer=RENDERER) as world:
        cell = Cell(s, world)
        q_now = world.joint_positions()

        def clearance(yaw: float) -> float:
            sols = cell.kin.ik(top_down((*xy, z), yaw))
            q = sols[int(np.argmin(np.abs(sols - q_now).sum(axis=1)))]
            return float(cell.scene.min_distance(q, include_self=False).distance)

        free = _clear_grasp_yaw(cell, _estimate("can", "vertical", xy, z), (*xy, z), 0.0)
        assert _clear_grasp_yaw(cell, _estimate("can", "vertical", xy, z), (*xy, z), 1.0) == free
        # a standing marker 65 mm from the can, on the line the fingers close along at that yaw
        T = np.eye(4)
        T[:3, 3] = [xy[0] + 0.065 * math.cos(free), xy[1] + 0.065 * math.sin(free), 0.0605]
        cell.scene.add_box("seen_0_marker", np.array([0.021, 0.021, 0.121]), T)
        assert clearance(free) < 0.0
        turned = _clear_grasp_yaw(cell, _estimate("can", "vertical", xy, z), (*xy, z), 0.0)
        assert abs(math.cos(turned - free)) < 0.75 and clearance(turned) >= 0.01, (free, turned, clearance(turned))
        lying = _clear_grasp_yaw(cell, _estimate("can", "horizontal", xy, 0.033), (*xy, 0.033), free)
        assert lying == free


def test_after_a_protective_stop_a_retreat_backs_off_the_object_it_touches_and_a_plain_move_does_not():
    s = load_config("robocup")
    for retreat in (False, True):
        with World(s, seed=1, renderer=RENDERER) as world:
            cell = Cell(s, world)
            cube = next(o for o in world.objects() if o.cls == "cube")
            x, y, _ = cube.position
            sols = cell.kin.ik(top_down((x, y, 0.065), 0.0))  # closed fingers pressed onto the cube's top
            world.reset_joints(sols[int(np.argmin(np.abs(sols - world.joint_positions()).sum(axis=1)))])
            world.close_gripper()
            world.step(60)
            assert world.touched_objects() == (cube.id,)
            up = top_down((x, y, 0.3), 0.0)
            if retreat:
                cell.move_pose("hover", up, retreat=True)
                assert cell.kin.fk(world.joint_positions())[2, 3] == pytest.approx(0.3, abs=1e-3)
            else:
                with pytest.raises(StageFailed, match="unexpected contact: left_finger with cube"):
                    cell.move_pose("hover", up)


def test_a_warehouse_cube_lost_on_the_way_is_seen_again_where_it_fell_and_placed():
    """Snatch the first carried cube (test setup, ground truth) and put it down elsewhere on the table: the
    task notices the loss from the finger opening, looks again from home and places it from where it is."""
    from twin.tasks.warehouse import run_warehouse

    s = load_config("warehouse")
    snatched: list[str] = []

    def snatch(w: World) -> None:
        held = w.grasped_object()
        if not snatched and held is not None and w.link_pose("tcp")[0][2] > 0.2:
            snatched.append(w.object_state(held).name)
            w.set_object_pose(held, [-0.62, -0.05, 0.026], [0, 0, 0, 1])  # on the table, away from the others

    with World(s, seed=3, renderer=RENDERER) as world:
        world.disturb(snatch, every_s=0.05)
        outcomes = {o.id: o for o in run_warehouse(Cell(s, world))}
    assert len(snatched) == 1
    assert outcomes[snatched[0]].placed, outcomes[snatched[0]].error
    assert all(o.placed for o in outcomes.values()), [(o.id, o.error) for o in outcomes.values()]


def _unknown_boxes(overrides: list[str], seed: int):
    from twin.perception.pipeline import make_detector
    from twin.tasks.robocup.perception import perceive_robocup
    from twin.tasks.robocup.task import _fixture_boxes

    s = load_config("robocup", overrides)
    with World(s, seed, renderer=RENDERER) as world:
        cap = capture_frame(world, s)
        res = perceive_robocup(
            cap.frame,
            cap.T_base_camera_nominal,
            s,
            make_detector(s),
            seed=seed,
            known_boxes=_fixture_boxes(Cell(s, world)),
        )
        truth = None if world.unmodelled_obstacle_centre is None else np.array(world.unmodelled_obstacle_centre)
        return res, truth, [o.position for o in world.objects()]


def test_an_unmodelled_box_on_the_table_is_seen_as_an_unknown_obstacle_and_nothing_else_is():
    """The fault model puts a 4 x 4 x 15 cm box among the objects (drawn from the seed, the objects where
    they were); perception names the 8 objects and reports the box as unknown, where it is; without it,
    nothing is unknown."""
    box = "world.unmodelled_obstacle={size_m: [0.04, 0.04, 0.15]}"
    res, truth, objects = _unknown_boxes([box], seed=4)
    nominal, none, objects_nominal = _unknown_boxes([], seed=4)
    assert none is None and nominal.unknown == ()
    assert np.array_equal(np.array(objects), np.array(objects_nominal))
    assert len(res.objects) == 8 and len(res.unknown) == 1
    lo, hi = res.unknown[0]
    assert np.linalg.norm((lo + hi)[:2] / 2 - truth[:2]) < 0.01
    np.testing.assert_allclose(hi - lo, [0.04, 0.04, 0.15], atol=0.01)
    assert min(np.linalg.norm(np.array(p[:2]) - truth[:2]) for p in objects) > 0.05  # placed clear of them
