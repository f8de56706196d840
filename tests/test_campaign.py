"""The robustness campaign's parts (issue 39): named fault sets, the loss taxonomy, the tables, and one real
campaign run through compare's runner."""

from __future__ import annotations

import pytest

from twin.campaign import LOSS_CLASSES, campaign_spec, classify_loss, render, summarize
from twin.config import load_config
from twin.errors import UnknownNameError
from twin.faults import FAULT_PRESETS, fault_overrides


def test_unknown_fault_set_names_the_known_ones():
    with pytest.raises(UnknownNameError, match=r"'strss'.*Did you mean 'stress'.*nominal, stress"):
        fault_overrides("strss")


@pytest.mark.parametrize("config", ["robocup", "warehouse"])
def test_every_fault_set_loads_on_both_tasks_and_stress_turns_each_fault_on(config):
    nominal = load_config(config)
    for name in FAULT_PRESETS:
        load_config(config, fault_overrides(name))
    s = load_config(config, fault_overrides("stress"))
    assert s.camera.noise.scale == 3 * nominal.camera.noise.scale
    assert s.camera.extrinsic_error.translation_m == pytest.approx(0.01)
    assert s.world.objects.mass_scale == (1.0, 1.5) and s.world.objects.friction_scale == (0.7, 1.0)
    assert s.robot.tracking_time_constant_s == pytest.approx(0.05)
    assert s.world.unmodelled_obstacle is not None and nominal.world.unmodelled_obstacle is None


def _obj(error, *, stage=None, failure=None, placed=False, oid="x_0"):
    return {"id": oid, "placed": placed, "error": error, "stage": stage, "failure": failure}


# failure texts as runs wrote them (issue 39's runs and twin.tasks' messages)
CASES = [
    (_obj("perception: never seen on the table"), "perception"),
    (
        _obj(
            "grasp: the fingers stopped at 82.7 mm, but the object should be 66 mm across (-15/+12 mm) (can_0)",
            stage="grasp",
        ),
        "grasp_width",
    ),
    (
        _obj("grasp: nothing between the fingers after closing (they closed to 0.1 mm) (marker_0, vertical)"),
        "grasp_width",
    ),
    (
        _obj(
            "ascent: the object slipped out of the gripper: the fingers closed from 79.0 mm at the grasp to -0.1 mm",
            stage="ascent",
            failure="grasp_lost",
        ),
        "slip",
    ),
    (
        _obj(
            "transfer: the object was dropped while carrying it: the fingers closed from 50.1 mm to 0.0 mm",
            stage="transfer",
            failure="grasp_lost",
        ),
        "slip",
    ),
    (
        _obj(
            "descent: toppra.movel: collision: the trajectory collides (upper_arm_link with obstacle); then: "
            "perception: not seen again on the table",
            stage="descent",
            failure="collision",
        ),
        "fixed_stage",
    ),
    (
        _obj(
            "transfer: croc: collision: the next segment would collide (forearm_link with gripper_base)",
            stage="transfer",
            failure="collision",
        ),
        "planner",
    ),
    (
        _obj("place: the object is stuck between the opened fingers: seen between them", stage="place"),
        "jam",
    ),
    (_obj("place: released, but it lies outside the bin", stage="place"), "other"),
    (_obj("calibration: the ArUco marker was not found: ArUco marker 0 not found in the image"), "calibration"),
    (
        _obj(
            "perception: never seen on the table (the run stopped: cannot reach the capture pose: capture: "
            "ruckig.movej: execution_stopped: unexpected contact: gripper_base with spam_0)",
            stage="perception",
        ),
        "fixed_stage",
    ),
    (
        _obj("perception: never seen on the table (the run stopped: run time limit reached)", stage="perception"),
        "other",
    ),
]


@pytest.mark.parametrize(("obj", "cls"), CASES, ids=[c for _, c in CASES])
def test_each_loss_lands_in_its_class(obj, cls):
    assert classify_loss(obj, {"objects": [obj]}) == cls
    assert cls in LOSS_CLASSES


def test_a_run_whose_calibration_fell_back_loses_to_calibration():
    obj = CASES[1][0]
    assert classify_loss(obj, {"calibration": {"status": "fallback"}}) == "calibration"
    assert classify_loss(obj, {"calibration": {"status": "measured"}}) == "grasp_width"


def _row(seed, placed, lost=(), planner="p", run=True):
    objs = [_obj(None, placed=True, oid=f"ok_{i}") for i in range(placed)] + list(lost)
    return {
        "planner": planner,
        "scenario": "robocup-stress",
        "seed": seed,
        "reason": "" if run else "worker died",
        "timing": {"wall_time_s": 10.0 + seed},
        "task": {"objects": objs} if run else None,
    }


def test_summary_counts_losses_worst_seeds_and_seeds_below_a_floor():
    slip, never = CASES[3][0], CASES[0][0]
    rows = [
        _row(1, 8),
        _row(2, 7, [slip]),
        _row(3, 1, [never] * 7),
        _row(4, 0, run=False),
    ]
    (s,) = summarize(rows)
    assert (s.runs, s.errors, s.objects, s.placed) == (4, 1, 24, 16)
    assert s.losses == {"slip": 1, "perception": 7}
    assert s.seeds_below(6) == 1  # seed 3; the errored run has no outcomes to count
    assert [w[2] for w in s.worst] == [4, 3, 2]  # the error first, then the fewest placed
    text = render([s], least=6)
    assert "objects placed 16/24 (66.7 %)" in text and "seeds below 6/8: 1" in text
    assert "slip" in text and "3: x_0: perception: never seen" in text


def test_campaign_spec_runs_the_configs_transfer_planner_under_the_fault_set():
    spec = campaign_spec("warehouse", faults="stress", seeds=[5, 6])
    assert [p.name for p in spec.planners] == ["nmpc"]
    (scenario,) = spec.scenarios
    assert list(scenario.overrides) == list(FAULT_PRESETS["stress"]) and spec.seeds == [5, 6]
    spec = campaign_spec("warehouse", faults="nominal", seeds=[5], planners=[{"name": "ompl.rrtconnect"}])
    assert [p.name for p in spec.planners] == ["ompl.rrtconnect"] and spec.scenarios[0].overrides == []


def test_a_small_campaign_runs_and_is_summarised(tmp_path):
    """One warehouse seed under the stress set (its unmodelled box finds room beside the cubes), in this
    process: the row carries the run's outcomes, and the summary counts them."""
    from twin.compare.runner import read_results, run_comparison

    spec = campaign_spec("warehouse", faults="stress", seeds=[3], planners=[{"name": "ompl.rrtconnect"}])
    run_comparison(spec, out_dir=tmp_path, workers=0, plots=False)
    rows = read_results(tmp_path / "results.jsonl")
    (s,) = summarize(rows)
    assert s.runs == 1 and s.errors == 0 and s.objects == 4
    assert sum(s.losses.values()) == s.objects - s.placed


def test_cli_takes_a_fault_set_by_name(capsys):
    from twin.cli import _settings, build_parser, main

    assert main(["scene", "warehouse", "--faults", "strss", "--snapshot", "x.png"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'strss'" in err and "stress" in err
    args = build_parser().parse_args(["run", "robocup", "--faults", "stress", "--set", "camera.noise.scale=5"])
    settings = _settings(args)
    assert settings.camera.noise.scale == 5  # a --set after the fault set wins
    assert settings.robot.tracking_time_constant_s == pytest.approx(0.05)
