"""FCL planning scene (twin.collision) against PyBullet as the reference, plus the scene-editing API.

PyBullet loads the same URDFs with URDF_USE_IMPLICIT_CYLINDER: without it PyBullet replaces cylinders
by convex hulls and its distances come out ~2 mm short. Its boxes carry a small rounding margin, so box
edge/corner distances read up to ~1 mm long; faces and cylinders agree to ~1e-7 m.
"""

from __future__ import annotations

import math

import numpy as np
import pybullet as pb
import pytest

from twin.collision import DistanceResult, PathCheck, PlanningScene
from twin.config import PROJECT_ROOT, Settings, load_config, settings_from_dict
from twin.errors import InvalidRequestError
from twin.robot.kinematics import JOINT_NAMES, URArm

N_REFERENCE = 2000


def _scene_settings() -> Settings:
    """configs/robocup.yaml when present (padding forced to 0), else a table and two bins."""
    path = PROJECT_ROOT / "configs" / "robocup.yaml"
    if path.is_file():
        s = load_config(path)
        return s.model_copy(update={"collision": s.collision.model_copy(update={"padding_m": 0.0})})
    return settings_from_dict(
        {
            "world": {
                "fixtures": [
                    {"name": "table", "urdf": "urdf/table.urdf", "position": [0.3, 0.0, 0.0]},
                    {"name": "bin_blue", "urdf": "urdf/bin_blue.urdf", "position": [0.05, 0.45, 0.0]},
                    {"name": "bin_green", "urdf": "urdf/bin_green.urdf", "position": [0.05, -0.45, 0.0]},
                ]
            }
        }
    )


def _sample(rng: np.random.Generator, n: int) -> np.ndarray:
    """Shoulder lift in [-pi, 0] (upper arm above the base plane), the rest in [-pi, pi]: about a third
    of these configurations collide (table, bins or self)."""
    lo = np.array([-math.pi, -math.pi, -math.pi, -math.pi, -math.pi, -math.pi])
    hi = np.array([math.pi, 0.0, math.pi, math.pi, math.pi, math.pi])
    return rng.uniform(lo, hi, size=(n, 6))


class BulletReference:
    """The same cell in PyBullet; distances from getClosestPoints per link pair, using the planning
    scene's own pair list (moving robot links vs every fixture, plus the allowed self pairs)."""

    def __init__(self, settings: Settings, scene: PlanningScene):
        self.cid = pb.connect(pb.DIRECT)
        flags = pb.URDF_USE_IMPLICIT_CYLINDER
        self.robot = pb.loadURDF(
            str(settings.resolve(settings.robot.urdf)), useFixedBase=True, flags=flags, physicsClientId=self.cid
        )
        self.joint, link = {}, {"base_link": -1}
        for i in range(pb.getNumJoints(self.robot, physicsClientId=self.cid)):
            info = pb.getJointInfo(self.robot, i, physicsClientId=self.cid)
            self.joint[info[1].decode()] = i
            link[info[12].decode()] = i
        fixtures = {
            f.name: pb.loadURDF(
                str(settings.resolve(f.urdf)),
                basePosition=f.position,
                baseOrientation=pb.getQuaternionFromEuler(f.rpy),
                useFixedBase=True,
                flags=flags,
                physicsClientId=self.cid,
            )
            for f in settings.world.fixtures
        }
        m = scene.model
        moving = [ln for ln in m.link_names if m.links[ln].shapes and ln != m.root]
        self.pairs = [(self.robot, fb, link[ln], -1, ln, fn) for ln in moving for fn, fb in fixtures.items()]
        self.pairs += [(self.robot, self.robot, link[a], link[b], a, b) for a, b in scene.allowed_self_pairs()]

    def min_distance(self, q: np.ndarray, opening: float = 0.085) -> tuple[float, str, str]:
        for name, v in zip(JOINT_NAMES, q, strict=True):
            pb.resetJointState(self.robot, self.joint[name], float(v), physicsClientId=self.cid)
        for name in ("left_finger_joint", "right_finger_joint"):
            pb.resetJointState(self.robot, self.joint[name], opening / 2, physicsClientId=self.cid)
        best = (math.inf, "", "")
        for ba, bb, la, lb, na, nb in self.pairs:
            for c in pb.getClosestPoints(ba, bb, 3.0, la, lb, physicsClientId=self.cid):
                if c[8] < best[0]:
                    best = (c[8], na, nb)
        return best

    def close(self) -> None:
        pb.disconnect(self.cid)


