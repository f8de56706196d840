"""`sweep:` in a comparison scenario: any config key as an axis, one factor at a time (the nominal point
runs once and belongs to every axis), with stable run ids, checked on load, carried by the rows, and
reported per level (success with a Wilson interval, median time) in tables and `sweep_<key>.png`."""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

import pytest
import yaml
from cli_runner import twin

from twin.compare import compare_spec_from_dict, expand_runs, run_comparison
from twin.compare.report import summarize, sweep_tables, write_summary
from twin.compare.stats import wilson_ci
from twin.config import load_config
from twin.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent
NOISE, SHIFT = "camera.noise.scale", "camera.extrinsic_error.translation_m"
ONE_QUERY = {"start": [0, -1.6, 1.5, -1.5, -1.57, 0], "goal": [0.8, -1.2, 1.0, -1.4, -1.57, 0.6]}


def task_spec(sweep: dict[str, list[Any]] | None = None, **scenario: Any) -> dict[str, Any]:
    """Two planners, the RoboCup task with a noise and an extrinsic axis (4 levels each), two seeds."""
    sc = {"name": "rc", "task": str(ROOT / "configs/robocup.yaml"), "overrides": ["camera.settle_s=1.0"]}
    sc["sweep"] = sweep if sweep is not None else {NOISE: [1, 2, 3, 4], SHIFT: [0, 0.005, 0.01, 0.02]}
    sc.update(scenario)
    return {"planners": ["ruckig.movej", "seed.quintic_movej"], "seeds": [0, 1], "scenarios": [sc]}


# ---- expansion -------------------------------------------------------------------------------------------
def test_axes_are_swept_one_at_a_time_and_the_nominal_point_runs_once():
    runs = expand_runs(compare_spec_from_dict(task_spec()))
    # 1 nominal + 3 noise + 3 extrinsic levels = 7 (the grid would be 16), x 2 seeds x 2 planners
    assert len(runs) == 7 * 2 * 2
    cases = list(dict.fromkeys(r.case for r in runs))
    assert cases == [
        "rc@nominal",
        f"rc@{NOISE}=2",
        f"rc@{NOISE}=3",
        f"rc@{NOISE}=4",
        f"rc@{SHIFT}=0.005",
        f"rc@{SHIFT}=0.01",
        f"rc@{SHIFT}=0.02",
    ]
    nominal = [r for r in runs if r.case == "rc@nominal"]
    assert sorted((r.planner_id, r.seed) for r in nominal) == sorted(
        (p, s) for p in ("ruckig.movej", "seed.quintic_movej") for s in (0, 1)
    )  # once per planner and seed, not once per axis
    assert nominal[0].sweep == {NOISE: 1, SHIFT: 0} and set(nominal[0].sweep_axes) == {NOISE, SHIFT}
    # every level sets every swept key (the other one at its first value), after the scenario's overrides
    by_case = {r.case: r for r in runs if r.planner_id == "ruckig.movej" and r.seed == 0}
    assert by_case[f"rc@{NOISE}=3"].overrides == ("camera.settle_s=1.0", f"{NOISE}=3", f"{SHIFT}=0")
    assert by_case[f"rc@{SHIFT}=0.01"].overrides == ("camera.settle_s=1.0", f"{NOISE}=1", f"{SHIFT}=0.01")
    assert by_case[f"rc@{SHIFT}=0.01"].sweep == {NOISE: 1, SHIFT: 0.01}
    assert by_case[f"rc@{SHIFT}=0.01"].sweep_axes == (SHIFT,)
    # ... and the overrides load into exactly that config
    s = load_config(ROOT / "configs/robocup.yaml", by_case[f"rc@{NOISE}=3"].overrides)
    assert s.camera.noise.scale == 3 and s.camera.extrinsic_error.translation_m == 0 and s.camera.settle_s == 1.0


