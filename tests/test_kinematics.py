"""Kinematics: analytic FK/IK (twin.robot.kinematics) and the URDF chain (twin.robot.urdf_model) against PyBullet.

PyBullet is only the reference here (tests may import it; library code other than twin.world may not).
"""

from __future__ import annotations

import math

import numpy as np
import pybullet as pb
import pytest

from twin.config import PROJECT_ROOT
from twin.errors import ConfigError, InvalidRequestError
from twin.robot.kinematics import JOINT_LIMITS, JOINT_NAMES, URArm, wrap_to_pi
from twin.robot.urdf_model import RobotModel, read_fixture_shapes, rpy_to_matrix

URDF = PROJECT_ROOT / "urdf" / "ur5e.urdf"
N_RANDOM = 1000


def _random_q(rng: np.random.Generator, n: int) -> np.ndarray:
    """Uniform inside the joint limits (+-2pi, elbow +-pi)."""
    return rng.uniform(JOINT_LIMITS[:, 0], JOINT_LIMITS[:, 1], size=(n, 6))


def _rot_angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle of the rotation Ra^T Rb, rad (robust near 0)."""
    D = Ra.T @ Rb
    s = np.linalg.norm([D[2, 1] - D[1, 2], D[0, 2] - D[2, 0], D[1, 0] - D[0, 1]]) / 2
    c = (np.trace(D) - 1) / 2
    return math.atan2(s, c)


@pytest.fixture(scope="module")
def bullet():
    """PyBullet DIRECT client with the arm loaded at the origin; yields (client, body, joint ids, link ids)."""
    cid = pb.connect(pb.DIRECT)
    body = pb.loadURDF(str(URDF), useFixedBase=True, physicsClientId=cid)
    joints, links = {}, {"base_link": -1}
    for i in range(pb.getNumJoints(body, physicsClientId=cid)):
        info = pb.getJointInfo(body, i, physicsClientId=cid)
        joints[info[1].decode()] = i
        links[info[12].decode()] = i
    yield cid, body, joints, links
    pb.disconnect(cid)


def _bullet_pose(bullet, q: np.ndarray, link: str, fingers: float = 0.0) -> np.ndarray:
    cid, body, joints, links = bullet
    for name, v in zip(JOINT_NAMES, q, strict=True):
        pb.resetJointState(body, joints[name], float(v), physicsClientId=cid)
    for name in ("left_finger_joint", "right_finger_joint"):
        pb.resetJointState(body, joints[name], fingers, physicsClientId=cid)
    if links[link] == -1:
        return np.eye(4)  # fixed base: its link frame is the world origin (PyBullet reports its inertial frame)
    st = pb.getLinkState(body, links[link], computeForwardKinematics=True, physicsClientId=cid)
    T = np.eye(4)
    T[:3, :3] = np.array(pb.getMatrixFromQuaternion(st[5])).reshape(3, 3)
    T[:3, 3] = st[4]
    return T


# ---- forward kinematics ---------------------------------------------------------------------------
def test_fk_flange_and_tcp_match_pybullet_on_1000_random_configurations(bullet):
    rng = np.random.default_rng(1)
    kin = URArm()
    worst_pos, worst_rot = 0.0, 0.0
    for q in _random_q(rng, N_RANDOM):
        for frame, link in (("flange", "tool0"), ("tcp", "tcp")):
            T = kin.fk(q, frame)
            B = _bullet_pose(bullet, q, link)
            worst_pos = max(worst_pos, float(np.abs(T[:3, 3] - B[:3, 3]).max()))
            worst_rot = max(worst_rot, _rot_angle(T[:3, :3], B[:3, :3]))
    assert worst_pos < 1e-6, f"worst position error {worst_pos:.2e} m"
    assert worst_rot < 1e-6, f"worst orientation error {worst_rot:.2e} rad"


def test_fk_batch_equals_single_fk():
    rng = np.random.default_rng(2)
    kin = URArm()
    qs = _random_q(rng, 200)
    for frame in ("tcp", "flange"):
        batch = kin.fk_batch(qs, frame)
        single = np.array([kin.fk(q, frame) for q in qs])
        assert batch.shape == (200, 4, 4)
        assert np.abs(batch - single).max() < 1e-12


def test_tcp_is_135mm_along_flange_z():
    kin = URArm()
    q = np.array([0.4, -1.2, 1.0, -0.3, 0.8, -2.0])
    F, T = kin.fk(q, "flange"), kin.fk(q, "tcp")
    assert np.allclose(T[:3, 3], F[:3, 3] + 0.135 * F[:3, 2], atol=1e-12)
    assert np.allclose(T[:3, :3], F[:3, :3], atol=1e-12)


# ---- inverse kinematics ---------------------------------------------------------------------------
def test_ik_on_1000_random_configurations_reproduces_pose_contains_q_and_respects_limits():
    rng = np.random.default_rng(3)
    kin = URArm()
    lo, hi = JOINT_LIMITS[:, 0] - 1e-9, JOINT_LIMITS[:, 1] + 1e-9
    missing, worst, counts = 0, 0.0, []
    for q in _random_q(rng, N_RANDOM):
        T = kin.fk(q)
        sols = kin.ik(T)
        counts.append(len(sols))
        assert sols.ndim == 2 and sols.shape[1] == 6 and len(sols) > 0
        assert np.all(sols >= lo) and np.all(sols <= hi)
        for s in sols:
            E = kin.fk(s)
            worst = max(worst, float(np.abs(E - T).max()))
        if np.abs(wrap_to_pi(sols - q)).max(axis=1).min() > 1e-6:
            missing += 1
    assert worst < 1e-6, f"an IK solution misses the pose by {worst:.2e}"
    assert missing == 0, f"q itself (mod 2pi) was not among the solutions for {missing} of {N_RANDOM} poses"
    # 8 branches, each with its 2pi wraps inside +-2pi (elbow +-pi): far more than 8 solutions in general
    assert np.median(counts) >= 8


def test_ik_flange_frame_round_trip():
    kin = URArm()
    q = np.array([1.0, -1.3, 1.9, -2.1, -1.4, 0.5])
    sols = kin.ik(kin.fk(q, "flange"), "flange")
    assert np.abs(wrap_to_pi(sols - q)).max(axis=1).min() < 1e-9


def test_ik_out_of_reach_pose_returns_empty_0x6_array():
    kin = URArm()
    T = np.eye(4)
    T[:3, 3] = [2.0, 0.0, 0.3]
    sols = kin.ik(T)
    assert sols.shape == (0, 6)


@pytest.mark.parametrize(
    "call",
    [
        lambda k: k.fk(np.zeros(5)),
        lambda k: k.fk(np.zeros((2, 6))),
        lambda k: k.fk(np.zeros(6), "elbow"),
        lambda k: k.ik(np.eye(3)),
        lambda k: k.ik(np.eye(4), "camera"),
    ],
    ids=["fk-q-5", "fk-q-2x6", "fk-unknown-frame", "ik-3x3", "ik-unknown-frame"],
)
def test_bad_shapes_and_frames_raise_invalid_request(call):
    with pytest.raises(InvalidRequestError):
        call(URArm())


# ---- differential kinematics ----------------------------------------------------------------------
def test_jacobian_matches_finite_differences():
    rng = np.random.default_rng(4)
    kin = URArm()
    h = 1e-6
    worst = 0.0
    for q in _random_q(rng, 50):
        J = kin.jacobian(q)
        Jn = np.empty((6, 6))
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = h
            Tp, Tm = kin.fk(q + dq), kin.fk(q - dq)
            Jn[:3, i] = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ kin.fk(q)[:3, :3].T  # skew(omega)
            Jn[3:, i] = [W[2, 1], W[0, 2], W[1, 0]]
        worst = max(worst, float(np.abs(J - Jn).max()))
    assert worst < 1e-6, f"Jacobian differs from finite differences by {worst:.2e}"


def test_manipulability_vanishes_at_wrist_singularity_and_not_elsewhere():
    kin = URArm()
    singular = np.array([0.3, -1.2, 1.4, -1.0, 0.0, 0.7])  # wrist_2 = 0: wrist_1 and wrist_3 axes align
    regular = np.array([0.3, -1.2, 1.4, -1.0, -1.2, 0.7])
    assert kin.manipulability(singular) < 1e-9
    assert kin.manipulability(regular) > 1e-3
    assert kin.condition_number(singular) > 1e6


# ---- URDF model -----------------------------------------------------------------------------------
def test_urdf_model_reads_the_ur5e_tree():
    m = RobotModel.from_urdf(URDF)
    assert m.root == "base_link"
    assert m.arm_joints == JOINT_NAMES
    assert m.gripper_joints == ("left_finger_joint", "right_finger_joint")
    assert m.joints["elbow_joint"].lower == pytest.approx(-math.pi)
    assert m.joints["left_finger_joint"].upper == pytest.approx(0.0425)
    kinds = {(s.link, s.kind) for s in m.shapes()}
    assert ("gripper_base", "box") in kinds and ("forearm_link", "cylinder") in kinds


def test_urdf_link_poses_match_analytic_fk_on_1000_random_configurations():
    rng = np.random.default_rng(5)
    kin, m = URArm(), RobotModel.from_urdf(URDF)
    qs = _random_q(rng, N_RANDOM)
    P = m.link_poses(qs)
    assert P["tcp"].shape == (N_RANDOM, 4, 4)
    assert np.abs(P["tcp"] - kin.fk_batch(qs, "tcp")).max() < 1e-9
    assert np.abs(P["tool0"] - kin.fk_batch(qs, "flange")).max() < 1e-9


def test_urdf_link_poses_match_pybullet_for_every_link(bullet):
    rng = np.random.default_rng(6)
    m = RobotModel.from_urdf(URDF)
    worst_pos, worst_rot = 0.0, 0.0
    for q in _random_q(rng, 100):
        opening = float(rng.uniform(0, 0.085))
        P = m.link_poses(q, finger_opening=opening)
        for link in m.link_names:
            B = _bullet_pose(bullet, q, link, fingers=opening / 2)
            worst_pos = max(worst_pos, float(np.abs(P[link][0, :3, 3] - B[:3, 3]).max()))
            worst_rot = max(worst_rot, _rot_angle(P[link][0, :3, :3], B[:3, :3]))
    assert worst_pos < 1e-6 and worst_rot < 1e-6, (worst_pos, worst_rot)


def test_finger_opening_moves_fingers_half_each_way_and_defaults_to_fully_open():
    m = RobotModel.from_urdf(URDF)
    q = np.zeros(6)
    for w in (0.0, 0.03, 0.085):
        P = m.link_poses(q, finger_opening=w)
        gap = np.linalg.inv(P["gripper_base"][0]) @ P["left_finger"][0]
        assert gap[0, 3] == pytest.approx(w / 2, abs=1e-12)
    P = m.link_poses(q)
    assert (np.linalg.inv(P["gripper_base"][0]) @ P["right_finger"][0])[0, 3] == pytest.approx(-0.0425)
    with pytest.raises(InvalidRequestError):
        m.link_poses(np.zeros(5))


def test_rpy_convention_is_fixed_axis_xyz():
    r, p, y = 0.3, -0.7, 1.1
    Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    assert np.allclose(rpy_to_matrix((r, p, y)), Rz @ Ry @ Rx, atol=1e-15)
    B = np.array(pb.getMatrixFromQuaternion(pb.getQuaternionFromEuler((r, p, y)))).reshape(3, 3)
    assert np.allclose(rpy_to_matrix((r, p, y)), B, atol=1e-7)


def test_fixture_shapes_of_a_bin_are_its_five_boxes_at_the_given_pose():
    pose = np.eye(4)
    pose[:3, 3] = [0.05, 0.45, 0.0]
    shapes = read_fixture_shapes(PROJECT_ROOT / "urdf" / "bin_blue.urdf", pose)
    assert [s.kind for s in shapes] == ["box"] * 5
    floor = shapes[0]
    assert floor.size == pytest.approx((0.30, 0.30, 0.01))
    assert floor.pose[:3, 3] == pytest.approx([0.05, 0.45, 0.005])
    assert shapes[1].pose[:3, 3] == pytest.approx([0.05 + 0.145, 0.45, 0.06])


def test_multi_link_fixture_shapes_follow_fixed_joints(tmp_path):
    urdf = tmp_path / "stand.urdf"
    urdf.write_text(
        """<robot name="stand">
          <link name="foot"><collision><geometry><box size="0.2 0.2 0.02"/></geometry></collision></link>
          <link name="pole"><collision><origin xyz="0 0 0.25"/>
            <geometry><cylinder radius="0.02" length="0.5"/></geometry></collision></link>
          <link name="head"><collision><geometry><sphere radius="0.05"/></geometry></collision></link>
          <joint name="a" type="fixed"><parent link="foot"/><child link="pole"/><origin xyz="0 0 0.01"/></joint>
          <joint name="b" type="fixed"><parent link="pole"/><child link="head"/>
            <origin xyz="0 0 0.5" rpy="0 0 1.0"/></joint>
        </robot>"""
    )
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 2.0, 0.0]
    shapes = {s.link: s for s in read_fixture_shapes(urdf, pose)}
    assert shapes["pole"].pose[:3, 3] == pytest.approx([1.0, 2.0, 0.26])
    assert shapes["head"].pose[:3, 3] == pytest.approx([1.0, 2.0, 0.51])
    assert shapes["head"].kind == "sphere" and shapes["head"].size == (0.05,)


def test_malformed_urdf_raises_config_error(tmp_path):
    with pytest.raises(ConfigError):
        RobotModel.from_urdf(tmp_path / "missing.urdf")
    bad = tmp_path / "bad.urdf"
    bad.write_text("<robot name='x'><link name='a'/><link name='b'/></robot>")  # two roots
    with pytest.raises(ConfigError):
        RobotModel.from_urdf(bad)
    bad.write_text("<robot name='x'><link name='a'><collision><geometry><torus/></geometry></collision></link></robot>")
    with pytest.raises(ConfigError):
        RobotModel.from_urdf(bad)