@pytest.fixture(scope="module")
def settings() -> Settings:
    return _scene_settings()


@pytest.fixture(scope="module")
def scene(settings) -> PlanningScene:
    return PlanningScene.from_settings(settings)


@pytest.fixture(scope="module")
def reference(settings, scene):
    ref = BulletReference(settings, scene)
    yield ref
    ref.close()


@pytest.fixture(scope="module")
def reference_run(scene, reference):
    """2000 seeded configurations with FCL and PyBullet answers."""
    qs = _sample(np.random.default_rng(7), N_REFERENCE)
    pb_d = np.array([reference.min_distance(q)[0] for q in qs])
    return qs, pb_d, scene.in_collision_batch(qs), scene.min_distance_batch(qs)


def _fresh(settings: Settings) -> PlanningScene:
    return PlanningScene.from_settings(settings)


def _pose(xyz, R=None) -> np.ndarray:
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    T[:3, 3] = xyz
    return T


DOWN = np.diag([1.0, -1.0, -1.0])  # tcp z pointing at the table


def _q_for_tcp(xyz, R=DOWN) -> np.ndarray:
    """An elbow-up IK solution for a tcp pose (the test scenes are all reachable)."""
    sols = URArm().ik(_pose(xyz, R))
    assert len(sols), f"no IK for {xyz}"
    # prefer solutions near the home posture (elbow up, wrist down)
    home = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    return sols[np.argmin(np.abs(sols - home).sum(axis=1))]


# ---- agreement with PyBullet ----------------------------------------------------------------------
def test_sampled_configurations_collide_often_enough_to_be_meaningful(reference_run):
    _, pb_d, fcl_hit, _ = reference_run
    frac = float(np.mean(pb_d < 0))
    assert 0.2 <= frac <= 0.6, f"{frac:.1%} of the sampled configurations collide"
    assert 0.2 <= float(np.mean(fcl_hit)) <= 0.6


def test_in_collision_agrees_with_pybullet_on_2000_configurations(reference_run):
    _, pb_d, fcl_hit, _ = reference_run
    agree = fcl_hit == (pb_d < 0)
    assert agree.mean() >= 0.995, f"agreement {agree.mean():.2%}"
    # every disagreement is a grazing contact
    assert np.all(np.abs(pb_d[~agree]) <= 1e-3), pb_d[~agree]


def test_min_distance_agrees_with_pybullet_within_2mm_where_both_are_free(reference_run):
    _, pb_d, fcl_hit, fcl_d = reference_run
    free = (pb_d > 0) & ~fcl_hit
    err = np.abs(fcl_d[free] - pb_d[free])
    assert free.sum() > 0.3 * N_REFERENCE
    assert err.max() <= 2e-3, f"worst |FCL - PyBullet| = {err.max() * 1e3:.2f} mm"
    assert np.median(err) <= 1e-5  # faces and cylinders agree essentially exactly


def test_signed_distance_is_negative_exactly_when_in_collision(reference_run):
    _, _, fcl_hit, fcl_d = reference_run
    assert np.array_equal(fcl_d <= 0, fcl_hit)


