"""Depth post-processing (issue 13): what each filter removes, what it keeps, and the seed preset."""

from __future__ import annotations

import math

import numpy as np
import pytest

from twin.camera import Intrinsics, RGBDFrame
from twin.config import DepthNoiseSettings, load_config
from twin.errors import ConfigError
from twin.perception.depth_filter import depth_noise_coefficient, spatial_filter, temporal_average
from twin.perception.detection import table_noise, table_threshold_for
from twin.perception.noise import depth_noise_rms, sensor_burst

INTR = Intrinsics(160, 120, 612.0, 611.0)


def _flat(z: float = 0.7) -> RGBDFrame:
    return RGBDFrame(np.full((120, 160, 3), 128, np.uint8), np.full((120, 160), z), INTR)


def _noise(**kw: float) -> DepthNoiseSettings:
    """The D435i model without quantisation and dropouts (they would blur the RMS being measured)."""
    return DepthNoiseSettings(depth_unit_m=0.0, dropout_fraction=0.0, **kw)


@pytest.mark.parametrize("frames", [4, 16])
def test_averaging_frames_divides_the_independent_noise_by_their_square_root(frames):
    noise = _noise(scale=3.0)
    burst = sensor_burst(_flat(), noise, np.random.default_rng(1), frames)
    assert len(burst) == frames
    single = float(np.std(burst[0].depth_m - 0.7))
    averaged = float(np.std(temporal_average(burst).depth_m - 0.7))
    assert single == pytest.approx(float(depth_noise_rms(0.7, noise)), rel=0.05)
    assert averaged == pytest.approx(single / math.sqrt(frames), rel=0.08)


def test_the_static_share_of_the_noise_survives_averaging():
    """With half the variance fixed for the capture, averaging many frames leaves sqrt(1/2) of the RMS."""
    noise = _noise(scale=3.0, static_fraction=0.5)
    burst = sensor_burst(_flat(), noise, np.random.default_rng(2), 32)
    single = float(np.std(burst[0].depth_m - 0.7))
    averaged = float(np.std(temporal_average(burst).depth_m - 0.7))
    assert single == pytest.approx(float(depth_noise_rms(0.7, noise)), rel=0.05)
    assert averaged == pytest.approx(single * math.sqrt(0.5 + 0.5 / 32), rel=0.08)


def test_a_pixel_missing_in_most_frames_stays_a_hole_and_one_missing_once_is_filled():
    frames = []
    for k in range(4):
        d = np.full((120, 160), 0.7)
        d[10, 10] = 0.0 if k < 3 else 0.7  # valid once in four frames
        d[20, 20] = 0.0 if k == 0 else 0.7  # missing once
        frames.append(RGBDFrame(np.zeros((120, 160, 3), np.uint8), d, INTR))
    out = temporal_average(frames, min_valid_fraction=0.5).depth_m
    assert out[10, 10] == 0.0
    assert out[20, 20] == pytest.approx(0.7)


def test_the_noise_is_measured_from_the_frame_itself_also_on_a_tilted_surface():
    noise = _noise(scale=2.0)
    rows, cols = np.mgrid[0:120, 0:160]
    tilted = 0.6 + 0.002 * cols + 0.001 * rows  # a plane seen obliquely: 2 mm per pixel across the image
    frame = RGBDFrame(np.zeros((120, 160, 3), np.uint8), tilted, INTR)
    noisy = sensor_burst(frame, noise, np.random.default_rng(3), 1)[0]
    c_true = noise.subpixel * noise.scale / (noise.focal_px * noise.baseline_m)
    assert depth_noise_coefficient(noisy.depth_m) == pytest.approx(c_true, rel=0.1)
    assert depth_noise_coefficient(tilted) == pytest.approx(0.0, abs=1e-9)


def test_the_spatial_filter_removes_noise_on_surfaces_but_keeps_a_2cm_step_and_the_holes():
    noise = _noise(scale=3.0)
    clean = np.full((120, 160), 0.70)
    clean[:, 80:] = 0.68  # an object's top 2 cm above the table
    frame = RGBDFrame(np.zeros((120, 160, 3), np.uint8), clean, INTR)
    noisy = sensor_burst(frame, noise, np.random.default_rng(4), 1)[0].depth_m.copy()
    noisy[60, 40] = 0.0
    c = depth_noise_coefficient(noisy)
    out = spatial_filter(noisy, c, radius_px=3, range_sigmas=2.0)
    area = (slice(5, 55), slice(5, 70))  # flat, away from the hole and the step
    rms_in, rms_out = np.std((noisy - clean)[area]), np.std((out - clean)[area])
    assert rms_in == pytest.approx(float(depth_noise_rms(0.7, noise)), rel=0.1)
    assert rms_out < 0.5 * rms_in
    assert out[60, 40] == 0.0
    # next to the step, each side keeps its own level: a column's mean moves by less than half the noise (a
    # plain blur over the same window pulls both sides ~7 mm towards each other)
    assert abs(np.mean(out[:, 79]) - 0.70) < 0.4 * rms_in and abs(np.mean(out[:, 80]) - 0.68) < 0.4 * rms_in


def test_the_table_threshold_follows_the_measured_table_noise_only_upwards():
    rng = np.random.default_rng(5)
    heights = np.concatenate([rng.normal(0.0, 0.006, 20000), rng.uniform(0.02, 0.2, 3000)])  # table + objects
    sigma = table_noise(heights)
    assert sigma == pytest.approx(0.006, rel=0.05)
    rc = load_config("robocup").perception.robocup
    assert table_threshold_for(sigma, rc) == pytest.approx(3.0 * sigma)
    assert table_threshold_for(0.001, rc) == rc.table_threshold_m  # never below the configured one
    seed = load_config("robocup", overrides=["perception.preset=seed"]).perception.robocup
    assert table_threshold_for(sigma, seed) == seed.table_threshold_m


def test_the_seed_preset_is_one_raw_frame_with_fixed_thresholds_and_a_config_key_still_wins():
    s = load_config("robocup", overrides=["perception.preset=seed"])
    assert s.perception.depth_filter.temporal_frames == 1 and not s.perception.depth_filter.spatial
    assert s.perception.robocup.table_threshold_sigmas is None
    s = load_config("robocup", overrides=["perception.preset=seed", "perception.depth_filter.temporal_frames=4"])
    assert s.perception.depth_filter.temporal_frames == 4 and not s.perception.depth_filter.spatial
    robust = load_config("robocup").perception
    assert robust.depth_filter.temporal_frames > 1 and robust.depth_filter.spatial
    with pytest.raises(ConfigError, match="preset"):
        load_config("robocup", overrides=["perception.preset=fancy"])
