"""Tasks are plugins: the built-in two are found by name like any other, and a third party can add one."""

from __future__ import annotations

import pytest

from twin.config import load_config
from twin.errors import ConfigError, UnknownNameError
from twin.registry import Kind, default_registry
from twin.tasks import make_task, run_task


def test_the_reference_systems_are_registered_tasks():
    reg = default_registry()
    assert {"robocup", "warehouse"} <= set(reg.names([Kind.TASK]))
    for name in ("robocup", "warehouse"):
        entry = reg.entry(name, [Kind.TASK])
        assert entry.load().__module__ == f"twin.tasks.{name}.task"
        assert entry.availability()


def test_the_task_is_chosen_by_the_config_name():
    s = load_config("warehouse")
    assert type(make_task(s)).__name__ == "WarehouseTask"
    s = load_config("robocup")
    assert type(make_task(s)).__name__ == "RobocupTask"


def test_an_unknown_task_name_is_a_one_line_error_listing_the_tasks():
    with pytest.raises(ConfigError) as e:
        load_config("robocup", ["task.kind=robocop"])
    msg = str(e.value)
    assert "\n" not in msg and "robocop" in msg and "robocup" in msg and "warehouse" in msg


def test_a_third_party_task_runs_with_its_own_validated_params(acme_plugin):
    s = load_config("robocup", ["task.kind=acme.wave", "task.params.times=2"])
    summary = run_task(s, seed=1)
    assert summary.objects == ()
    # two waves: capture and home, twice, each a real executed motion with its simulated time
    assert summary.sim_time_s > 1.0
    with pytest.raises(Exception, match="times"):
        make_task(load_config("robocup", ["task.kind=acme.wave", "task.params.times=9"]))


def test_a_task_name_is_not_a_planner_name(acme_plugin):
    with pytest.raises(UnknownNameError):
        default_registry().entry("acme.wave", [Kind.PLANNER, Kind.RECEDING_HORIZON])