def test_min_distance_names_the_same_pair_as_pybullet(scene, reference):
    rng = np.random.default_rng(8)
    same = total = 0
    for q in _sample(rng, 200):
        r = scene.min_distance(q)
        d, a, b = reference.min_distance(q)
        if r.distance > 5e-3 and d > 5e-3:  # skip near-ties between colliding pairs
            total += 1
            same += {r.robot_part, r.other} == {a, b} or abs(r.distance - d) < 1e-3
    assert total > 50 and same / total >= 0.95


# ---- exclusions and sanity of the model -----------------------------------------------------------
def test_home_and_zero_postures_are_collision_free(scene, settings):
    assert not scene.in_collision(np.array(settings.robot.home))
    assert not scene.in_collision(np.zeros(6))
    assert scene.min_distance(np.array(settings.robot.home)).distance > 0.005


def test_exclusions_cover_jointed_links_gripper_parts_and_closed_fingers(scene):
    ex = scene.excluded_pairs
    for pair in [
        ("base_link", "shoulder_link"),
        ("shoulder_link", "upper_arm_link"),
        ("upper_arm_link", "forearm_link"),
        ("forearm_link", "wrist_1_link"),
        ("wrist_1_link", "wrist_2_link"),
        ("wrist_2_link", "wrist_3_link"),
        ("wrist_3_link", "gripper_base"),
        ("gripper_base", "left_finger"),
        ("gripper_base", "right_finger"),
        ("left_finger", "right_finger"),
    ]:
        assert pair in ex, pair
    allowed = set(scene.allowed_self_pairs())
    assert ("base_link", "forearm_link") in allowed and ("upper_arm_link", "gripper_base") in allowed
    assert not allowed & ex
    geo = [ln for ln in scene.model.link_names if scene.model.links[ln].shapes]
    assert len(allowed) + len(ex) == len(geo) * (len(geo) - 1) // 2
    held = set(scene.held_object_checked_against())
    assert held == {"base_link", "shoulder_link", "upper_arm_link", "forearm_link", "wrist_1_link", "wrist_2_link"}


def test_robot_base_is_not_checked_against_the_table_it_stands_on(settings):
    s = _fresh(settings)
    s.add_box_bounds("slab_under_base", (-0.1, -0.1, -0.02), (0.1, 0.1, 0.01))  # overlaps base_link only
    assert not s.in_collision(np.array(settings.robot.home))


def test_link_poses_of_the_collision_model_match_the_urdf_chain(scene):
    rng = np.random.default_rng(9)
    for q in _sample(rng, 20):
        got = scene.link_poses(q)
        want = scene.model.link_poses(q, finger_opening=scene.gripper_opening)
        for ln in scene.model.link_names:
            assert np.abs(got[ln] - want[ln][0]).max() < 1e-12


# ---- perceived boxes ------------------------------------------------------------------------------
def test_added_box_at_the_tcp_causes_collision_and_removing_it_clears_it(settings):
    s = _fresh(settings)
    q = _q_for_tcp((-0.45, 0.0, 0.35))
    assert not s.in_collision(q)
    s.add_box("obstacle", (0.1, 0.1, 0.1), _pose((-0.45, 0.0, 0.35)))
    assert "obstacle" in s.names()
    assert s.in_collision(q)
    r = s.min_distance(q)
    assert r.distance < 0 and r.other == "obstacle" and not r.self_collision
    s.remove("obstacle")
    assert "obstacle" not in s.names()
    assert not s.in_collision(q)


def test_box_distance_is_exact_below_a_downward_gripper(settings):
    s = _fresh(settings)
    q = _q_for_tcp((-0.45, 0.0, 0.35))
    tip_z = 0.35 - (0.147 - 0.135)  # fingertips: 0.147 m along tool z from the flange, tcp at 0.135
    top = 0.30  # 3.8 cm below the fingertips: closer than anything else in the cell
    s.add_box_bounds("block", (-0.55, -0.1, 0.0), (-0.35, 0.1, top))
    r = s.min_distance(q, include_self=False)
    assert r.other == "block"
    assert r.distance == pytest.approx(tip_z - top, abs=1e-6)