def test_the_first_value_is_nominal_even_when_it_is_not_the_default():
    runs = expand_runs(compare_spec_from_dict(task_spec({SHIFT: [0.01, 0], NOISE: [2, 1]})))
    by_case = {r.case: r for r in runs if r.planner_id == "ruckig.movej" and r.seed == 0}
    assert list(by_case) == ["rc@nominal", f"rc@{SHIFT}=0", f"rc@{NOISE}=1"]
    assert by_case[f"rc@{NOISE}=1"].sweep == {SHIFT: 0.01, NOISE: 1}  # the shift stays at its nominal 1 cm


def test_run_ids_are_stable_and_change_with_the_level():
    ids = {r.key: r.run_id for r in expand_runs(compare_spec_from_dict(task_spec()))}
    assert ids == {r.key: r.run_id for r in expand_runs(compare_spec_from_dict(task_spec()))}
    assert len(set(ids.values())) == len(ids) == 28
    # a changed level is a different run; the other levels keep their ids
    moved = {
        r.key: r.run_id
        for r in expand_runs(compare_spec_from_dict(task_spec({NOISE: [1, 2, 5, 4], SHIFT: [0, 0.005, 0.01, 0.02]})))
    }
    gone = set(ids) - set(moved)
    assert gone and all(f"{NOISE}=3" in k for k in gone)
    assert all(moved[k] == ids[k] for k in set(ids) & set(moved))
    # an added level leaves the others their ids
    more = {
        r.key: r.run_id
        for r in expand_runs(compare_spec_from_dict(task_spec({NOISE: [1, 2, 3, 4, 6], SHIFT: [0, 0.005, 0.01, 0.02]})))
    }
    assert len(more) == len(ids) + 4 and all(more[k] == ids[k] for k in ids)
    # a changed nominal value changes the runs that set it (the nominal point and the other axis) and
    # leaves its own axis's other levels alone (their point is the same)
    nominal = {
        r.key: r.run_id
        for r in expand_runs(
            compare_spec_from_dict(task_spec({NOISE: [1, 2, 3, 4], SHIFT: [0.001, 0.005, 0.01, 0.02]}))
        )
    }
    assert set(nominal) == set(ids)
    changed = {k for k in ids if nominal[k] != ids[k]}
    assert changed == {k for k in ids if "@nominal" in k or f"@{NOISE}=" in k}
    # a scenario without a sweep keeps the ids it had before sweeps existed
    plain = task_spec()
    del plain["scenarios"][0]["sweep"]
    plain_ids = [r.run_id for r in expand_runs(compare_spec_from_dict(plain))]
    assert all("@" not in rid for rid in plain_ids)
    assert [r.run_id for r in expand_runs(compare_spec_from_dict(task_spec({})))] == plain_ids


def test_grid_mode_runs_every_combination():
    runs = expand_runs(compare_spec_from_dict(task_spec({NOISE: [1, 3], SHIFT: [0, 0.005, 0.01]}, sweep_mode="grid")))
    levels = {r.case: (r.sweep, r.sweep_axes) for r in runs}
    assert len(levels) == 6 and len(runs) == 6 * 2 * 2
    assert levels["rc@nominal"][1] == (NOISE, SHIFT)
    assert levels[f"rc@{NOISE}=3"] == ({NOISE: 3, SHIFT: 0}, (NOISE,))
    assert levels[f"rc@{NOISE}=3;{SHIFT}=0.01"] == ({NOISE: 3, SHIFT: 0.01}, ())  # on neither axis


def test_a_query_scenario_sweep_names_its_queries_per_level():
    spec = {
        "planners": ["ruckig.movej"],
        "scenarios": [
            {
                "name": "q",
                "scene": str(ROOT / "configs/robocup.yaml"),
                "queries": [ONE_QUERY, dict(ONE_QUERY, goal=[0.2, -1.4, 1.2, -1.4, -1.57, 0.2])],
                "sweep": {"robot.max_joint_vel": [3.0, 1.0]},
            }
        ],
    }
    runs = expand_runs(compare_spec_from_dict(spec))
    assert [r.case for r in runs] == [
        "q@nominal#0",
        "q@robot.max_joint_vel=1.0#0",
        "q@nominal#1",
        "q@robot.max_joint_vel=1.0#1",
    ]
    assert [r.query_index for r in runs] == [0, 0, 1, 1]


