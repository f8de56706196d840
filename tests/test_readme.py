"""The README's examples work as written: its minimal planner keeps the planner contract, and its
comparison config (a query scenario and a task scenario) is accepted and counted by a dry run."""

from __future__ import annotations

import re
from pathlib import Path

from twin.compare import compare_spec_from_dict, plan_comparison

ROOT = Path(__file__).resolve().parent.parent
README = (ROOT / "README.md").read_text()


def _block(language: str, after: str) -> str:
    m = re.search(re.escape(after) + r".*?```" + language + r"\n(.*?)```", README, re.DOTALL)
    assert m is not None, f"no ```{language} block after {after!r} in README.md"
    return m.group(1)


def test_the_readme_planner_keeps_the_contract() -> None:
    from twin.testing import check_planner

    namespace: dict[str, object] = {"__name__": "readme_planner"}
    exec(compile(_block("python", "<!-- readme-planner"), "README.md", "exec"), namespace)
    report = check_planner(namespace["StraightLine"])  # type: ignore[arg-type]
    assert report.goal_kinds == ("joint",)
    broken = [(r.rule, r.detail) for r in report.results if not r.passed]
    assert not broken, broken
    solved = [q for q in report.requests if q["purpose"] == "query" and q["status"] == "success"]
    refused = [q for q in report.requests if q["purpose"] == "query" and q["status"] == "collision"]
    assert solved and refused  # it plans the free query and refuses the blocked one


def test_the_readme_comparison_config_dry_runs() -> None:
    import yaml

    spec = compare_spec_from_dict(yaml.safe_load(_block("yaml", "(`task:`), each planner block")))
    dry = plan_comparison(spec)
    kinds = {r.kind for r in dry.runs}
    assert kinds == {"query", "task"} and not dry.skipped
    assert {r.seed for r in dry.runs if r.kind == "task"} == {2, 3, 4}