def test_add_box_bounds_equals_add_box(settings):
    a, b = _fresh(settings), _fresh(settings)
    a.add_box_bounds("o", (-0.5, -0.2, 0.0), (-0.3, 0.1, 0.3))
    b.add_box("o", (0.2, 0.3, 0.3), _pose((-0.4, -0.05, 0.15)))
    qs = _sample(np.random.default_rng(10), 100)
    assert np.allclose(a.min_distance_batch(qs), b.min_distance_batch(qs), atol=1e-9)


def test_add_box_with_an_existing_name_replaces_it(settings):
    s = _fresh(settings)
    q = _q_for_tcp((-0.45, 0.0, 0.35))
    s.add_box("o", (0.1, 0.1, 0.1), _pose((-0.45, 0.0, 0.35)))
    s.add_box("o", (0.1, 0.1, 0.1), _pose((-0.45, 0.0, 0.80)))
    assert s.names().count("o") == 1
    assert not s.in_collision(q)


def test_padding_inflates_the_environment_not_the_robot(settings):
    q = _q_for_tcp((-0.45, 0.0, 0.35))  # fingertips 8.8 cm above the block, 1 cm with top at 0.328
    plain = _fresh(settings)
    padded_settings = settings.model_copy(
        update={"collision": settings.collision.model_copy(update={"padding_m": 0.02})}
    )
    padded = PlanningScene.from_settings(padded_settings)
    # self-collision is unpadded: the same robot-robot minimum with and without padding
    home = np.array(settings.robot.home)
    assert plain.min_distance(home).self_collision
    assert padded.min_distance(home).distance == pytest.approx(plain.min_distance(home).distance, abs=1e-9)
    for s in (plain, padded):
        s.add_box_bounds("block", (-0.55, -0.1, 0.0), (-0.35, 0.1, 0.328))
    d_plain = plain.min_distance(q, include_self=False).distance
    assert d_plain == pytest.approx(0.010, abs=1e-6)
    assert padded.min_distance(q, include_self=False).distance == pytest.approx(d_plain - 0.02, abs=1e-6)
    assert not plain.in_collision(q) and padded.in_collision(q)


# ---- held object ----------------------------------------------------------------------------------
def test_attached_box_moves_with_the_tcp(settings):
    s = _fresh(settings)
    q_low, q_high = _q_for_tcp((-0.45, 0.0, 0.20)), _q_for_tcp((-0.45, 0.0, 0.30))
    # a 5 x 5 x 30 cm bar held 10 cm below the tcp: its lower end is 0.25 m below the tcp
    s.attach_box("bar", (0.05, 0.05, 0.30), _pose((0.0, 0.0, 0.10)))
    assert s.attached == "bar"
    assert s.in_collision(q_low)  # bar end at z = -0.05: through the table
    r = s.min_distance(q_low, include_self=False)
    assert r.robot_part == "bar" and r.other == "table" and r.distance < 0
    r = s.min_distance(q_high, include_self=False)
    assert r.robot_part == "bar" and r.other == "table"
    assert r.distance == pytest.approx(0.30 - 0.25, abs=1e-6)
    assert s.detach() == "bar" and s.attached is None
    assert not s.in_collision(q_low)


def test_attached_box_is_not_checked_against_the_gripper_holding_it(settings):
    s = _fresh(settings)
    q = _q_for_tcp((-0.45, 0.0, 0.40))
    s.attach_box("cube", (0.10, 0.10, 0.10), _pose((0.0, 0.0, -0.03)))  # overlaps both fingers and the palm
    assert s.min_distance(q).distance > 0
    assert not s.in_collision(q)