# ---- validation ----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("sweep", "needles"),
    [
        (
            {"camera.noise.scal": [1, 2]},
            ["scenarios.0 (rc)", "sweep key 'camera.noise.scal'", "Did you mean 'camera.noise.scale'?"],
        ),
        ({NOISE: [1, -1]}, ["scenarios.0 (rc)", f"sweep '{NOISE}' value -1", "greater than or equal to 0"]),
        ({SHIFT: [0, 0.5]}, ["scenarios.0 (rc)", f"sweep '{SHIFT}' value 0.5", "less than or equal to 0.2"]),
        ({"camera.noise": [1, 2]}, ["scenarios.0 (rc)", "sweep 'camera.noise' value 1", "valid dictionary"]),
        ({NOISE: []}, ["scenarios.0", "scenario 'rc'", f"sweep '{NOISE}'", "empty"]),
        ({NOISE: [1, 2, 2]}, ["scenario 'rc'", f"sweep '{NOISE}'", "value 2 is listed twice"]),
        ({"camera noise": [1]}, ["scenario 'rc'", "dotted config key"]),
    ],
    ids=["unknown-key", "negative-noise", "too-far", "a-section", "empty", "duplicate", "not-a-key"],
)
def test_a_bad_sweep_is_a_config_error_naming_the_scenario_and_key(sweep: dict[str, Any], needles: list[str]):
    with pytest.raises(ConfigError) as err:
        compare_spec_from_dict(task_spec(sweep), source="robust.yaml")
    msg = str(err.value)
    assert "\n" not in msg and msg.startswith("robust.yaml: ")
    for n in needles:
        assert n in msg, msg


