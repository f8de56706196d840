"""Fault models (issue 13): each changes what it should, where a real fault arises, and nothing when off."""

from __future__ import annotations

import numpy as np
import pytest

from twin.camera import Intrinsics, RGBDFrame, camera_pose, mount_error, true_camera_pose
from twin.config import load_config
from twin.errors import ConfigError
from twin.perception.capture import capture_frame
from twin.perception.noise import apply_sensor_noise, depth_noise_rms
from twin.tasks.warehouse.perception import perceive_warehouse
from twin.world import World

pytest.importorskip("open3d")

RENDERER = "tiny"


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