def test_attached_box_collides_with_the_arm(settings):
    s = _fresh(settings)
    q = _q_for_tcp((-0.45, 0.0, 0.40))
    s.attach_box("rod", (0.03, 0.03, 0.04), _pose((0.0, 0.0, -0.25)))  # reaches back into wrist_2
    assert s.in_collision(q)
    r = s.min_distance(q)
    assert r.self_collision and "rod" in (r.robot_part, r.other)


def test_closing_the_gripper_on_a_thin_post_collides(settings):
    s = _fresh(settings)
    q = _q_for_tcp((-0.45, 0.0, 0.30))
    s.add_box("post", (0.02, 0.02, 0.02), _pose((-0.45, 0.0, 0.30)))  # between the open fingertips
    assert not s.in_collision(q)
    s.set_gripper_opening(0.01)
    assert s.gripper_opening == pytest.approx(0.01)
    assert s.in_collision(q)
    s.set_gripper_opening(0.085)
    assert not s.in_collision(q)


# ---- batches and paths ----------------------------------------------------------------------------
def test_batch_results_equal_single_calls(settings):
    s = _fresh(settings)
    s.attach_box("cube", (0.06, 0.06, 0.06), _pose((0.0, 0.0, 0.02)))
    qs = _sample(np.random.default_rng(11), 300)
    single_hit = np.array([s.in_collision(q) for q in qs])
    single_d = np.array([s.min_distance(q).distance for q in qs])
    assert np.array_equal(s.in_collision_batch(qs), single_hit)
    # The link poses come from two computations (batched `_frames`, single `_frames_one`), equal here but
    # free to differ by an ulp on another BLAS kernel or SIMD path; FCL's GJK distance is not that stable:
    # a 1-ulp change of q moved 1.5 % of these distances, by up to 9e-5 m (measured, 3000 configurations).
    # So: nearly all equal to 1e-12 m, every one within 0.5 mm (a batch row mixed up is centimetres off).
    gap = np.abs(s.min_distance_batch(qs) - single_d)
    assert np.mean(gap <= 1e-12) >= 0.95 and gap.max() <= 5e-4, (np.mean(gap <= 1e-12), gap.max())
    assert 0 < single_hit.sum() < len(qs)


def test_first_collision_and_check_path_find_the_first_hit(settings):
    s = _fresh(settings)
    q_free = _q_for_tcp((-0.45, 0.0, 0.40))
    q_hit = _q_for_tcp((-0.45, 0.0, -0.02))  # fingertips 3.2 cm below the table top
    assert s.first_collision(np.array([q_free, q_free])) is None
    assert s.first_collision(np.array([q_free, q_free, q_hit, q_hit])) == 2
    result = s.check_path(np.array([q_free, q_hit]), resolution_rad=0.01)
    assert isinstance(result, PathCheck) and not result.free and result.segment == 0
    assert s.in_collision(result.q)
    assert s.check_path(np.array([q_free, _q_for_tcp((-0.40, 0.1, 0.40))])).free


def test_min_distance_result_type_and_environment_only_option(scene, settings):
    home = np.array(settings.robot.home)
    r = scene.min_distance(home)
    assert isinstance(r, DistanceResult) and not r.in_collision and r.robot_part and r.other
    env_only = scene.min_distance(home, include_self=False)
    assert not env_only.self_collision and env_only.other in scene.names()
    assert env_only.distance >= r.distance


def test_sequential_queries_along_a_path_match_fresh_scenes(settings):
    """The warm start (previous closest pair) must never change the answer."""
    s = _fresh(settings)
    path = np.linspace(_q_for_tcp((-0.45, -0.2, 0.30)), _q_for_tcp((-0.45, 0.25, 0.05)), 25)
    along = [s.min_distance(q, include_self=False) for q in path]
    for q, r in zip(path, along, strict=True):
        f = _fresh(settings).min_distance(q, include_self=False)
        assert r.distance == pytest.approx(f.distance, abs=1e-12)  # names may differ on exact ties (fingers)


