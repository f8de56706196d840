"""Fault models (issue 13): each changes what it should, where a real fault arises, and nothing when off."""

from __future__ import annotations

import numpy as np
import pytest

from twin.camera import camera_pose, mount_error, true_camera_pose
from twin.config import load_config
from twin.errors import ConfigError
from twin.perception.capture import capture_frame
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
