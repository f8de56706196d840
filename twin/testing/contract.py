"""The contract's rules and what a check reports: one table, so a rule's number and wording are written once
and the report, the CLI and `assert_conformant` all quote it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from twin.testing.allowances import time_slack_s

__all__ = ["RULES", "CheckResult", "ConformanceReport"]


# rule name -> (number of the rule in the contract, what it demands)
RULES: dict[str, tuple[int, str]] = {
    "statuses": (1, "a status, never an exception; unreachable and colliding goals get a failure status with a reason"),
    "start_goal": (
        2,
        "starts exactly at the start (segments: at the measured state), ends on the goal within its tolerance",
    ),
    "velocity": (3, "joint velocities within the request's limits"),
    "acceleration": (3, "joint accelerations within the request's limits"),
    "jerk": (3, "joint jerks within the request's limits"),
    "time_limit": (4, "every planning call returns within the request's time limit (plus slack)"),
    "determinism": (5, "the same request and seed give the same status and trajectory"),
    "invalid_start": (6, "a start in collision gets a status, not a trajectory"),
    "collision_free": (7, "no trajectory or segment it returns collides (FCL, configured resolution)"),
}


@dataclass(frozen=True)
class CheckResult:
    """One rule's verdict: `passed` when both the plugin's own output (`raw`) and what the runs get through
    `CheckedPlanner` (`checked`) keep it; `detail` says why, in one line."""

    rule: str
    passed: bool
    detail: str
    raw: bool = True
    checked: bool = True

    @property
    def number(self) -> int:
        return RULES[self.rule][0]

    @property
    def description(self) -> str:
        return RULES[self.rule][1]

    def to_json(self) -> dict[str, Any]:
        return {
            "rule": self.rule,
            "number": self.number,
            "passed": self.passed,
            "raw": self.raw,
            "checked": self.checked,
            "detail": self.detail,
            "description": self.description,
        }


@dataclass(frozen=True)
class ConformanceReport:
    """What `check_planner` found: one `CheckResult` per rule, and what was asked (`requests`)."""

    planner: str
    kind: str  # "one-shot" or "receding-horizon"
    config: str
    seed: int
    time_limit_s: float
    goal_kinds: tuple[str, ...]
    results: tuple[CheckResult, ...]
    requests: tuple[dict[str, Any], ...] = ()
    wall_time_s: float = 0.0

    @property
    def ok(self) -> bool:
        return all(r.passed for r in self.results)

    @property
    def failures(self) -> list[CheckResult]:
        return [r for r in self.results if not r.passed]

    def result(self, rule: str) -> CheckResult:
        for r in self.results:
            if r.rule == rule:
                return r
        raise KeyError(f"no rule {rule!r}; rules: {', '.join(RULES)}")

    def summary(self) -> str:
        """'ompl.rrtconnect: 9/9 rules pass' or the failures, one per line."""
        head = f"{self.planner}: {len(self.results) - len(self.failures)}/{len(self.results)} rules pass"
        return "\n".join([head] + [f"  {r.number} {r.rule}: {r.detail}" for r in self.failures])

    def to_json(self) -> dict[str, Any]:
        return {
            "planner": self.planner,
            "kind": self.kind,
            "config": self.config,
            "seed": self.seed,
            "time_limit_s": self.time_limit_s,
            "time_slack_s": time_slack_s(self.time_limit_s),
            "goal_kinds": list(self.goal_kinds),
            "ok": self.ok,
            "rules": [r.to_json() for r in self.results],
            "requests": list(self.requests),
            "wall_time_s": self.wall_time_s,
        }


class _Verdict:
    """Collects the failures of one rule on both layers; the first reason of each is kept for the detail."""

    def __init__(self) -> None:
        self.raw: list[str] = []
        self.checked: list[str] = []

    def fail(self, layer: str, why: str) -> None:
        (self.raw if layer == "raw" else self.checked).append(why)

    def both(self, why: str) -> None:
        self.raw.append(why)
        self.checked.append(why)

    def result(self, rule: str, ok_detail: str) -> CheckResult:
        raw_ok, checked_ok = not self.raw, not self.checked
        if raw_ok and checked_ok:
            return CheckResult(rule, True, ok_detail)
        parts = []
        if self.raw and self.checked and self.raw[0] == self.checked[0]:
            parts.append(self.raw[0] + _more(self.raw))
        else:
            if self.raw:
                parts.append("the planner itself: " + self.raw[0] + _more(self.raw))
            if self.checked:
                parts.append("through CheckedPlanner: " + self.checked[0] + _more(self.checked))
        return CheckResult(rule, False, "; ".join(parts), raw_ok, checked_ok)


def _more(items: list[str]) -> str:
    return f" (and {len(items) - 1} more)" if len(items) > 1 else ""