# ---- bad input ------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    "call",
    [
        lambda s: s.in_collision(np.zeros(5)),
        lambda s: s.min_distance(np.full(6, np.nan)),
        lambda s: s.in_collision_batch(np.zeros((3, 5))),
        lambda s: s.add_box("b", (0.1, -0.1, 0.1), np.eye(4)),
        lambda s: s.add_box("b", (0.1, 0.1, 0.1), np.eye(3)),
        lambda s: s.add_box("b", (0.1, 0.1, 0.1), np.diag([2.0, 1.0, 1.0, 1.0])),
        lambda s: s.add_box_bounds("b", (0, 0, 0), (0.1, -0.1, 0.1)),
        lambda s: s.add_box("table", (0.1, 0.1, 0.1), np.eye(4)),
        lambda s: s.remove("nothing"),
        lambda s: s.set_gripper_opening(0.2),
        lambda s: s.check_path(np.zeros((2, 6)), resolution_rad=0.0),
    ],
    ids=[
        "q-5",
        "q-nan",
        "qs-3x5",
        "neg-size",
        "pose-3x3",
        "pose-scaled",
        "bounds-flipped",
        "replace-fixture",
        "remove-unknown",
        "opening-too-wide",
        "zero-resolution",
    ],
)
def test_bad_input_raises_invalid_request(settings, call):
    with pytest.raises(InvalidRequestError):
        call(_fresh(settings))


def test_attaching_twice_without_detach_raises(settings):
    s = _fresh(settings)
    s.attach_box("a", (0.05, 0.05, 0.05), np.eye(4))
    with pytest.raises(InvalidRequestError):
        s.attach_box("b", (0.05, 0.05, 0.05), np.eye(4))


def test_run_time_boxes_are_listed_with_their_bounds_and_the_held_box_with_its_size():
    from twin.config import settings_from_dict

    scene = PlanningScene.from_settings(settings_from_dict({}))
    scene.add_box_bounds("obstacle", [-0.5, -0.2, 0.0], [-0.4, 0.3, 0.2])
    b = scene.box_bounds()["obstacle"]
    np.testing.assert_allclose(
        [b.x_min, b.x_max, b.y_min, b.y_max, b.z_min, b.z_max], [-0.5, -0.4, -0.2, 0.3, 0.0, 0.2], atol=1e-12
    )
    assert "table" not in scene.boxes()
    scene.remove("obstacle")
    assert scene.box_bounds() == {}
    T = np.eye(4)
    T[2, 3] = 0.02
    scene.attach_box("cube", [0.05, 0.05, 0.05], T)
    name, size, pose = scene.attached_box()
    assert name == "cube" and size.tolist() == [0.05, 0.05, 0.05] and pose[2, 3] == 0.02
    scene.detach()
    assert scene.attached_box() is None


def test_clearance_ignores_the_shoulder_and_follows_the_arm():
    from twin.config import load_config

    scene = PlanningScene.from_settings(load_config(PROJECT_ROOT / "configs/robocup.yaml"))
    home = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    lower = home + np.array([0.0, 0.35, 0.3, 0.0, 0.0, 0.0])  # the gripper closer to the table
    c_home, c_low = scene.clearance(home), scene.clearance(lower)
    assert c_home.robot_part not in ("base_link", "shoulder_link")
    assert c_low.distance < c_home.distance
    assert c_home.distance >= scene.min_distance(home, include_self=False).distance - 1e-12
    np.testing.assert_allclose(scene.clearance_batch(np.stack([home, lower])), [c_home.distance, c_low.distance])


