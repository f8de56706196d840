"""Who wins on what: per scenario, the planner that leads on success and on each time a user chooses on,
the one behind it, and whether the lead holds up on the problems both ran (the paired tests of
`twin.compare.stats`, as the paired comparison with the reference uses them).

A lead is read from the summary (the highest success rate; the lowest median time), and tested pair by
pair against the runner-up: the exact sign test on the problems one solved and the other did not
(success), the Wilcoxon signed-rank test on the problems both have a value for (times). The medians of a
time are over the runs that have one (a trajectory's duration: successful runs only), so each names its n:
a planner that solved only the easy problems can show the shortest median duration, and its n says so.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

from twin.compare.metrics import METRICS, TIMINGS
from twin.compare.stats import MIN_DISCORDANT, SIGNIFICANCE, is_tie
from twin.compare.summary import (
    ALL,
    SUCCESS,
    PairedComparison,
    Summary,
    SummaryRow,
    by_problem,
    paired_comparison,
)

__all__ = ["VERDICT_METRICS", "Verdict", "p_text", "verdicts"]

# per kind of run: the metrics a lead is named on after success (lower is better for each)
VERDICT_METRICS = {
    "query": ("planning_time_s", "duration_s"),
    "task": ("task_planning_time_s", "cycle_time_s"),
}
_LABELS = {
    SUCCESS: "success",
    "planning_time_s": "planning time (median)",
    "duration_s": "trajectory duration (median, successful plans)",
    "task_planning_time_s": "planning time per motion in the task (median)",
    "cycle_time_s": "cycle time per placed object (median)",
}
_UNITS = {d.key: d.unit for d in METRICS + TIMINGS}
_LISTED = 5  # leaders named in a verdict; more are counted


@dataclass(frozen=True)
class Verdict:
    """The lead on `metric` in `scenario` (ALL: every scenario, success only): the planners that share the
    best value (`leaders`, in config order), the best planner behind them (`runner_up`, None when every
    planner ties), and the first leader against it on the problems both ran (`test`; None without a
    runner-up or a common problem)."""

    scenario: str
    metric: str
    leaders: tuple[str, ...]
    value: str
    runner_up: str | None
    runner_up_value: str | None
    test: PairedComparison | None
    pool: str = ""  # whom a time lead is among, when not every planner (`_fastest`), in words

    @property
    def significant(self) -> bool:
        """Whether the lead holds on the paired problems at the 5 % level."""
        return self.test is not None and self.test.p_value is not None and self.test.p_value < SIGNIFICANCE

    @property
    def text(self) -> str:
        """One sentence in Markdown: who leads, by how much, and whether the paired test backs it."""
        names = [f"`{p}`" for p in self.leaders]
        if len(names) > _LISTED:
            names = [*names[: _LISTED - 1], f"{len(names) - _LISTED + 1} more"]
        who = ", ".join(names)
        lead = f"{who} share the lead at" if len(self.leaders) > 1 else f"{who} leads with"
        pool = f" ({self.pool})" if self.pool else ""
        head = f"**{_LABELS.get(self.metric, self.metric)}**{pool}: {lead} {self.value}"
        if self.runner_up is None:
            return head + (
                "; no other planner has its success rate." if self.pool else "; every planner here has the same."
            )
        head += f"; next `{self.runner_up}`: {self.runner_up_value}"
        t = self.test
        if t is None:
            return head + "; they share no problem to compare on."
        if self.metric == SUCCESS:
            pairs = (
                f"on the {_problems(t.n)} both ran, {t.wins} solved by `{t.planner}` only, "
                f"{t.losses} by `{t.reference}` only"
            )
            test = "exact sign test"
        else:
            pairs = (
                f"on the {_problems(t.n)} both have a value for, `{t.planner}` lower on {t.wins}, tied on {t.ties}, "
                f"higher on {t.losses}"
            )
            test = "Wilcoxon signed-rank"
        if t.p_value is None:
            why = f"too few differing problems to test (fewer than {MIN_DISCORDANT})"
        elif t.p_value < SIGNIFICANCE:
            why = f"a real lead ({test} {p_text(t.p_value)})"
        else:
            why = f"not a significant lead ({test} {p_text(t.p_value)})"
        return f"{head}; {pairs}: {why}."


def p_text(p: float) -> str:
    """'p = 0.031', or 'p < 0.001'."""
    return "p < 0.001" if p < 1e-3 else f"p = {p:.3f}"


def _problems(n: int) -> str:
    return "1 problem" if n == 1 else f"{n} problems"


def _rate(r: SummaryRow) -> str:
    return f"{100 * (r.success_rate or 0.0):.0f}% ({r.successes}/{r.runs})"


def _time(r: SummaryRow, key: str) -> str:
    st = r.stats[key]
    unit = _UNITS.get(key, "")
    v = st.median or 0.0
    text = f"{v * 1e3:.3g} ms" if unit == "s" and v < 1.0 else f"{v:.3g} {unit}".rstrip()
    return f"{text} (n={st.n})"


def _success(summary: Summary, scenario: str, problems: dict[str, Any]) -> Verdict | None:
    rows = [r for r in _rows(summary, scenario) if r.runs]
    if not rows:
        return None
    best = max(r.success_rate or 0.0 for r in rows)
    leaders = [r for r in rows if (r.success_rate or 0.0) == best]
    behind = sorted((r for r in rows if (r.success_rate or 0.0) < best), key=lambda r: -(r.success_rate or 0.0))
    return _verdict(scenario, SUCCESS, leaders, behind, _rate, problems)


def _fastest(summary: Summary, scenario: str, key: str, problems: dict[str, Any]) -> Verdict | None:
    """The lead on a time among the planners with the top success rate: a planner that fails fast is not
    the one to choose for speed (it is named beside the lead when it is the fastest of all)."""
    timed = [r for r in _rows(summary, scenario) if r.runs and r.stats[key].n]
    if len(timed) < 2:
        return None
    top = max(r.success_rate or 0.0 for r in _rows(summary, scenario) if r.runs)
    pool = sorted((r for r in timed if (r.success_rate or 0.0) == top), key=lambda r: r.stats[key].median or 0.0)
    if not pool:
        return None
    best = pool[0].stats[key].median or 0.0
    leaders = [r for r in pool if is_tie(r.stats[key].median or 0.0, best)]
    behind = [r for r in pool if r not in leaders]
    verdict = _verdict(scenario, key, leaders, behind, lambda r: _time(r, key), problems)
    if len(pool) == len(timed):
        return verdict
    words = f"among the {len(pool)} planners at the top success rate, {100 * top:.0f}%"
    if len(pool) == 1:
        words = f"among the planners at the top success rate, {100 * top:.0f}%"
    fastest = min(timed, key=lambda r: r.stats[key].median or 0.0)
    if fastest not in pool:
        words += f"; fastest of all: `{fastest.planner}` {_time(fastest, key)} at {_rate(fastest)} success"
    return replace(verdict, pool=words)


def _verdict(
    scenario: str,
    metric: str,
    leaders: Sequence[SummaryRow],
    behind: Sequence[SummaryRow],
    value: Any,
    problems: dict[str, Any],
) -> Verdict:
    first = leaders[0]
    nxt = behind[0] if behind else None
    test = None
    if nxt is not None:
        test = paired_comparison(
            first.planner,
            nxt.planner,
            scenario,
            metric,
            problems.get(first.planner, {}),
            problems.get(nxt.planner, {}),
        )
    return Verdict(
        scenario=scenario,
        metric=metric,
        leaders=tuple(r.planner for r in leaders),
        value=value(first),
        runner_up=nxt.planner if nxt is not None else None,
        runner_up_value=value(nxt) if nxt is not None else None,
        test=test,
    )


def _rows(summary: Summary, scenario: str) -> list[SummaryRow]:
    return summary.overall if scenario == ALL else [r for r in summary.by_scenario if r.scenario == scenario]


def verdicts(summary: Summary, rows: Sequence[dict[str, Any]]) -> list[Verdict]:
    """Per scenario (in order): the lead on success, then on the times of its kind of run
    (VERDICT_METRICS); then, with more than one scenario, the lead on success over all of them. `rows`
    are the summary's result rows (the paired tests pair them)."""
    rows = [r for r in rows if r.get("status") != "skipped"]
    problems = by_problem(rows)
    kinds = {r["scenario"]: str(r.get("kind") or "query") for r in rows}
    out: list[Verdict] = []
    scenarios = list(dict.fromkeys(r.scenario for r in summary.by_scenario))
    for s in scenarios:
        found = [_success(summary, s, problems)]
        found += [_fastest(summary, s, key, problems) for key in VERDICT_METRICS.get(kinds.get(s, "query"), ())]
        out += [v for v in found if v is not None]
    if len(scenarios) > 1:
        overall = _success(summary, ALL, problems)
        if overall is not None:
            out.append(overall)
    return out
