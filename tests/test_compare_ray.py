"""The ray backend on a cluster: what a task needs from the driver reaches a node whose twin is installed
elsewhere, and a connection the cluster refuses is one line naming what to check.

(`bench/bench_ray_cluster.py` runs a real two-node cluster whose second node holds only the wheel.)"""

from __future__ import annotations

from dataclasses import replace
from types import SimpleNamespace
from typing import Any

import pytest

from twin.compare import runner
from twin.compare.spec import expand_runs, load_compare_config
from twin.errors import ConfigError
from twin.resources import packaged_config


@pytest.mark.parametrize("config", ["compare-smoke", "compare", "compare-robustness", "compare-tasks"])
def test_every_shipped_config_a_sweep_runs_is_sent_by_name(config):
    """The tasks carry the driver's absolute paths; each one of a shipped config must be recognised, or a
    node whose venv lives at another path fails every run with 'config file not found' (as it did)."""
    runs = expand_runs(load_compare_config(config))
    shipped = runner._shipped_config_names()
    assert runs and all(r.config in shipped for r in runs)
    assert {shipped[r.config] for r in runs} <= {"robocup.yaml", "warehouse.yaml"}


def _a_task() -> Any:
    return expand_runs(load_compare_config("compare-smoke"))[0]


def test_a_node_reads_a_shipped_config_from_its_own_install(monkeypatch):
    seen: list[str] = []
    monkeypatch.setattr(runner, "execute_run", lambda task: seen.append(task.config) or {"run_id": task.run_id})
    task = replace(_a_task(), config="/driver/venv/site-packages/twin/data/configs/warehouse.yaml")
    runner._run_on_node(task, "warehouse.yaml")
    assert seen == [str(packaged_config("warehouse.yaml"))]
    runner._run_on_node(replace(task, config="/shared/my-scene.yaml"), None)  # a user's own file: as given
    assert seen[-1] == "/shared/my-scene.yaml"


def test_a_node_without_the_shipped_config_gives_an_error_row(monkeypatch):
    monkeypatch.setattr(runner, "execute_run", lambda task: pytest.fail("must not run"))
    row = runner._run_on_node(_a_task(), "newer-than-this-node.yaml")
    assert row["status"] == "error" and row["failure"] == "error"
    assert "ships no config 'newer-than-this-node.yaml'" in row["reason"]


def _refusing_ray() -> SimpleNamespace:
    def init(**_: Any) -> None:
        raise ConnectionError("Failed to connect to Ray cluster at 10.0.0.1:6379.")

    return SimpleNamespace(init=init, exceptions=SimpleNamespace())


def test_a_refused_connection_without_token_mode_says_to_set_it(monkeypatch):
    monkeypatch.delenv("RAY_AUTH_MODE", raising=False)
    with pytest.raises(ConfigError) as e:
        runner._ray_connect(_refusing_ray(), "head:6379")
    text = str(e.value)
    assert "\n" not in text and text.startswith("cannot connect to the Ray cluster at head:6379: Failed to connect")
    assert "RAY_AUTH_MODE=token" in text and "~/.ray/auth_token" in text


def test_a_refused_connection_in_token_mode_points_at_the_token(monkeypatch):
    monkeypatch.setenv("RAY_AUTH_MODE", "token")
    with pytest.raises(ConfigError, match=r"the cluster's \(`ray get-auth-token` on the head\)"):
        runner._ray_connect(_refusing_ray(), "head:6379")
