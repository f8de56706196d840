"""The summary of a comparison as numbers: per planner (overall and per scenario) the success rate and the
median and 95th percentile of every metric with their intervals (`SummaryRow`, `Stat`), the paired comparison
with a reference planner (`PairedComparison`), the points of swept scenarios (`SweepPoint`), what ran
(`Provenance`), all in one `Summary`. How they are computed is said in `twin.compare.report`, which composes
them (`summarize`: these statistics, then `twin.compare.verdicts`) and writes them out; the statistics
themselves live in `twin.compare.stats`. Nothing here writes a file or imports a writer.
"""

from __future__ import annotations

import difflib
import json
from collections import Counter
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from typing import TYPE_CHECKING, Any

import numpy as np

from twin.compare.metrics import FAILURES, METRICS, TIMINGS, MetricDef, failure_of_row
from twin.compare.stats import (
    bootstrap_ci,
    sign_test,
    signed_rank,
    stable_seed,
    wilson_ci,
)
from twin.errors import ConfigError

if TYPE_CHECKING:
    from twin.compare.verdicts import Verdict

__all__ = [
    "ALL",
    "METRIC_DEFS",
    "PAIRED_KEYS",
    "SUCCESS",
    "SWEEP_TIME_KEYS",
    "PairedComparison",
    "Provenance",
    "Stat",
    "Summary",
    "SummaryRow",
    "SweepPoint",
    "by_problem",
    "paired_comparison",
    "summary_of",
    "sweep_points",
]

ALL = "all"  # the scenario column of a planner's overall row
METRIC_DEFS: tuple[MetricDef, ...] = METRICS + TIMINGS  # every metric and timing a summary has
_BETTER = {d.key: d.better for d in METRIC_DEFS}

PAIRED_KEYS = ("planning_time_s", "duration_s")  # metrics compared pair by pair with the reference
SUCCESS = "success"  # the metric name of the paired success comparison
SWEEP_TIME_KEYS = {"task": "cycle_time_s", "query": "duration_s"}  # the time a sweep shows, per run kind


@dataclass(frozen=True)
class Stat:
    """Median and 95th percentile (linear interpolation) of n values, and the 95 % percentile-bootstrap
    interval of the median [ci_low, ci_high] (None below two values: `stats.bootstrap_ci`)."""

    n: int
    median: float | None
    p95: float | None
    ci_low: float | None = None
    ci_high: float | None = None

    @classmethod
    def of(cls, values: Sequence[float] | np.ndarray, *, seed: int = 0) -> Stat:
        """The statistics of `values`; `seed` seeds the bootstrap of the median's interval."""
        a = np.asarray(values, dtype=float)
        if a.size == 0:
            return cls(0, None, None)
        ci = bootstrap_ci(a, seed=seed)
        lo, hi = ci if ci is not None else (None, None)
        return cls(int(a.size), float(np.median(a)), float(np.percentile(a, 95)), lo, hi)

    @property
    def ci(self) -> tuple[float, float] | None:
        return None if self.ci_low is None or self.ci_high is None else (self.ci_low, self.ci_high)


@dataclass(frozen=True)
class SummaryRow:
    """One planner on one scenario (or on all of them: scenario == ALL)."""

    planner: str
    scenario: str
    runs: int
    successes: int
    errors: int
    stats: dict[str, Stat]
    min_clearance_m: float | None = None  # the smallest min_clearance_m of any run
    closest_pair: str | None = None  # 'robot_part->body' of that run
    common_pair: str | None = None  # the closest pair seen most often over the successful runs
    common_pair_runs: int = 0  # ... in how many of them
    straight_free: int = 0  # query runs whose straight joint motion was collision-free
    straight_known: int = 0  # query runs that recorded it
    success_ci: tuple[float, float] | None = None  # 95 % Wilson interval of success_rate (0..1)
    failures: dict[str, int] = field(default_factory=dict)  # reason -> runs, in FAILURES order, nonzero only
    # failed task runs by where they failed (the worker's `failure_in`): in a stage the compared planner
    # planned, or elsewhere; and "stage (planner)" -> failed task runs, for the ones that failed elsewhere
    task_failed_in_planner: int = 0
    task_failed_elsewhere: int = 0
    task_failed_stages: dict[str, int] = field(default_factory=dict)
    failed_runs: tuple[str, ...] = ()  # run ids of the runs that did not succeed (`twin replay` takes them)

    @property
    def success_rate(self) -> float | None:
        return self.successes / self.runs if self.runs else None

    @property
    def straight_free_rate(self) -> float | None:
        return self.straight_free / self.straight_known if self.straight_known else None