def test_the_cli_reports_a_bad_sweep_in_one_line_with_exit_2(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump(task_spec({NOISE: [1, -2]})))
    r = twin("compare", str(path), "--dry-run")
    assert r.returncode == 2, (r.stdout, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and f"sweep '{NOISE}' value -2" in lines[0] and "Traceback" not in r.stderr


def test_the_robustness_config_sweeps_both_tasks_along_both_fault_axes():
    from twin.compare import load_compare_config

    spec = load_compare_config(ROOT / "configs/compare-robustness.yaml")
    assert {s.name: s.kind for s in spec.scenarios} == {"warehouse-task": "task", "robocup-task": "task"}
    for s in spec.scenarios:
        assert s.sweep == {NOISE: [1, 2, 3, 4], SHIFT: [0, 0.005, 0.01, 0.02]} and s.sweep_mode == "one_at_a_time"
        assert spec.seeds_for(s) == [0, 1, 2]
    runs = expand_runs(spec)
    n = len(spec.planners) * 2 * 7 * 3
    assert len(runs) == n and f"{n} task runs" in (ROOT / "configs/compare-robustness.yaml").read_text()
    assert {"ruckig.movej", "ompl.rrtconnect", "nmpc"} <= {p.id for p in spec.planners}


# ---- rows ------------------------------------------------------------------------------------------------
def test_rows_carry_the_level_and_the_level_reaches_the_run(tmp_path):
    """A motion query at three joint-velocity limits: each row says its level, and the limit took effect
    (the same motion gets slower as the limit falls)."""
    spec = {
        "name": "vel-sweep",
        "execute": False,
        "planners": ["ruckig.movej"],
        "scenarios": [
            {
                "name": "q",
                "scene": str(ROOT / "configs/robocup.yaml"),
                "queries": [ONE_QUERY],
                "sweep": {"robot.max_joint_vel": [3.0, 1.0, 0.5]},
            }
        ],
    }
    result = run_comparison(compare_spec_from_dict(spec), out_dir=tmp_path / "out", workers=0)
    rows = result.rows
    assert [r["sweep"] for r in rows] == [{"robot.max_joint_vel": v} for v in (3.0, 1.0, 0.5)]
    assert all(r["sweep_axes"] == ["robot.max_joint_vel"] and r["success"] for r in rows)
    durations = [r["metrics"]["duration_s"] for r in rows]
    assert durations[0] < durations[1] < durations[2], durations
    on_disk = [json.loads(line) for line in (tmp_path / "out/results.jsonl").read_text().splitlines()]
    assert [r["sweep"] for r in on_disk] == [r["sweep"] for r in rows]
    # the summary and the plot are written beside the rest
    assert (tmp_path / "out/sweep.csv") in result.files
    pytest.importorskip("matplotlib")
    assert (tmp_path / "out/sweep_robot.max_joint_vel.png") in result.files


def test_rows_of_a_scenario_without_a_sweep_say_so(tmp_path):
    spec = {
        "execute": False,
        "planners": ["ruckig.movej"],
        "scenarios": [{"name": "q", "scene": str(ROOT / "configs/robocup.yaml"), "queries": [ONE_QUERY]}],
    }
    result = run_comparison(compare_spec_from_dict(spec), out_dir=tmp_path / "out", workers=0, plots=False)
    [row] = result.rows
    assert row["sweep"] is None and row["sweep_axes"] is None and row["case"] == "q#0"
    assert result.summary.sweeps == [] and not (tmp_path / "out/sweep.csv").exists()


# ---- report and plots (synthetic rows) ----------------------------------------------------------------
def sweep_rows() -> list[dict[str, Any]]:
    """Task rows of two planners along the noise and the extrinsic axes, 4 seeds: 'robust' places all
    objects everywhere, 'fragile' loses one seed per noise step and one per 5 mm."""
    levels = [({NOISE: 1, SHIFT: 0}, [NOISE, SHIFT], 0)]
    levels += [({NOISE: n, SHIFT: 0}, [NOISE], n - 1) for n in (2, 3, 4)]
    levels += [({NOISE: 1, SHIFT: t}, [SHIFT], round(t / 0.005)) for t in (0.005, 0.01, 0.02)]
    rows = []
    for planner in ("robust", "fragile"):
        for point, axes, lost in levels:
            for seed in range(4):
                ok = planner == "robust" or seed >= min(lost, 4)
                rows.append(
                    {
                        "run_id": f"{planner}|{point}|{seed}",
                        "planner": planner,
                        "scenario": "rc",
                        "case": f"rc@{point}",
                        "kind": "task",
                        "seed": seed,
                        "status": "success" if ok else "incomplete",
                        "success": ok,
                        "sweep": dict(point),
                        "sweep_axes": list(axes),
                        "metrics": {
                            "task_success_rate": 1.0 if ok else 0.5,
                            "cycle_time_s": 7.0 + point[NOISE] + 0.1 * seed,
                        },
                        "timing": {"wall_time_s": 1.0},
                    }
                )
    return rows


def test_the_summary_gives_success_with_a_wilson_interval_per_planner_and_level(tmp_path):
    summary = summarize(sweep_rows(), planners=["robust", "fragile"])
    assert summary.sweep_axes() == [("rc", NOISE), ("rc", SHIFT)]
    noise = [p for p in summary.sweeps if p.key == NOISE and p.planner == "fragile"]
    assert [p.value for p in noise] == [1, 2, 3, 4]
    assert [(p.successes, p.runs) for p in noise] == [(4, 4), (3, 4), (2, 4), (1, 4)]
    assert [p.success_ci for p in noise] == [wilson_ci(k, 4) for k in (4, 3, 2, 1)]
    assert noise[0].success_ci is not None and noise[0].success_ci[0] < 1.0  # 4/4 is not certainty
    assert [p.time.median for p in noise] == pytest.approx([8.15, 9.15, 10.15, 11.15])
    assert noise[-1].placed == pytest.approx((1 + 3 * 0.5) / 4) and noise[-1].time_key == "cycle_time_s"
    # the nominal runs count on both axes
    shift = [p for p in summary.sweeps if p.key == SHIFT and p.planner == "fragile"]
    assert [p.value for p in shift] == [0, 0.005, 0.01, 0.02] and shift[0].runs == noise[0].runs == 4
    assert [p.successes for p in shift] == [4, 3, 2, 0]

    paths = write_summary(summary, tmp_path)
    assert tmp_path / "sweep.csv" in paths
    with open(tmp_path / "sweep.csv", newline="") as f:
        table = list(csv.DictReader(f))
    assert len(table) == 2 * (4 + 4)
    line = next(r for r in table if (r["planner"], r["key"], r["value"]) == ("fragile", NOISE, "3"))
    assert (line["runs"], line["successes"], line["time_metric"]) == ("4", "2", "cycle_time_s")
    assert float(line["success_ci_low"]) == pytest.approx(wilson_ci(2, 4)[0], abs=1e-5)  # type: ignore[index]
    md = (tmp_path / "summary.md").read_text()
    assert f"### rc: {NOISE}" in md and f"### rc: {SHIFT}" in md
    lo, hi = wilson_ci(2, 4)  # type: ignore[misc]
    assert f"50% (2/4) [{100 * lo:.0f}, {100 * hi:.0f}]; placed 75%; 10.15 s" in md

    from rich.console import Console

    console = Console(width=250, record=True)
    for t in sweep_tables(summary):
        console.print(t)
    text = console.export_text()
    assert f"by {NOISE}" in text and f"by {SHIFT}" in text and "25% (1/4)" in text


def test_the_plots_draw_success_and_time_against_each_swept_key(tmp_path):
    pytest.importorskip("matplotlib", reason="plots need matplotlib (the `twin[plots]` extra)")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    from twin.compare.plots import sweep_figures, write_plots

    rows = sweep_rows()
    summary = summarize(rows, planners=["robust", "fragile"])
    figs = sweep_figures(summary)
    try:
        assert set(figs) == {f"sweep_{NOISE}", f"sweep_{SHIFT}"}
        top, bottom = figs[f"sweep_{NOISE}"].axes[:2]
        lines = {ln.get_label(): ln for ln in top.get_lines()}
        assert set(lines) == {"robust", "fragile"}
        assert list(lines["fragile"].get_ydata()) == pytest.approx([100, 75, 50, 25])
        # each line carries its Wilson band
        bands = [c for c in top.collections if isinstance(c, PolyCollection)]
        assert len(bands) == 2
        ys = bands[1].get_paths()[0].vertices[:, 1]
        assert min(ys) == pytest.approx(100 * wilson_ci(1, 4)[0])  # type: ignore[index]
        assert max(ys) == pytest.approx(100.0)
        assert [ln.get_label() for ln in bottom.get_lines()] == ["robust", "fragile"]
        assert bottom.get_ylim()[0] == 0.0  # a time axis from zero: a 0.1 s spread does not fill the plot
    finally:
        for fig in figs.values():
            plt.close(fig)

    paths = write_plots(rows, tmp_path, planners=["robust", "fragile"])
    names = [p.name for p in paths]
    assert names[-2:] == [f"sweep_{NOISE}.png", f"sweep_{SHIFT}.png"]
    assert all(p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" for p in paths)
    # rows without a sweep: no sweep plot
    (tmp_path / "plain").mkdir()
    plain = [dict(r, sweep=None, sweep_axes=None) for r in rows]
    assert not [p for p in write_plots(plain, tmp_path / "plain") if p.name.startswith("sweep_")]


def test_wilson_interval_matches_the_textbook_values():
    assert wilson_ci(0, 0) is None
    lo, hi = wilson_ci(10, 20)  # type: ignore[misc]
    assert (lo, hi) == pytest.approx((0.2993, 0.7007), abs=1e-4)
    assert wilson_ci(3, 3) == pytest.approx((0.4385, 1.0), abs=1e-4)
    assert wilson_ci(0, 3) == pytest.approx((0.0, 0.5615), abs=1e-4)
    with pytest.raises(ValueError, match="successes must be in"):
        wilson_ci(4, 3)
