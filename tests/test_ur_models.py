"""The arm is a config choice within the Universal Robots family: one DH table (`twin.robot.ur_models`) that agrees
with the closed-form IK twin uses for each arm, kinematics for any of them, and the UR5e unchanged."""

from __future__ import annotations

import typing

import numpy as np
import pytest
import ur_analytic_ik

from twin.config import load_config
from twin.config.schema import RobotSettings
from twin.errors import ConfigError
from twin.planning import limits_from_settings
from twin.robot import Robot
from twin.robot.kinematics import DH_A, DH_D, URArm, wrap_to_pi
from twin.robot.ur_models import UR_MODELS, ur_model


@pytest.mark.parametrize("name", list(UR_MODELS))
def test_the_dh_table_is_the_one_the_analytic_ik_uses(name: str) -> None:
    arm = URArm(model=name)
    qs = np.random.default_rng(7).uniform(-np.pi, np.pi, (50, 6))
    flange = arm.fk_batch(qs, "flange")
    module = getattr(ur_analytic_ik, name)
    want = np.array([module.forward_kinematics(*q) for q in qs])
    assert np.abs(flange - want).max() < 1e-9  # our compiled DH chain = the IK's own FK, for every arm
    for q, T in zip(qs[:10], flange[:10], strict=True):
        assert np.abs(arm.fk(q, "flange") - T).max() < 1e-12
        sols = arm.ik(arm.fk(q), all_wraps=False)
        assert any(np.abs(wrap_to_pi(s - q)).max() < 1e-6 for s in sols), name  # the IK finds q again
        J = arm.jacobian(q)
        dq = 1e-6 * np.eye(6)
        numeric = np.array([(arm.fk(q + e)[:3, 3] - arm.fk(q - e)[:3, 3]) / 2e-6 for e in dq]).T
        assert np.abs(J[:3] - numeric).max() < 1e-6  # the Jacobian is the arm's own


def test_the_arms_differ_where_their_datasheets_do() -> None:
    ur5, ur5e, ur10e = (URArm(model=m) for m in ("ur5", "ur5e", "ur10e"))
    home = np.zeros(6)
    # the same joint angles put the flanges of two arms centimetres to decimetres apart
    assert np.linalg.norm(ur5.fk(home, "flange")[:3, 3] - ur5e.fk(home, "flange")[:3, 3]) > 0.05
    assert np.linalg.norm(ur10e.fk(home, "flange")[:3, 3] - ur5e.fk(home, "flange")[:3, 3]) > 0.3
    # base-to-shoulder height d1: 89 mm on the UR5, 163 mm on the UR5e
    assert ur5.dh_frames(home)[0, 1][2, 3] == pytest.approx(0.089159)
    assert ur5e.dh_frames(home)[0, 1][2, 3] == pytest.approx(0.1625)
    assert ur10e.model == "ur10e" and ur_model("ur10e").reach_m > 1.2 > ur_model("ur5e").reach_m
    assert ur_model("ur10e").speed_limits()[0] == pytest.approx(np.radians(120))  # base and shoulder slower
    assert ur_model("ur3e").speed_limits()[5] == pytest.approx(np.radians(360))  # wrists faster


def test_the_ur5e_is_the_default_and_unchanged() -> None:
    assert URArm().model == "ur5e"  # the default arm
    assert list(DH_D) == [0.1625, 0, 0, 0.1333, 0.0997, 0.0996] and list(DH_A) == [0, -0.425, -0.3922, 0, 0, 0]
    q = np.array([0.3, -1.2, 1.1, -1.4, -1.6, 0.2])
    assert np.array_equal(URArm().fk(q), ur_analytic_ik.ur5e.forward_kinematics(*q) @ URArm().tool_transform())
    assert Robot.from_settings(load_config("robocup")).arm.model == "ur5e"


def test_robot_model_is_checked_on_load() -> None:
    allowed = typing.get_args(RobotSettings.model_fields["model"].annotation)
    assert set(allowed) == set(UR_MODELS)  # the schema offers exactly the arms the table has
    ur10e = load_config("robocup", ["robot.model=ur10e"])
    assert Robot.from_settings(ur10e).arm.model == "ur10e"
    # planning limits: the config's, no faster than the datasheet (UR5e: pi everywhere, unchanged)
    assert np.array_equal(limits_from_settings(load_config("robocup")).max_joint_vel, np.full(6, np.pi))
    assert limits_from_settings(ur10e).max_joint_vel == pytest.approx([np.radians(120)] * 2 + [np.pi] * 4)
    with pytest.raises(ConfigError, match=r"robot\.model"):
        load_config("robocup", ["robot.model=ur6"])
    with pytest.raises(ConfigError, match="unknown arm 'ur6'; allowed: ur3, ur3e, ur5, ur5e"):
        ur_model("ur6")


def test_compare_smoke_gives_the_rows_it_gave_before_the_arm_was_a_choice(tmp_path) -> None:
    """Every row's outcome (and the closed-form planners' durations) as compare-smoke gave them before
    `robot.model` existed (tests/data/compare_smoke_rows.json, written at commit c7851c8)."""
    import json
    from pathlib import Path

    from twin.compare import run_comparison

    want = json.loads((Path(__file__).parent / "data" / "compare_smoke_rows.json").read_text())
    result = run_comparison("compare-smoke", out_dir=tmp_path / "o", workers=2, plots=False)
    got = {}
    for r in result.rows:
        rec = {"status": r["status"], "failure": r.get("failure"), "success": r["success"]}
        closed_form = r["planner"] in ("ruckig.movej", "seed.quintic_movej", "toppra.movel", "seed.slerp_movel")
        if closed_form and r["metrics"]["duration_s"] is not None:
            rec["duration_s"] = round(r["metrics"]["duration_s"], 4)
        got[r["run_id"].rsplit("|", 1)[0]] = rec
    assert got == want