@dataclass(frozen=True)
class PairedComparison:
    """`planner` against `reference` on `metric` over the n problems both ran (same scenario, case and
    seed; scenario == ALL pools every scenario) where both have a value.

    Wins, ties and losses are from `planner`'s side: a win is a better value (lower, unless the metric's
    `better` is "higher"; PAIRED_KEYS are all lower-is-better); a tie is `is_tie(a, b)`. `median_diff`
    is the median of planner - reference over all n pairs (negative: planner lower). `p_value` is the
    two-sided Wilcoxon signed-rank test (scipy.stats.wilcoxon, zero_method="wilcox", method="auto":
    exact up to 50 pairs when no two differences have the same size) on the wins + losses pairs: ties
    are set aside as zero differences, as the "wilcox" convention does, and reported as ties. With fewer
    than MIN_DISCORDANT non-tied pairs, p is None.

    metric == "success": every problem both ran; a win is a success where the reference failed, a tie is
    both succeeded or both failed; p is the exact two-sided sign test (binomial, p = 1/2; McNemar's exact
    test) on the discordant pairs, again None below MIN_DISCORDANT; median_diff is None (the difference in
    success rate on these problems is (wins - losses) / n).
    """

    planner: str
    reference: str
    scenario: str
    metric: str
    n: int
    wins: int
    ties: int
    losses: int
    median_diff: float | None
    p_value: float | None


@dataclass(frozen=True)
class SweepPoint:
    """One planner at one level (`value`) of one swept `key` of a scenario: the runs on that key's axis
    with that value (the nominal point's runs lie on every axis), their success rate with its 95 % Wilson
    interval, the mean share of objects placed (task runs; None for queries), and the median of
    `time_key` (SWEEP_TIME_KEYS: cycle time per placed object, or trajectory duration) with its 95 %
    percentile-bootstrap interval."""

    scenario: str
    key: str
    value: Any
    planner: str
    runs: int
    successes: int
    errors: int
    success_ci: tuple[float, float] | None
    placed: float | None
    time_key: str
    time: Stat

    @property
    def success_rate(self) -> float | None:
        return self.successes / self.runs if self.runs else None

    @property
    def value_text(self) -> str:
        """The level as a column header shows it: a string as it is, anything else as compact JSON."""
        return self.value if isinstance(self.value, str) else json.dumps(self.value, separators=(",", ":"))


@dataclass(frozen=True)
class Provenance:
    """What ran: the config's `name` and file (`config_path`, None for a config built in code), when the sweep
    started (`date`, with its time zone) and where (`environment`: a `twin.environment.environment()` record,
    as compare.json keeps it; None when not recorded)."""

    name: str
    config_path: str | None = None
    date: datetime | None = None
    environment: Mapping[str, Any] | None = None

    def lines(self) -> list[str]:
        """'config: ...', 'date: ...', 'commit: ...', 'machine: ...': summary.md's opening lines (names, paths,
        the commit and the host in backticks, as Markdown sets code)."""
        env = self.environment or {}
        twin = env.get("twin") or {}
        if twin.get("commit"):
            commit = f"`{twin['commit']}`" + (" with uncommitted changes" if twin.get("dirty") else "")
        else:
            commit = "unknown (not run from a git checkout)" if twin else "not recorded"
        if twin.get("version"):
            commit += f", twin {twin['version']}"
        cpu = env.get("cpu") or {}
        cores = f"{_known(cpu.get('cores'))} cores ({_known(cpu.get('usable_cores'))} usable)"
        host = f", host `{env['hostname']}`" if env.get("hostname") else ""
        machine = f"{cpu.get('model') or 'CPU unknown'}, {cores}{host}" if env else "not recorded"
        config = f"`{self.name}`" + (f" (`{self.config_path}`)" if self.config_path else "")
        date = self.date.isoformat(sep=" ", timespec="seconds") if self.date else "not recorded"
        return [f"config: {config}", f"date: {date}", f"commit: {commit}", f"machine: {machine}"]