@pytest.mark.parametrize("held", [False, True])
def test_min_clearance_is_the_exact_minimum_of_the_clearances(held):
    """`min_clearance` measures with FCL only where the sphere bounds allow a smaller clearance than found so
    far; its answer must be `clearance_batch`'s minimum and argmin, on paths that sweep near the table and the
    bins (clearances from centimetres to decimetres), with a held cube too, and where some configurations
    collide (their bound is none: they are measured)."""
    from twin.config import load_config

    scene = PlanningScene.from_settings(load_config(PROJECT_ROOT / "configs/robocup.yaml"))
    if held:
        T = np.eye(4)
        T[2, 3] = 0.03
        scene.attach_box("cube", [0.05, 0.05, 0.05], T)
    rng = np.random.default_rng(5)
    home = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    for _ in range(12):
        ends = home + rng.uniform(-1.2, 1.2, (3, 6))
        qs = np.vstack([np.linspace(ends[k], ends[k + 1], 150) for k in range(2)])
        d = scene.clearance_batch(qs)
        least, where = scene.min_clearance(qs)
        assert least == d.min() and d[where] == d.min()
    with pytest.raises(InvalidRequestError):
        scene.min_clearance(np.empty((0, 6)))


def test_clearance_is_not_capped_by_a_shape_the_shoulder_lift_turns_in_place():
    """The upper arm's cylinder around the shoulder-lift axis is 0.1025 m from the robocup table in every
    configuration (the lift turns it about its own axis): it once capped every clearance at that value. Left
    out like the shoulder, the clearance of an arm raised clear of everything is larger and follows the arm."""
    from twin.config import load_config

    scene = PlanningScene.from_settings(load_config(PROJECT_ROOT / "configs/robocup.yaml"))
    home = np.array([0.0, -1.5708, 1.5708, -1.5708, -1.5708, 0.0])
    raised = [home + np.array([0.0, dq, 0.0, 0.0, 0.0, 0.0]) for dq in (0.0, -0.2, -0.4)]
    c = scene.clearance_batch(np.stack(raised))
    assert c.max() > 0.1025 + 0.005, c
    assert len(set(np.round(c, 6))) == len(c), c  # every posture its own clearance


# ---- padded copies --------------------------------------------------------------------------------
def _padded_pair(settings, extra=0.02):
    """A scene with a run-time box, a held box and a half-open gripper, and its padded copy."""
    s = _fresh(settings)
    s.add_box_bounds("block", (-0.55, -0.1, 0.0), (-0.35, 0.1, 0.328))
    s.set_gripper_opening(0.05)
    s.attach_box("cube", (0.04, 0.04, 0.04), _pose((0.0, 0.0, 0.03)))
    return s, s.padded(extra)


def test_padded_copy_collides_within_the_extra_margin_and_is_clear_where_both_are(settings):
    q_near = _q_for_tcp((-0.45, 0.0, 0.35))  # fingertips 1 cm above the block
    q_far = _q_for_tcp((-0.45, 0.0, 0.45))  # 11 cm above it
    plain = _fresh(settings)
    plain.add_box_bounds("block", (-0.55, -0.1, 0.0), (-0.35, 0.1, 0.328))
    big = plain.padded(0.02)
    assert not plain.in_collision(q_near) and big.in_collision(q_near)
    assert not plain.in_collision(q_far) and not big.in_collision(q_far)
    assert big.padding_m == pytest.approx(plain.padding_m + 0.02)


