"""Fault models (issue 13): each changes what it should, where a real fault arises, and nothing when off."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.camera import Intrinsics, RGBDFrame, camera_pose, mount_error, true_camera_pose
from twin.config import load_config
from twin.errors import ConfigError
from twin.perception.capture import capture_frame
from twin.perception.evaluate import run_perception
from twin.perception.noise import apply_sensor_noise, depth_noise_rms
from twin.tasks.pipelines import TASK_PIPELINES
from twin.tasks.warehouse.perception import perceive_warehouse
from twin.world import World

pytest.importorskip("open3d")

RENDERER = "tiny"
# the pipelines scored (perception sits below the tasks that own them, so the caller hands them in)
PIPELINES = TASK_PIPELINES


def _warehouse(**extrinsic_error: float):
    return load_config("warehouse", overrides=[f"camera.extrinsic_error.{k}={v}" for k, v in extrinsic_error.items()])


def _cube_centroids(settings, seed: int) -> np.ndarray:
    """Perceived cube centroids (sorted by x, then y) with the extrinsics the config says (no calibration)."""
    with World(settings, seed, renderer=RENDERER) as world:
        cap = capture_frame(world, settings)
        res = perceive_warehouse(cap.frame, cap.T_base_camera_nominal, settings.perception.warehouse, seed=seed)
    c = np.array([cube.centroid for cube in res.cubes])
    return c[np.lexsort((c[:, 1], c[:, 0]))]


def test_the_mount_error_is_exactly_the_identity_when_off_and_has_the_configured_size():
    s = load_config("configs/warehouse.yaml")
    assert np.array_equal(true_camera_pose(s.camera, 3), camera_pose(s.camera))
    err = s.camera.extrinsic_error.model_copy(update={"translation_m": 0.01, "rotation_deg": 1.0})
    E = mount_error(err, 3)
    assert np.linalg.norm(E[:3, 3]) == pytest.approx(0.01)
    angle = np.degrees(np.arccos(np.clip((np.trace(E[:3, :3]) - 1) / 2, -1, 1)))
    assert angle == pytest.approx(1.0)
    assert np.array_equal(E, mount_error(err, 3)) and not np.allclose(E, mount_error(err, 4))


def test_a_1cm_camera_extrinsic_error_moves_perceived_positions_by_1cm():
    """The fixed camera really sits 1 cm off; perception assumes the configured pose, so every perceived
    cube moves by the error seen from the base: -R t (the same 1 cm for every point)."""
    seed = 2
    nominal = _cube_centroids(_warehouse(), seed)
    faulty_settings = _warehouse(translation_m=0.01)
    faulty = _cube_centroids(faulty_settings, seed)
    assert nominal.shape == faulty.shape and nominal.shape[0] >= 3
    expected = (
        -camera_pose(faulty_settings.camera)[:3, :3] @ mount_error(faulty_settings.camera.extrinsic_error, seed)[:3, 3]
    )
    shift = (faulty - nominal).mean(axis=0)
    assert np.linalg.norm(shift[:2] - expected[:2]) < 0.002, (shift, expected)
    assert np.linalg.norm(expected) == pytest.approx(0.01)


def test_a_mount_error_beyond_its_range_is_a_config_error():
    with pytest.raises(ConfigError, match="translation_m"):
        _warehouse(translation_m=-0.01)


def test_the_noise_scale_multiplies_the_measured_depth_rms_on_a_flat_patch():
    """A flat wall 1 m away: the measured RMS is the model's (~3.8 mm) at scale 1 and three times it at 3;
    scale 1 is bit-for-bit the model without the knob."""
    noise = load_config("warehouse").camera.noise
    flat = RGBDFrame(np.zeros((120, 160, 3), np.uint8), np.full((120, 160), 1.0), Intrinsics(160, 120, 150.0, 150.0))
    rms = {}
    for scale in (1.0, 3.0):
        n = noise.model_copy(update={"scale": scale, "dropout_fraction": 0.0})
        d = apply_sensor_noise(flat, n, np.random.default_rng(7)).depth_m
        rms[scale] = float(np.sqrt(np.mean((d[d > 0] - 1.0) ** 2)))
    assert rms[1.0] == pytest.approx(float(depth_noise_rms(1.0, noise)), rel=0.05)
    assert rms[3.0] / rms[1.0] == pytest.approx(3.0, rel=0.03)
    z = np.linspace(0.3, 2.0, 7)
    plain = z * z * noise.subpixel / (noise.focal_px * noise.baseline_m)
    assert np.array_equal(depth_noise_rms(z, noise), plain)


def _dynamics(world) -> dict[str, tuple[float, float]]:
    import pybullet as pb

    out = {}
    for o in world.objects():
        info = pb.getDynamicsInfo(o.id, -1, physicsClientId=world.client_id)
        out[o.name] = (info[0], info[1])
    return out


def test_object_mass_and_friction_scales_are_drawn_per_object_from_the_seed():
    """Each object's mass and friction are its catalogue values times a factor from the configured range,
    drawn per object from the scene seed, one stream per knob; at [1, 1] nothing changes."""
    with World(load_config("robocup"), 3, renderer=RENDERER) as w:
        nominal = _dynamics(w)
        assert all(not v for v in w.object_scales.values())
    fixed = load_config(
        "robocup", overrides=["world.objects.mass_scale=[1.5, 1.5]", "world.objects.friction_scale=[0.7, 0.7]"]
    )
    with World(fixed, 3, renderer=RENDERER) as w:
        for name, (m, f) in _dynamics(w).items():
            assert m == pytest.approx(1.5 * nominal[name][0]) and f == pytest.approx(0.7 * nominal[name][1])
    ranged = load_config("robocup", overrides=["world.objects.mass_scale=[0.5, 2.0]"])
    both = load_config(
        "robocup", overrides=["world.objects.mass_scale=[0.5, 2.0]", "world.objects.friction_scale=[0.5, 1.0]"]
    )
    scales = []
    for settings in (ranged, ranged, both):
        with World(settings, 3, renderer=RENDERER) as w:
            scales.append({n: v.get("mass") for n, v in w.object_scales.items()})
    masses = list(scales[0].values())
    assert all(0.5 <= m <= 2.0 for m in masses) and len(set(masses)) == len(masses) > 1
    assert scales[0] == scales[1] == scales[2]  # same seed, same draws; the friction knob leaves them alone


def test_a_scale_range_must_be_positive_and_ordered():
    with pytest.raises(ConfigError, match="mass_scale"):
        load_config("robocup", overrides=["world.objects.mass_scale=[2.0, 1.0]"])
    with pytest.raises(ConfigError, match="friction_scale"):
        load_config("robocup", overrides=["world.objects.friction_scale=[0, 1]"])


def test_at_three_times_the_depth_noise_the_robust_preset_still_classifies_every_object_and_the_seed_does_not():
    """The seed's single raw frame and fixed 8 mm table threshold drown at 3x noise (~6 mm RMS at the
    capture range); averaging the settling pause's frames, the edge-preserving filter and a threshold
    from the measured table noise keep every class."""

    def correct(preset: str) -> int:
        s = load_config("robocup", overrides=["camera.noise.scale=3", f"perception.preset={preset}"])
        rep = run_perception(s, pipelines=PIPELINES, seed=11, renderer=RENDERER)
        assert rep.false_positives == 0
        return sum(o["class_est"] == o["class_true"] and o["color_est"] == o["color_true"] for o in rep.objects)

    assert correct("robust") == 8
    assert correct("seed") <= 4


def _joint_after(settings, seconds: float, step_rad: float = 0.2) -> np.ndarray:
    """Command a step of `step_rad` on the shoulder pan from home and return the joints after `seconds`."""
    with World(settings, 0, renderer=RENDERER) as world:
        q0 = world.joint_positions()
        world.set_joint_targets(q0 + np.array([step_rad, 0, 0, 0, 0, 0]))
        world.step(round(seconds / world.dt))
        return world.joint_positions() - q0


def test_a_sluggish_controller_lags_behind_its_targets_and_catches_up_and_is_exact_when_off():
    nominal = load_config("robocup")
    assert np.array_equal(
        _joint_after(nominal, 0.25), _joint_after(load_config("robocup", ["robot.tracking_time_constant_s=0"]), 0.25)
    )
    slow = load_config("robocup", ["robot.tracking_time_constant_s=0.2"])
    early_nominal, early_slow = _joint_after(nominal, 0.1)[0], _joint_after(slow, 0.1)[0]
    assert early_slow < 0.6 * early_nominal, (early_slow, early_nominal)  # behind where it should be
    assert _joint_after(slow, 2.0)[0] == pytest.approx(0.2, abs=2e-3)  # and there in the end


def test_tracking_noise_shakes_a_held_arm_by_about_its_rms():
    def jitter(settings) -> float:
        with World(settings, 0, renderer=RENDERER) as world:
            qs = []
            for _ in range(240):
                world.step()
                qs.append(world.joint_positions())
        return float(np.std(np.diff(np.array(qs)[:, 0])))

    assert jitter(load_config("robocup")) < 1e-5
    assert jitter(load_config("robocup", ["robot.tracking_noise_rad=0.002"])) > 1e-4


def test_a_worn_gripper_squeezes_with_its_force_scale():
    def effort(overrides: list[str]) -> float:
        s = load_config("robocup", ["world.objects.items=[{class: cube, color: red}]", *overrides])
        with World(s, 1, renderer=RENDERER) as world:
            from twin.tasks.cell import Cell, top_down

            cell = Cell(s, world)
            cube = world.objects()[0]
            x, y, _ = cube.position
            qx, qy, qz, qw = cube.orientation_xyzw
            yaw = math.atan2(2 * (qx * qy + qz * qw), 1 - 2 * (qy * qy + qz * qz))  # across two faces
            sols = cell.kin.ik(top_down((x, y, 0.0375), yaw))
            world.reset_joints(sols[int(np.argmin(np.abs(sols - world.joint_positions()).sum(axis=1)))])
            world.close_gripper(force_n=25.0)  # below what the contact settles at on its own (~29 N a finger)
            world.step(480)
            return world.gripper_effort()

    assert effort([]) == pytest.approx(25.0, rel=0.02)
    assert effort(["gripper.force_scale=0.5"]) == pytest.approx(12.5, rel=0.02)


def test_a_late_frame_shows_the_world_as_it_was_latency_ago():
    """A cube let go 0.3 m above the table: after a 0.25 s pause it lies on the table, but a frame 0.25 s
    late still shows it where it was let go (closer to the camera)."""
    from twin.camera import Intrinsics as Intr

    def depth_at_start(latency: float) -> float:
        s = load_config("warehouse", [f"camera.latency_s={latency}", "perception.depth_filter.spatial=false"])
        s = s.model_copy(
            update={
                "camera": s.camera.model_copy(update={"noise": s.camera.noise.model_copy(update={"enabled": False})})
            }
        )
        with World(s, 0, renderer=RENDERER) as world:
            cube = world.objects()[0]
            p = np.array([cube.position[0], cube.position[1], 0.3])
            world.set_object_pose(cube.id, p, [0, 0, 0, 1])
            cap = capture_frame(world, s, settle_s=0.25)
            T = camera_pose(s.camera)
            pc = np.linalg.inv(T) @ np.append(p, 1.0)
            K = Intr.from_settings(s.camera).matrix()
            u, v = (K @ (pc[:3] / pc[2]))[:2]
            return float(cap.frame.depth_m[round(v), round(u)]), float(pc[2])

    late, z_start = depth_at_start(0.25)
    now, _ = depth_at_start(0.0)
    assert late == pytest.approx(z_start - 0.025, abs=0.02)  # the cube's near face, 0.3 m up
    assert now > late + 0.1  # it has fallen out of that ray


# every fault model's key at its "off" value (the defaults)
FAULTS_OFF = [
    "camera.noise.scale=1",
    "camera.noise.static_fraction=0",
    "camera.noise.color_gain=[1,1,1]",
    "camera.extrinsic_error.translation_m=0",
    "camera.extrinsic_error.rotation_deg=0",
    "camera.latency_s=0",
    "robot.tracking_time_constant_s=0",
    "robot.tracking_noise_rad=0",
    "gripper.force_scale=1",
    "world.objects.mass_scale=[1,1]",
    "world.objects.friction_scale=[1,1]",
]


def test_a_run_with_every_fault_model_set_to_off_is_the_nominal_run_bit_for_bit():
    from twin.tasks import run_task

    nominal = run_task(load_config("robocup"), seed=1)
    off = run_task(load_config("robocup", FAULTS_OFF), seed=1)
    assert off.sim_time_s == nominal.sim_time_s
    assert [(o.id, o.placed, o.error, o.cycle_time_s, o.pose_error_m) for o in off.objects] == [
        (o.id, o.placed, o.error, o.cycle_time_s, o.pose_error_m) for o in nominal.objects
    ]


@pytest.mark.parametrize(
    "override",
    [
        "world.unmodelled_obstacle={size_m: [0.04, 0, 0.15]}",
        "robot.tracking_time_constant_s=-0.1",
        "gripper.force_scale=0",
        "camera.latency_s=2",
        "camera.noise.static_fraction=1.5",
        "camera.noise.color_gain=[0.1,1,1]",
    ],
)
def test_a_fault_model_out_of_its_range_is_a_config_error(override):
    with pytest.raises(ConfigError):
        load_config("robocup", [override])


def test_a_coloured_light_scales_each_channel_of_the_colour_image_and_nothing_when_off():
    from twin.config import DepthNoiseSettings

    rgb = np.full((8, 8, 3), [100, 150, 200], np.uint8)
    frame = RGBDFrame(rgb, np.full((8, 8), 0.7), Intrinsics(8, 8, 612.0, 611.0))
    plain = DepthNoiseSettings(rgb_noise_std=0.0)
    warm = DepthNoiseSettings(rgb_noise_std=0.0, color_gain=(1.2, 1.0, 0.8))
    out = apply_sensor_noise(frame, warm, np.random.default_rng(0)).rgb
    assert out[0, 0].tolist() == [120, 150, 160]
    assert np.array_equal(apply_sensor_noise(frame, plain, np.random.default_rng(0)).rgb, rgb)


def test_under_a_warm_light_the_table_white_balance_keeps_the_colours_and_the_seed_pipeline_does_not():
    """A light of [1.5, 1.0, 0.6] turns the blue cube grey-violet; balanced on the table, whose model colour
    is known, it is blue again."""

    def correct(preset: str) -> int:
        s = load_config("robocup", ["camera.noise.color_gain=[1.5,1.0,0.6]", f"perception.preset={preset}"])
        rep = run_perception(s, pipelines=PIPELINES, seed=5, renderer=RENDERER)
        return sum(o["class_est"] == o["class_true"] and o["color_est"] == o["color_true"] for o in rep.objects)

    assert correct("robust") == 8
    assert correct("seed") <= 7