def _known(v: Any) -> str:
    return "?" if v is None else str(v)


@dataclass(frozen=True)
class Summary:
    """Overall rows (one per planner, in config order) and per-scenario rows; skipped runs with reasons;
    the paired comparison of every planner with `reference`; the sweep points of swept scenarios."""

    overall: list[SummaryRow]
    by_scenario: list[SummaryRow]
    skipped: list[tuple[str, str]] = field(default_factory=list)
    paired: list[PairedComparison] = field(default_factory=list)
    reference: str | None = None
    sweeps: list[SweepPoint] = field(default_factory=list)
    # (planner, scenario) -> runs skipped there (a pair that could not run: not a failure, not a 0 %)
    skipped_pairs: dict[tuple[str, str], int] = field(default_factory=dict)
    verdicts: list[Verdict] = field(default_factory=list)  # who leads on what (`twin.compare.verdicts`)
    provenance: Provenance | None = None  # what ran, when, where: summary.md's opening lines

    def sweep_axes(self) -> list[tuple[str, str]]:
        """(scenario, key) of every swept key, in the order the rows first show them."""
        return list(dict.fromkeys((p.scenario, p.key) for p in self.sweeps))

    def metric_keys(self) -> list[str]:
        """Metrics that have at least one value (the others would be empty columns)."""
        return [d.key for d in METRIC_DEFS if any(r.stats[d.key].n for r in self.overall)]

    def row(self, planner: str, scenario: str = ALL) -> SummaryRow | None:
        """The row of `planner` on `scenario` (ALL: overall), None if it has no runs there."""
        rows = self.overall if scenario == ALL else self.by_scenario
        return next((r for r in rows if r.planner == planner and r.scenario == scenario), None)


def _value(row: dict[str, Any], key: str) -> float | None:
    v = row.get("metrics", {}).get(key)
    if v is None:
        v = row.get("timing", {}).get(key)
    return None if v is None else float(v)


def _failure_counts(rows: list[dict[str, Any]]) -> dict[str, int]:
    counts = Counter(f for r in rows if (f := failure_of_row(r)) is not None)
    known = [k for k in FAILURES if counts[k]]
    return {k: counts[k] for k in known + sorted(set(counts) - set(FAILURES))}


def _task_failure_places(rows: list[dict[str, Any]]) -> tuple[int, int, dict[str, int]]:
    """(failed task runs in the compared planner's stages, failed elsewhere, "stage (planner)" -> runs)."""
    failed = [r for r in rows if r.get("kind") == "task" and r.get("failure_in") is not None]
    stages = Counter(
        f"{r.get('failed_stage') or '?'}" + (f" ({r['failed_planner']})" if r.get("failed_planner") else "")
        for r in failed
    )
    return (
        sum(r["failure_in"] == "planner" for r in failed),
        sum(r["failure_in"] != "planner" for r in failed),
        dict(sorted(stages.items(), key=lambda kv: (-kv[1], kv[0]))),
    )


def _summarize(rows: list[dict[str, Any]], planner: str, scenario: str) -> SummaryRow:
    stats = {
        d.key: Stat.of(
            [v for r in rows if (v := _value(r, d.key)) is not None], seed=stable_seed(planner, scenario, d.key)
        )
        for d in METRIC_DEFS
    }
    with_pair = [
        (v, r["clearance_pair"])
        for r in rows
        if (v := _value(r, "min_clearance_m")) is not None and r.get("clearance_pair")
    ]
    closest = min(with_pair, key=lambda vp: vp[0]) if with_pair else (None, None)
    counts = Counter(p for _, p in with_pair)
    common, n_common = counts.most_common(1)[0] if counts else (None, 0)
    known = [r["straight_free"] for r in rows if r.get("straight_free") is not None]
    ok = sum(1 for r in rows if r.get("success"))
    in_planner, elsewhere, stages = _task_failure_places(rows)
    return SummaryRow(
        planner=planner,
        scenario=scenario,
        runs=len(rows),
        successes=ok,
        errors=sum(1 for r in rows if r.get("status") == "error"),
        stats=stats,
        min_clearance_m=closest[0],
        closest_pair=closest[1],
        common_pair=common,
        common_pair_runs=n_common,
        straight_free=sum(1 for v in known if v),
        straight_known=len(known),
        success_ci=wilson_ci(ok, len(rows)),
        failures=_failure_counts(rows),
        task_failed_in_planner=in_planner,
        task_failed_elsewhere=elsewhere,
        task_failed_stages=stages,
        failed_runs=tuple(str(r["run_id"]) for r in rows if not r.get("success")),
    )


