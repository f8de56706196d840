"""Problem sets: the file format, export from a scene config, and the round trip through `twin compare` and the
mplib driver (the same starts, goals and obstacles on both sides)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from twin.compare import compare_spec_from_dict, run_comparison
from twin.errors import ConfigError
from twin.problems import export_problem_set, json_schema, load_problem_set, save_problem_set
from twin.problems.world import planning_scene, settings_for
from twin.resources import packaged_path
from twin.transforms import pose_from_xyz_rpy

ROOT = Path(__file__).resolve().parents[1]
# the shipped smoke comparison's warehouse scenario: drawn again under its name, these are its queries
WAREHOUSE_BLOCKED = {"goal": "position", "straight": "blocked"}


@pytest.fixture(scope="module")
def exported(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    out = tmp_path_factory.mktemp("problems")
    sets = {
        "warehouse": export_problem_set(
            "warehouse", count=2, seed=3, name="warehouse-blocked", random=WAREHOUSE_BLOCKED, time_limit_s=2.0
        ),
        "robocup": export_problem_set("robocup", count=2, seed=3, name="robocup", random={"goal": "pose"}),
    }
    return {k: save_problem_set(ps, out / f"{k}.json") for k, ps in sets.items()}


def test_the_shipped_schema_is_the_models_and_validates_an_export(exported: dict[str, Path]) -> None:
    jsonschema = pytest.importorskip("jsonschema")
    path = packaged_path("schemas/problem-set.schema.json")
    assert path is not None, "the schema ships with the package"
    shipped = json.loads(path.read_text())
    assert shipped == json_schema(), (
        "regenerate it: twin problems schema --out twin/data/schemas/problem-set.schema.json"
    )
    for f in exported.values():
        jsonschema.validate(json.loads(f.read_text()), shipped)


def test_export_round_trips_and_its_world_is_the_planning_scene(exported: dict[str, Path]) -> None:
    from twin.config import find_config, load_config
    from twin.problems.cells import cell_for

    ps = load_problem_set(exported["warehouse"])
    assert ps == export_problem_set(
        "warehouse", count=2, seed=3, name="warehouse-blocked", random=WAREHOUSE_BLOCKED, time_limit_s=2.0
    ), "same arguments, same problems"
    assert [o.name for o in ps.world.objects] == ["table", "aruco_plate", "obstacle"]  # the obstacle as a known box
    assert ps.robot.joint_names[0] == "shoulder_pan_joint" and ("base_link" in ps.robot.static_links)
    assert all(p.goal.kind == "position" and p.time_limit_s == 2.0 for p in ps.problems)
    # the cell built from the file's primitives measures the same clearances as the config's own cell
    original = cell_for(str(find_config("warehouse").resolve()), (), "box").scene
    settings = settings_for(ps, load_config("warehouse"))
    rebuilt = planning_scene(ps, settings)
    qs = np.random.default_rng(0).uniform(-np.pi, np.pi, (500, 6))
    assert np.allclose(original.clearance_batch(qs), rebuilt.clearance_batch(qs), atol=1e-9)
    assert (original.in_collision_batch(qs) == rebuilt.in_collision_batch(qs)).all()


def _rows(
    tmp: Path, scenario: dict[str, Any], seeds: list[int] | None = None, planners: tuple[str, ...] = ("ruckig.movej",)
) -> list[dict[str, Any]]:
    spec: dict[str, Any] = {"name": "t", "planners": list(planners), "scenarios": [scenario], "execute": False}
    if seeds is not None:
        spec["seeds"] = seeds
    result = run_comparison(compare_spec_from_dict(spec, base_dir=tmp), out_dir=tmp / scenario["name"], workers=0)
    return result.rows


def _same_query(a: dict[str, Any], b: dict[str, Any]) -> None:
    assert np.allclose(a["start"], b["start"], atol=1e-12)
    if a["goal"] is not None:
        assert np.allclose(a["goal"], b["goal"], atol=1e-12)
        return
    Ta, Tb = (
        pose_from_xyz_rpy(a["goal_pose"][:3], a["goal_pose"][3:]),
        pose_from_xyz_rpy(b["goal_pose"][:3], b["goal_pose"][3:]),
    )
    assert np.allclose(Ta, Tb, atol=1e-12)
    assert (a["orientation_free"], a["position_tolerance_m"]) == (b["orientation_free"], b["position_tolerance_m"])


def test_compare_plans_the_exported_problems_the_random_scenario_drew(
    exported: dict[str, Path], tmp_path: Path
) -> None:
    """The same problems in the same world give the same plans (to float rounding: a pose goal goes through a
    quaternion in the file): a seeded sampling planner and nmpc (which sees the perceived obstacle as a box
    in both) on the random scenario and on its export."""
    planners = ("ompl.rrtconnect", "nmpc")
    random = {"name": "warehouse-blocked", "scene": "warehouse", "random": {"count": 2, **WAREHOUSE_BLOCKED}}
    drawn = _rows(tmp_path, {**random, "time_limit_s": 2.0}, [3], planners)
    from_file = _rows(tmp_path, {"name": "from-file", "problems": str(exported["warehouse"])}, None, planners)
    assert len(drawn) == len(from_file) == 4
    for a, b in zip(drawn, from_file, strict=True):
        assert a["planner"] == b["planner"]
        _same_query(a["query"], b["query"])
        assert b["seed"] == 3 and b["time_limit_s"] == 2.0  # each problem with its own seed and limit
        assert (a["status"], a["failure"]) == (b["status"], b["failure"])
        for key in ("duration_s", "joint_path_length_rad", "min_clearance_m"):
            assert a["metrics"][key] == pytest.approx(b["metrics"][key], rel=1e-9, abs=1e-12), key
    assert all(r["success"] for r in drawn if r["planner"] == "ompl.rrtconnect")


def test_the_mplib_driver_reads_the_same_problems_and_obstacles(exported: dict[str, Path], tmp_path: Path) -> None:
    """The driver runs in mplib's own venv and imports nothing from twin: its reading of the file (`--describe`,
    no mplib needed) must give twin's starts, goals and obstacles."""
    for name, path in exported.items():
        out = subprocess.run(
            [sys.executable, str(ROOT / "bench" / "mplib_driver.py"), "--problems", str(path), "--describe"],
            capture_output=True,
            text=True,
            check=True,
            timeout=60,
        )
        seen = json.loads(out.stdout)
        rows = _rows(tmp_path, {"name": f"file-{name}", "problems": str(path)})
        assert [q["start"] for q in seen["queries"]] == [r["query"]["start"] for r in rows]
        ps = load_problem_set(path)
        for q, p in zip(seen["queries"], ps.problems, strict=True):
            if p.goal.kind == "joint":
                assert q["goals"] == [p.goal.joints]
            else:
                assert np.allclose(q["goal_pose"], p.goal.pose.matrix(), atol=1e-12)
        prims = [(o.name, prim) for o in ps.world.objects for prim in o.primitives]
        assert len(seen["objects"]) == len(prims)
        for obj, (_, prim) in zip(seen["objects"], prims, strict=True):
            assert obj["shape"] == prim.shape and np.allclose(obj["pose"], prim.pose.matrix(), atol=1e-12)
            assert obj["size"] == list(prim.dims())


