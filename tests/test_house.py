"""The house keeps its shape (issue 40): data flows one way, rooms stay livable, one robot per run.

`bench/bench_house.py` measures; these tests keep what it measured from drifting back."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

import pytest

from twin.config import load_config

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def house() -> ModuleType:
    spec = importlib.util.spec_from_file_location("bench_house", ROOT / "bench" / "bench_house.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_no_import_cycle_no_room_too_big_and_the_mpcs_are_siblings(house: ModuleType) -> None:
    report = house.static_report()
    assert report["cycles"] == []  # imports inside functions counted, TYPE_CHECKING aside
    assert report["classes_over_limit"] == [] and report["functions_over_limit"] == []
    assert report["twin_croc_import_statements_of_twin_nmpc"] == 0


def test_the_cycle_finder_finds_a_cycle(house: ModuleType) -> None:
    """The check above is not vacuous: a two-module and a three-module circle are found, a chain is not."""
    found = house._cycles({"a": {"b"}, "b": {"a", "c"}, "c": set(), "x": {"y"}, "y": {"z"}, "z": {"x"}})
    assert sorted(sorted(c) for c in found) == [["a", "b"], ["x", "y", "z"]]
    assert house._cycles({"a": {"b"}, "b": {"c"}, "c": set()}) == []


def test_a_run_builds_one_robot_one_arm_one_context_and_reads_the_robot_urdf_once(house: ModuleType) -> None:
    s = load_config("robocup")
    no_objects = s.world.objects.model_copy(update={"items": []})  # the whole set-up, no sorting
    s = s.model_copy(update={"world": s.world.model_copy(update={"objects": no_objects})})
    counts = house.counted_run(s, seed=1)
    assert counts["robots_built"] == 1 and counts["arms_built"] == 1 and counts["plugin_contexts"] == 1, counts
    assert counts["urdf_parses:ur5e.urdf"] == 1, counts