def _problem(row: dict[str, Any]) -> tuple[Any, ...]:
    """What makes two runs the same problem: the same query (scenario and case) with the same seed."""
    return (row["scenario"], row.get("case"), row.get("seed"))


def by_problem(rows: Iterable[dict[str, Any]]) -> dict[str, dict[tuple[Any, ...], dict[str, Any]]]:
    """planner -> problem (scenario, case, seed) -> its row: what a paired comparison pairs."""
    problems: dict[str, dict[tuple[Any, ...], dict[str, Any]]] = {}
    for r in rows:
        problems.setdefault(r["planner"], {})[_problem(r)] = r
    return problems


def paired_comparison(
    planner: str,
    reference: str,
    scenario: str,
    metric: str,
    mine: dict[tuple[Any, ...], dict[str, Any]],
    ref: dict[tuple[Any, ...], dict[str, Any]],
) -> PairedComparison | None:
    """`planner` against `reference` on `metric` ("success" or a metric key) over the problems of
    `scenario` (ALL: every one) that both ran (`by_problem`'s rows of each), None when no problem has a
    value for both."""
    keys = [k for k in mine if k in ref and (scenario == ALL or k[0] == scenario)]
    if metric == SUCCESS:
        if not keys:
            return None
        return _paired_success(
            planner, reference, scenario, [(bool(mine[k].get("success")), bool(ref[k].get("success"))) for k in keys]
        )
    pairs = [
        (a, b) for k in keys if (a := _value(mine[k], metric)) is not None and (b := _value(ref[k], metric)) is not None
    ]
    return _paired_metric(planner, reference, scenario, metric, pairs) if pairs else None


def _paired_metric(
    planner: str, reference: str, scenario: str, metric: str, pairs: list[tuple[float, float]]
) -> PairedComparison:
    a, b = np.array(pairs, dtype=float).T
    t = signed_rank(a, b, higher_is_better=_BETTER.get(metric) == "higher")
    return PairedComparison(
        planner, reference, scenario, metric, int(a.size), t.wins, t.ties, t.losses, t.median_diff, t.p_value
    )


def _paired_success(planner: str, reference: str, scenario: str, pairs: list[tuple[bool, bool]]) -> PairedComparison:
    wins = sum(1 for mine, ref in pairs if mine and not ref)
    losses = sum(1 for mine, ref in pairs if ref and not mine)
    p = sign_test(wins, losses)
    return PairedComparison(
        planner, reference, scenario, SUCCESS, len(pairs), wins, len(pairs) - wins - losses, losses, None, p
    )


def _paired(
    rows: list[dict[str, Any]], order: list[str], scenarios: list[str], reference: str
) -> list[PairedComparison]:
    """Every planner but the reference against it: overall, then per scenario; success, then PAIRED_KEYS."""
    problems = by_problem(rows)
    ref = problems.get(reference, {})
    out: list[PairedComparison] = []
    for p in order:
        mine = problems.get(p, {})
        if p == reference or not mine:
            continue
        for s in [ALL, *scenarios]:
            for m in (SUCCESS, *PAIRED_KEYS):
                c = paired_comparison(p, reference, s, m, mine, ref)
                if c is not None:
                    out.append(c)
    return out


