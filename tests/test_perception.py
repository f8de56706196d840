"""Perception against ground truth, with the numbers of issue 7 (default sensor noise on).

- ArUco: camera-to-base error <= 5 mm and <= 0.5 deg (fixed warehouse camera, wrist calibration view).
- Warehouse, 20 seeded scenes: every cube found, colour label 100 % right, centroid error <= 1 cm,
  obstacle box faces within 2 cm of the true box (before the +-0.5 m extension).
- RoboCup, 20 seeded scenes with all 8 classes, some lying: class accuracy >= 95 %, vertical/horizontal
  accuracy >= 95 % including lying cans, median centroid x-y error <= 1 cm.

Headless with PyBullet's TinyRenderer (a fresh EGL world costs ~1 s to build here, TinyRenderer ~0.05 s;
both renderers give the same accuracy within a millimetre, see bench/bench_perception.py).
"""

from __future__ import annotations

import numpy as np
import pytest

from twin.camera import camera_pose
from twin.config import load_config
from twin.perception.aruco import calibrate, transform_error
from twin.perception.capture import capture_frame
from twin.perception.evaluate import run_calibration, run_perception, true_obstacle_box
from twin.tasks.pipelines import TASK_PIPELINES
from twin.tasks.warehouse.perception import perceive_warehouse
from twin.world import World

pytest.importorskip("open3d")

SEEDS = range(20)
RENDERER = "tiny"
# the pipelines scored (perception sits below the tasks that own them, so the caller hands them in)
PIPELINES = TASK_PIPELINES


@pytest.fixture(scope="module")
def warehouse_settings():
    s = load_config("configs/warehouse.yaml")
    assert s.camera.noise.enabled
    return s


@pytest.fixture(scope="module")
def robocup_settings():
    s = load_config("configs/robocup.yaml")
    assert s.camera.noise.enabled and s.world.objects.lying_probability > 0
    return s


@pytest.fixture(scope="module")
def warehouse_runs(warehouse_settings):
    """Per seed: (seed, true cubes, WarehouseResult, calibration error) through the library API."""
    out = []
    for seed in SEEDS:
        with World(warehouse_settings, seed, renderer=RENDERER) as world:
            cap = capture_frame(world, warehouse_settings)
            cal = calibrate(cap.frame, warehouse_settings)
            res = perceive_warehouse(cap.frame, cal.T_base_camera, warehouse_settings.perception.warehouse, seed=seed)
            truth = [o for o in world.objects() if o.cls == "warehouse_cube"]
        out.append((seed, truth, res, transform_error(cal.T_base_camera, camera_pose(warehouse_settings.camera))))
    return out


@pytest.fixture(scope="module")
def robocup_reports(robocup_settings):
    return [run_perception(robocup_settings, pipelines=PIPELINES, seed=seed, renderer=RENDERER) for seed in SEEDS]


# ---- ArUco -------------------------------------------------------------------------------------
def test_aruco_fixed_camera_to_base_within_5mm_and_half_a_degree(warehouse_settings):
    for seed in (0,):
        rep = run_calibration(warehouse_settings, seed=seed, renderer=RENDERER)
        assert rep.method == "pnp+plane"
        assert rep.translation_error_m <= 0.005, (seed, rep.translation_error_m)
        assert rep.rotation_error_deg <= 0.5, (seed, rep.rotation_error_deg)


def test_aruco_wrist_calibration_view_within_5mm_and_half_a_degree(robocup_settings):
    rep = run_calibration(robocup_settings, seed=3, renderer=RENDERER)
    assert rep.translation_error_m <= 0.005 and rep.rotation_error_deg <= 0.5
    assert rep.n_points > 4  # the interior grid corners were used at this range


def test_aruco_error_over_the_warehouse_scenes(warehouse_runs):
    """The calibration inside every warehouse run (the frame the cubes come from) meets the bar too."""
    for seed, _, _, (dt, dr) in warehouse_runs:
        assert dt <= 0.005 and dr <= 0.5, (seed, dt, dr)


# ---- warehouse ---------------------------------------------------------------------------------
def test_warehouse_every_cube_found_with_the_right_colour_within_1cm(warehouse_runs):
    worst = 0.0
    for seed, truth, res, _ in warehouse_runs:
        assert len(res.cubes) == len(truth) == 4, (seed, [c.color_label for c in res.cubes])
        labels = sorted(c.color_label for c in res.cubes)
        assert labels == sorted(o.color for o in truth), (seed, labels)
        for o in truth:
            cube = next(c for c in res.cubes if c.color_label == o.color)
            err = float(np.linalg.norm(cube.centroid - o.position))  # 3D centroid error
            worst = max(worst, err)
            assert err <= 0.01, (seed, o.color, err)
    assert worst > 0.0  # noise is on: never exact