def test_padded_copy_shrinks_environment_distances_by_the_extra_margin(settings):
    s, p = _padded_pair(settings, 0.015)
    # on a face the distance shrinks by exactly the extra margin (fingertips 1 cm above the block top)
    q = _q_for_tcp((-0.45, 0.0, 0.35))
    bare = _fresh(settings)
    bare.add_box_bounds("block", (-0.55, -0.1, 0.0), (-0.35, 0.1, 0.328))
    d = bare.min_distance(q, include_self=False)
    assert d.other == "block"
    d_padded = bare.padded(0.004).min_distance(q, include_self=False).distance
    assert d_padded == pytest.approx(d.distance - 0.004, abs=1e-9)
    # everywhere: by at least the margin (more near box edges and cylinder rims, as padding_m is defined),
    # and exactly as much as in a scene built from scratch with the larger padding
    qs = _sample(np.random.default_rng(21), 300)
    d0, d1 = s.min_distance_batch(qs, include_self=False), p.min_distance_batch(qs, include_self=False)
    ok = d0 > 0.02
    assert ok.sum() > 50
    assert np.all(d1[ok] <= d0[ok] - 0.015 + 1e-6)  # FCL GJK tolerance
    wider = settings.collision.model_copy(update={"padding_m": s.padding_m + 0.015})
    rebuilt = PlanningScene.from_settings(settings.model_copy(update={"collision": wider}))
    rebuilt.add_box_bounds("block", (-0.55, -0.1, 0.0), (-0.35, 0.1, 0.328))
    rebuilt.set_gripper_opening(0.05)
    rebuilt.attach_box("cube", (0.04, 0.04, 0.04), _pose((0.0, 0.0, 0.03)))
    np.testing.assert_allclose(d1, rebuilt.min_distance_batch(qs, include_self=False), atol=1e-12)
    np.testing.assert_allclose(p.min_distance_batch(qs), rebuilt.min_distance_batch(qs), atol=1e-12)
    # self-collision is not padded: the robot-robot minimum at home is the same
    home = np.array(settings.robot.home)
    empty = _fresh(settings)
    assert empty.min_distance(home).self_collision
    assert empty.padded(0.02).min_distance(home).distance == pytest.approx(empty.min_distance(home).distance, abs=1e-12)


def test_padded_copy_keeps_boxes_held_object_opening_and_rules_and_leaves_the_original(settings):
    s, p = _padded_pair(settings)
    assert p.names() == s.names()
    assert p.excluded_pairs == s.excluded_pairs
    assert p.allowed_self_pairs() == s.allowed_self_pairs()
    assert p.gripper_opening == s.gripper_opening == 0.05
    assert p.attached == "cube" and np.array_equal(p.attached_box()[2], s.attached_box()[2])
    assert {n: (a.tolist(), b.tolist()) for n, (a, b) in p.boxes().items()} == {
        n: (a.tolist(), b.tolist()) for n, (a, b) in s.boxes().items()
    }
    assert p.model is s.model  # the parsed robot is shared, not read again
    # the original is unchanged: same padding and the same answers as an identically built scene
    twin_scene = _fresh(settings)
    twin_scene.add_box_bounds("block", (-0.55, -0.1, 0.0), (-0.35, 0.1, 0.328))
    twin_scene.set_gripper_opening(0.05)
    twin_scene.attach_box("cube", (0.04, 0.04, 0.04), _pose((0.0, 0.0, 0.03)))
    qs = _sample(np.random.default_rng(22), 200)
    assert s.padding_m == twin_scene.padding_m
    np.testing.assert_array_equal(s.min_distance_batch(qs), twin_scene.min_distance_batch(qs))
    # edits of the copy do not reach the original, and the reverse
    p.remove("block")
    p.detach()
    assert "block" in s.names() and s.attached == "cube"
    s.set_gripper_opening(0.0)
    assert p.gripper_opening == 0.05


def test_padded_zero_is_an_equal_copy(settings):
    s, p = _padded_pair(settings, 0.0)
    qs = _sample(np.random.default_rng(23), 300)
    assert p.padding_m == s.padding_m
    np.testing.assert_array_equal(p.in_collision_batch(qs), s.in_collision_batch(qs))
    np.testing.assert_allclose(p.min_distance_batch(qs), s.min_distance_batch(qs), atol=1e-12)
    np.testing.assert_allclose(p.clearance_batch(qs), s.clearance_batch(qs), atol=1e-12)


def test_padded_rejects_a_total_padding_out_of_range(settings):
    s = _fresh(settings)
    for bad in (-0.01, 1.5, math.nan):
        with pytest.raises(InvalidRequestError):
            s.padded(bad)