def sweep_points(rows: Iterable[dict[str, Any]], *, planners: Sequence[str] | None = None) -> list[SweepPoint]:
    """The sweep points of the rows that carry a sweep level (`row["sweep"]`, `row["sweep_axes"]`): per
    scenario, swept key, level and planner (in `planners` order, then any others). Levels are in the order
    the rows show them: in run order (as `run_comparison` returns them) the nominal value first, then the
    others as the sweep lists them."""
    rows = [r for r in rows if r.get("status") != "skipped" and r.get("sweep")]
    order = list(planners or [])
    order += sorted({r["planner"] for r in rows} - set(order))
    out: list[SweepPoint] = []
    for scenario in dict.fromkeys(r["scenario"] for r in rows):
        srows = [r for r in rows if r["scenario"] == scenario]
        for key in dict.fromkeys(k for r in srows for k in r["sweep"]):
            on_axis = [r for r in srows if key in (r.get("sweep_axes") or ()) and key in r["sweep"]]
            levels: dict[str, Any] = {}
            for r in on_axis:
                levels.setdefault(json.dumps(r["sweep"][key], sort_keys=True), r["sweep"][key])
            for text in levels:
                at = [r for r in on_axis if json.dumps(r["sweep"][key], sort_keys=True) == text]
                for p in order:
                    sel = [r for r in at if r["planner"] == p]
                    if not sel:
                        continue
                    time_key = SWEEP_TIME_KEYS.get(str(sel[0].get("kind")), "duration_s")
                    ok = sum(1 for r in sel if r.get("success"))
                    placed = [v for r in sel if (v := _value(r, "task_success_rate")) is not None]
                    times = [v for r in sel if (v := _value(r, time_key)) is not None]
                    out.append(
                        SweepPoint(
                            scenario=scenario,
                            key=key,
                            value=levels[text],
                            planner=p,
                            runs=len(sel),
                            successes=ok,
                            errors=sum(1 for r in sel if r.get("status") == "error"),
                            success_ci=wilson_ci(ok, len(sel)),
                            placed=float(np.mean(placed)) if placed else None,
                            time_key=time_key,
                            time=Stat.of(times, seed=stable_seed(p, scenario, f"{key}={text}", time_key)),
                        )
                    )
    return out


def summary_of(
    rows: Iterable[dict[str, Any]],
    *,
    planners: Sequence[str] | None = None,
    skipped: Sequence[tuple[str, str]] = (),
    reference: str | None = None,
    skipped_pairs: dict[tuple[str, str], int] | None = None,
    provenance: Provenance | None = None,
) -> Summary:
    """Group result rows by planner (in `planners` order, then any others) and by planner x scenario, with
    bootstrap intervals and failure counts, compare every planner with `reference` on the problems both
    ran (default: the first planner in that order that has runs); no verdicts yet (`twin.compare.report.summarize`
    adds them). `skipped` are the (run id, reason) of runs that could not run and
    `skipped_pairs` their count per (planner, scenario); rows with status "skipped" count there too.
    `provenance`: what ran, for summary.md's opening lines."""
    rows = list(rows)
    pairs = Counter(dict(skipped_pairs or {}))
    pairs.update((r["planner"], r["scenario"]) for r in rows if r.get("status") == "skipped")
    rows = [r for r in rows if r.get("status") != "skipped"]
    order = list(planners or [])
    order += sorted({r["planner"] for r in rows} - set(order))
    scenarios: list[str] = []
    for r in rows:
        if r["scenario"] not in scenarios:
            scenarios.append(r["scenario"])
    overall = [_summarize([r for r in rows if r["planner"] == p], p, ALL) for p in order]
    by_scenario = [
        _summarize(sel, p, s)
        for s in scenarios
        for p in order
        if (sel := [r for r in rows if r["planner"] == p and r["scenario"] == s])
    ]
    ran = [r.planner for r in overall if r.runs]
    if reference is None:
        reference = ran[0] if ran else None
    elif reference not in order:
        close = difflib.get_close_matches(reference, order, n=1)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        raise ConfigError(f"reference planner {reference!r} is not compared here.{hint} Planners: {', '.join(order)}")
    paired = _paired(rows, order, scenarios, reference) if reference is not None else []
    summary = Summary(
        overall,
        by_scenario,
        list(skipped),
        paired,
        reference,
        sweep_points(rows, planners=order),
        dict(pairs),
        provenance=provenance,
    )
    return summary
