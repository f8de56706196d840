"""The README's examples work as written: its plugin package (a planner that runs a task) installs, keeps the
planner contract and places objects in `twin run`, and its comparison config (a query scenario and a task
scenario) is accepted and counted by a dry run."""

from __future__ import annotations

import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest
from cli_runner import twin

from twin.compare import compare_spec_from_dict, plan_comparison

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()
# `twin run` on a cut-down table (the README's commands run as written, plus this): two objects, one per bin
TWO_OBJECTS = "world.objects.items=[{class: bottle}, {class: cube, color: red}]"


def _block(language: str, after: str) -> str:
    m = re.search(re.escape(after) + r".*?```" + language + r"\n(.*?)```", README, re.DOTALL)
    assert m is not None, f"no ```{language} block after {after!r} in README.md"
    return m.group(1)


def _package_files() -> dict[str, str]:
    """The README's plugin package: path -> the block after each `<!-- readme-plugin: PATH -->`."""
    files = dict(re.findall(r"<!-- readme-plugin: (\S+) -->\n```\w+\n(.*?)```", README, re.DOTALL))
    assert set(files) >= {"acme-twin-plugin/pyproject.toml", "acme-twin-plugin/acme_twin_plugin/planner.py"}
    return files


def _commands() -> list[list[str]]:
    """The README's install-and-run commands, each split into words (comments dropped)."""
    block = _block("bash", "<!-- readme-plugin-commands")
    return [shlex.split(line, comments=True) for line in block.splitlines() if line.strip()]


@pytest.fixture(scope="module")
def readme_plugin(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The README's package written from its blocks and installed by pip from its `pip install -e` line's path,
    built the same way (setuptools, its pyproject.toml) but into a folder of its own, which goes on a
    subprocess's PYTHONPATH: the shared venv is left as it was."""
    src = tmp_path_factory.mktemp("readme-plugin")
    for rel, text in _package_files().items():
        (src / rel).parent.mkdir(parents=True, exist_ok=True)
        (src / rel).write_text(text)
    install = next(c for c in _commands() if c[:3] == [".venv/bin/pip", "install", "-e"])
    site = src / "site"
    pip = [sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--no-build-isolation", "--no-index"]
    subprocess.run([*pip, "--target", str(site), str(src / install[3])], check=True, capture_output=True)
    assert (site / "acme_twin_plugin" / "planner.py").is_file()
    return site


def test_the_readme_planner_keeps_the_contract() -> None:
    from twin.testing import check_planner

    namespace: dict[str, object] = {"__name__": "readme_planner"}
    source = _package_files()["acme-twin-plugin/acme_twin_plugin/planner.py"]
    exec(compile(source, "README.md", "exec"), namespace)
    report = check_planner(namespace["StraightLine"])  # type: ignore[arg-type]
    assert report.goal_kinds == ("joint", "pose", "position")
    broken = [(r.rule, r.detail) for r in report.results if not r.passed]
    assert not broken, broken
    queries = [q for q in report.requests if q["purpose"] == "query"]
    assert any(q["status"] == "collision" for q in queries)  # it refuses the blocked query, with a reason
    solved = {q["goal_kind"] for q in queries if q["status"] == "success"}
    assert solved >= {"joint", "position"}  # the check's pose query is the blocked one (a pose is run below)
    refused = [q for q in report.requests if q["purpose"] in ("unreachable", "colliding_goal")]
    assert refused and all(q["status"] == "invalid_goal" and q["reason"] for q in refused)


def test_the_readme_plugin_installs_checks_and_runs_a_task(readme_plugin: Path, tmp_path: Path) -> None:
    runs = 0
    for i, words in enumerate(_commands()):
        if words[0] != ".venv/bin/twin":
            continue
        out = tmp_path / f"{i}.json"
        args = words[1:] + (["--set", TWO_OBJECTS] if words[1] == "run" else []) + ["--json", str(out)]
        r = twin(*args, extra_path=readme_plugin)
        assert r.returncode == 0, f"{shlex.join(words)}: {r.stdout[-3000:]}{r.stderr[-3000:]}"
        result = json.loads(out.read_text())
        if words[1] == "check-planner":
            assert result["planner"] == "acme.straight" and result["ok"]
            continue
        runs += 1
        assert [o["placed"] for o in result["objects"]] == [True, True], result["objects"]
        mine = result["metrics"]["acme.straight"]
        groups = {"transfer"} | ({"movej"} if "planners.movej.name=acme.straight" in words else set())
        # every transfer (and with movej, every capture, align, hover and home) is its motion, and succeeded
        assert mine["succeeded"] == mine["motions"] >= 2 * len(groups)
        assert ("ruckig.movej" in result["metrics"]) == ("movej" not in groups)
    assert runs == 2


def test_the_readme_comparison_config_dry_runs() -> None:
    import yaml

    spec = compare_spec_from_dict(yaml.safe_load(_block("yaml", "(`task:`), each planner block")))
    dry = plan_comparison(spec)
    kinds = {r.kind for r in dry.runs}
    assert kinds == {"query", "task"} and not dry.skipped
    assert {r.seed for r in dry.runs if r.kind == "task"} == {2, 3, 4}