def test_twin_ships_a_urdf_per_arm_that_matches_its_dh() -> None:
    from pathlib import Path

    from twin.collision import PlanningScene
    from twin.robot.ur_urdf import arm_urdf
    from twin.robot.urdf_model import RobotModel

    root = Path(__file__).resolve().parent.parent / "urdf"
    for name in UR_MODELS:
        text = (root / f"{name}.urdf").read_text()
        stale = f"urdf/{name}.urdf is stale: python -m twin.robot.ur_urdf"
        assert text == arm_urdf(name), stale  # ur5e: the hand-written
        model = RobotModel.from_string(text)
        assert np.array_equal(URArm(model=name).urdf_base(model), np.eye(4))  # rooted at the arm's base
        assert URArm(model=name).urdf_mismatch(model) is None
        assert load_config("robocup", [f"robot.model={name}"]).robot.urdf == f"urdf/{name}.urdf"
    # a URDF of another arm is refused where the planners would use it, in one line naming the joint (its base
    # placed as well as it goes: the UR5e's shoulder, 73.3 mm higher, puts its root below the UR5's base)
    wrong = r"not the arm of robot.model ur5: joint wrist_1_joint: .* root placed 73.3 mm"
    with pytest.raises(ConfigError, match=wrong):
        PlanningScene.from_settings(load_config("robocup", ["robot.model=ur5", "robot.urdf=urdf/ur5e.urdf"]))
    # and one whose tcp is not where the planners put it (another gripper's TCP): pose goals would miss
    longer = RobotModel.from_string(arm_urdf("ur5").replace('<origin xyz="0 0 0.135"', '<origin xyz="0 0 0.15"'))
    assert URArm(model="ur5").urdf_mismatch(longer) == (
        "its tcp link is 15 mm (or rotation entries) from the arm's TCP, tool0 + 0.135 m along z"
    )


@pytest.mark.parametrize("name", ["ur5", "ur10e"])
def test_plan_compare_and_the_contract_work_for_other_arms(name: str, tmp_path) -> None:
    from tests.cli_runner import twin
    from twin.compare import compare_spec_from_dict, run_comparison
    from twin.testing import check_planner

    r = twin(
        "plan", "robocup", "--set", f"robot.model={name}", "--planner", "ompl.rrtconnect",
        "--start", "0,-1.6,1.5,-1.5,-1.57,0", "--goal", "0.6,-1.4,1.2,-1.4,-1.57,0.2",
    )  # fmt: skip
    assert r.returncode == 0, r.stderr
    spec = {
        "planners": ["ruckig.movej", "ompl.rrtconnect"],
        "scenarios": [
            {
                "name": "q",
                "scene": "robocup",
                "overrides": [f"robot.model={name}"],
                "random": {"count": 2, "goal": "pose"},
            }
        ],
    }
    result = run_comparison(compare_spec_from_dict(spec), out_dir=tmp_path / "o", workers=0, plots=False)
    rrt = [row for row in result.rows if row["planner"] == "ompl.rrtconnect"]
    assert all(row["success"] for row in rrt), [row["reason"] for row in rrt]
    # executed in physics with the arm's own URDF and motors: it tracks the plan to the goal
    assert max(row["metrics"]["goal_error_m"] for row in rrt) < 1e-3
    report = check_planner("ompl.rrtconnect", settings=load_config("robocup", [f"robot.model={name}"]))
    assert not report.failures, report.summary()


def test_the_mpc_planners_refuse_an_arm_their_sphere_models_do_not_cover() -> None:
    pytest.importorskip("casadi")
    from twin.planning import make_context, make_planner

    settings = load_config("robocup", ["robot.model=ur10e"])
    for name in ("nmpc", "croc"):
        with pytest.raises(ConfigError, match=rf"^{name} does not plan for robot\.model ur10e; it plans for ur5e$"):
            make_planner(name, context=make_context(settings))


def test_a_urdf_rooted_above_the_arm_is_placed_on_the_base_in_plan_and_physics(tmp_path) -> None:
    """twin's UR5e under a world link (0.5 m below its base, a quarter turn): the planning scene and the physics
    both put the arm's base at the origin, so their links agree with the DH kinematics."""
    from pathlib import Path

    from twin.collision import PlanningScene
    from twin.world import World

    text = (Path(__file__).resolve().parent.parent / "urdf" / "ur5e.urdf").read_text()
    mount = (
        '<link name="mount"/><joint name="mount_joint" type="fixed"><parent link="mount"/><child link="base_link"/>'
        '<origin xyz="0.1 0 0.5" rpy="0 0 1.5707963267948966"/></joint>'
    )
    urdf = tmp_path / "ur5e_mounted.urdf"
    urdf.write_text(text.replace("</robot>", mount + "</robot>"))
    settings = load_config("robocup", [f"robot.urdf={urdf}"])
    arm = URArm(model="ur5e")
    q = np.array([0.4, -1.2, 1.3, -1.7, -1.5, 0.3])
    scene = PlanningScene.from_settings(settings)
    assert np.allclose(scene.link_poses(q)["tcp"], arm.fk(q), atol=1e-9)
    with World(settings, seed=0, renderer="tiny") as world:
        world.reset_joints(q)
        assert np.allclose(world.link_matrix("tcp"), arm.fk(q), atol=1e-5)