def _doc(path: Path) -> dict[str, Any]:
    return json.loads(path.read_text())


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.update(version=3), "version 3 is not supported; this twin reads versions 1, 2"),
        (lambda d: d["problems"][0].update(world={"objects": []}), "problems.0.world: a problem's own world needs"),
        (lambda d: d.update(format="other"), "not a problem set"),
        (lambda d: d["problems"][0].pop("start"), "problems.0.start"),
        (lambda d: d["problems"][1].update(start=[0.0] * 5), "has 5 values; the robot has 6 joints"),
        (
            lambda d: d["world"]["objects"][0]["primitives"][0]["pose"].update(orientation=[0, 0, 0, 2]),
            "unit quaternion",
        ),
        (lambda d: d["world"]["objects"][0]["primitives"][0].update(shape="cone"), "world.objects.0.primitives.0"),
        (lambda d: d["problems"][1].update(id=d["problems"][0]["id"]), "problem ids must be unique"),
        (lambda d: d.update(extra=1), "unknown key 'extra'"),
    ],
)
def test_a_bad_problem_file_is_one_line_naming_what_is_wrong(
    exported: dict[str, Path], tmp_path: Path, edit: Any, message: str
) -> None:
    d = _doc(exported["warehouse"])
    edit(d)
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps(d))
    with pytest.raises(ConfigError) as e:
        load_problem_set(bad)
    assert message in str(e.value) and "\n" not in str(e.value)


def test_a_compare_scenario_names_a_bad_or_foreign_problem_set_in_one_line(
    exported: dict[str, Path], tmp_path: Path
) -> None:
    d = _doc(exported["robocup"])
    d["robot"]["joint_names"] = ["joint_a1", "joint_a2", "joint_a3", "joint_a4", "joint_a5", "joint_a6"]
    foreign = tmp_path / "kuka.json"
    foreign.write_text(json.dumps(d))
    spec = compare_spec_from_dict(
        {"planners": ["ruckig.movej"], "scenarios": [{"name": "k", "problems": "kuka.json"}]}, base_dir=tmp_path
    )
    with pytest.raises(ConfigError, match=r"scenarios\.0 \(k\): .*joint_names .* are not the arm joints"):
        run_comparison(spec, out_dir=tmp_path / "o", workers=0)
    d["source"] = {}
    foreign.write_text(json.dumps(d))
    with pytest.raises(ConfigError, match=r"names no twin config .*give `scene:`"):
        compare_spec_from_dict(
            {"planners": ["ruckig.movej"], "scenarios": [{"name": "k", "problems": "kuka.json"}]}, base_dir=tmp_path
        )
    with pytest.raises(ConfigError, match=r"scenarios\.0\.problems: problem set .*missing.json does not exist"):
        compare_spec_from_dict(
            {"planners": ["ruckig.movej"], "scenarios": [{"name": "k", "problems": "missing.json"}]}, base_dir=tmp_path
        )
    with pytest.raises(ConfigError, match="exactly one of `queries`"):
        compare_spec_from_dict(
            {
                "planners": ["ruckig.movej"],
                "scenarios": [{"name": "k", "scene": "robocup", "problems": "x.json", "random": {"count": 1}}],
            },
            base_dir=tmp_path,
        )


def test_each_problem_runs_once_with_its_own_seed_unless_the_scenario_gives_seeds(
    exported: dict[str, Path], tmp_path: Path
) -> None:
    from twin.compare import plan_comparison

    d = _doc(exported["robocup"])
    d["problems"][1]["seed"] = 7
    (tmp_path / "two-seeds.json").write_text(json.dumps(d))
    spec = {"planners": ["ruckig.movej"], "scenarios": [{"name": "p", "problems": "two-seeds.json"}]}
    dry = plan_comparison(compare_spec_from_dict(spec, base_dir=tmp_path))
    assert dry.cases() == {"p": 2} and [r.seed for r in dry.runs] == [3, 7]
    spec["scenarios"][0]["seeds"] = [0, 1]  # every problem with each of these seeds instead
    dry = plan_comparison(compare_spec_from_dict(spec, base_dir=tmp_path))
    assert dry.cases() == {"p": 4} and [r.seed for r in dry.runs] == [0, 0, 1, 1]