def test_warehouse_obstacle_box_faces_within_2cm_and_extended_in_y(warehouse_runs, warehouse_settings):
    true_box = true_obstacle_box(warehouse_settings)
    assert true_box is not None
    for seed, _, res, _ in warehouse_runs:
        box = res.obstacle
        assert box is not None, seed
        assert res.obstacle_points >= warehouse_settings.perception.warehouse.obstacle_min_points
        faces = np.r_[box.lo - true_box.lo, box.hi - true_box.hi]
        assert np.all(np.abs(faces) <= 0.02), (seed, faces)
        ext = res.obstacle_extended
        assert ext.y_min == pytest.approx(box.y_min - 0.5) and ext.y_max == pytest.approx(box.y_max + 0.5)
        assert (ext.x_min, ext.x_max, ext.z_min, ext.z_max) == (box.x_min, box.x_max, box.z_min, box.z_max)


# ---- RoboCup -----------------------------------------------------------------------------------
def test_robocup_scenes_hold_all_8_classes_some_lying(robocup_reports):
    classes = {o["class_true"] for r in robocup_reports for o in r.objects}
    assert classes == {"bottle", "can", "spam", "marker", "cube_red", "cube_blue", "cube_green", "cube_yellow"}
    lying = [o for r in robocup_reports for o in r.objects if o["orientation_true"] == "horizontal"]
    assert len(lying) >= 10
    assert any(o["class_true"] == "can" for o in lying)


def test_robocup_class_accuracy_at_least_95_percent(robocup_reports):
    rows = [o for r in robocup_reports for o in r.objects]
    acc = np.mean([o["class_est"] == o["class_true"] for o in rows])
    assert acc >= 0.95, acc
    assert sum(r.false_positives for r in robocup_reports) <= 2


def test_robocup_orientation_accuracy_at_least_95_percent_including_lying_cans(robocup_reports):
    rows = [o for r in robocup_reports for o in r.objects]
    acc = np.mean([o["orientation_est"] == o["orientation_true"] for o in rows])
    assert acc >= 0.95, acc
    cans = [o for o in rows if o["class_true"] == "can" and o["orientation_true"] == "horizontal"]
    assert cans and all(o["orientation_est"] == "horizontal" for o in cans)


def test_robocup_median_centroid_xy_error_within_1cm(robocup_reports):
    errs = [o["position_error_m"] for r in robocup_reports for o in r.objects if o["position_error_m"] is not None]
    assert len(errs) >= 0.95 * sum(len(r.objects) for r in robocup_reports)
    assert float(np.median(errs)) <= 0.01, float(np.median(errs))


def test_robocup_report_fields_and_score(robocup_reports):
    rep = robocup_reports[0].to_dict()
    keys = {
        "class_true",
        "class_est",
        "orientation_true",
        "orientation_est",
        "color_true",
        "color_est",
        "position_error_m",
        "yaw_error_deg",
        "score",
    }
    assert all(keys <= set(o) for o in rep["objects"])
    assert set(rep["calibration"]) >= {"translation_error_m", "rotation_error_deg"}
    assert isinstance(rep["false_positives"], int)
    for o in rep["objects"]:
        assert 0.0 <= o["score"] <= 100.0
    for e in rep["estimates"]:
        g = e["grasp"]
        assert len(g) == 7 and g[4] == pytest.approx(np.pi) and g[5] == 0.0 and -np.pi / 2 <= g[3] < np.pi / 2


def test_lying_cans_are_horizontal_when_everything_lies(robocup_settings):
    """The seed's known failure: lying cans (e ~ 2.1). Every object lies here."""
    s = load_config("configs/robocup.yaml", ["world.objects.lying_probability=1.0"])
    for seed in (0, 1):
        rep = run_perception(s, pipelines=PIPELINES, seed=seed, renderer=RENDERER)
        for o in rep.objects:
            if o["class_true"] in ("can", "bottle", "marker", "spam"):
                assert o["orientation_true"] == "horizontal"
                assert o["orientation_est"] == "horizontal", (seed, o)
