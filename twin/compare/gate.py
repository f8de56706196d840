"""A regression gate between two sweeps (`twin compare CONFIG --baseline OLD/results.jsonl`).

A planner plugin's CI reruns a comparison and wants one verdict: did any planner get worse than in the
baseline sweep? Why it works the way it does:

* runs are paired by run id, never by label: a run id hashes the whole run definition (planner block,
  scenario settings and loaded config, case, seed), so equal ids mean the same planner on the same problem
  and seed. Runs without a partner (a planner or scenario added or removed since) are counted and shown,
  and never fail the gate by themselves; a sweep that shares no run with its baseline is a ConfigError
  (a gate that compares nothing must not pass);
* per planner, over the paired runs only, three quantities are checked: the success rate, the p95 of
  the planning time and the p95 of the trajectory duration. A statistic is taken over the runs where
  both sides have the value (duration: runs successful in both sweeps; planning time: runs that finished
  a plan in both), so a planner that now also solves a hard query with a long trajectory is not
  reported as slower, and one that fails a query it solved before is reported once, by its success rate;
* a check regresses only when the difference is both real and large: significantly worse on the paired
  runs (`twin.compare.stats`' paired tests, two-sided p < SIGNIFICANCE = 0.05 and pointing to worse: the
  exact McNemar test on the runs that only one sweep solved, for success; the Wilcoxon signed-rank test
  on the log-ratios now/baseline of the paired runs, for a time: ranks, so one slow outlier weighs as
  one run, and ratios, so a 1 ms planner and a 1 s one count alike) AND beyond the tolerance's limit
  (`Tolerance`: how large a change matters). Neither alone: a p95 of four runs is their maximum, and one
  run that a busy neighbour slowed 3x moves it beyond any limit with no code change (issue 38: a rerun of
  the same commit on a busy machine "FAILED, 4 of 21 checks regressed"), while a significant 3 % is real
  but no reason to fail a CI job;
* a check with too few paired runs to judge says "not enough runs (n = 4; need >= 20)" and is never
  'regressed', whatever its values: success needs MIN_SUCCESS_RUNS = 6 paired runs, because the exact
  test reaches p < 0.05 only when at least 6 runs differ (6 of 6 lost: p = 2/2^6 = 0.031; 5 of 5: 0.0625,
  4 of 4: 0.125, so compare-smoke's 4 runs per planner cannot tell even a total loss from chance); a p95
  needs MIN_P95_RUNS = 20, the value one run in 20 exceeds: with fewer runs none is expected above it and
  the p95 is mostly the maximum (numpy's linear p95 of 4 runs is 0.15 x the 3rd + 0.85 x the 4th);
* the paired test removes per-run noise, not a sweep-wide shift: a sweep run while the machine was twice as
  loaded as during the baseline looks, to any test on its own numbers, like code twice as slow. That is
  what the loose planning-time tolerance (may double) and the environment lines below are for; success
  and duration are (nearly) deterministic for the same run id, so their limits stay tight (`Tolerance`);
* a sweep records where it ran (`twin.environment`, in the compare.json beside its results.jsonl), and the
  report names every difference that can move a result (twin commit, Python, a backend's version, CPU
  model, core count), so a slower p95 on another machine is not mistaken for a code regression. It never
  fails the gate: the verdict is about the numbers, the lines say what else changed;
* `check_shares_runs` is the same pairing before anything runs: the CLI asks the dry run's planner for the
  sweep's run ids, so an unrelated baseline is a ConfigError at once, not after the whole sweep.

Rows are the dicts of results.jsonl (`twin.compare.worker`); rows with status 'skipped' are no runs.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any, Literal

import numpy as np

from twin.compare.runner import RESULTS_FILE, latest_rows, read_results, recorded_environment
from twin.compare.stats import MIN_DISCORDANT, SIGNIFICANCE, is_tie, sign_test, signed_rank
from twin.compare.verdicts import p_text
from twin.environment import environment_changes
from twin.errors import ConfigError

__all__ = [
    "DEFAULT_TOLERANCE",
    "MIN_P95_RUNS",
    "MIN_SUCCESS_RUNS",
    "GateCheck",
    "GateReport",
    "Tolerance",
    "check_shares_runs",
    "gate",
    "load_baseline",
    "load_baseline_environment",
]

Quantity = Literal["success_rate", "planning_time_p95_s", "duration_p95_s"]
Verdict = Literal["ok", "regressed", "not_enough_runs", "n/a"]

# The fewest paired runs a check is judged on (below: "not enough runs", never a regression).
# Success: the exact two-sided McNemar p reaches SIGNIFICANCE only with MIN_DISCORDANT = 6 runs that differ
# (all lost: 2 / 2^6 = 0.031; with 5: 0.0625), so fewer than 6 paired runs can never show a real loss.
MIN_SUCCESS_RUNS = MIN_DISCORDANT
# A p95 is the value one run in 20 exceeds: below 20 runs none is expected above it, and the p95 is mostly
# the largest of the runs (numpy's linear p95 weighs the maximum 0.95 (n - 1) - (n - 2): 85 % at n = 4, 5 %
# at n = 20), which one run slowed by a busy machine moves as far as it likes. 20 >= MIN_DISCORDANT, so the
# paired test can reach significance too.
MIN_P95_RUNS = 20
_TINY_S = 1e-9  # a time of 0 s is taken as 1 ns in a log-ratio (stats.TIE_ABS: nothing below it is resolved)

# the keys of `Tolerance.parse` (as a user types them) and the fields they set
_KEYS: dict[str, str] = {
    "success": "success_drop",
    "planning_time": "planning_time",
    "planning_time_abs_s": "planning_time_abs_s",
    "duration": "duration",
}
_ALIASES: dict[str, str] = {"success_drop": "success_drop"}  # the field name works as well
_EXAMPLE = "success=0.05,planning_time=0.5,duration=0.1,planning_time_abs_s=0.01"
_EPS = 1e-9  # float noise: a value this close to its limit is within it


@dataclass(frozen=True)
class Tolerance:
    """How much worse than the baseline a planner may get before the gate fails: the practical half of the
    rule. A check also has to be significantly worse on the paired runs (`gate`), so a limit says how large
    a change matters, and the test whether it is more than noise.

    `success_drop`: absolute drop of the success rate allowed (0.05 = five percentage points). Default 0:
    a run id fixes the planner, the problem and the seed, so a run that succeeded in the baseline and fails
    now is a change in behaviour; the exact test decides whether the runs lost (against those gained) are
    more than a sampling planner's timing luck (an RRT that finds a path just inside its time limit on a
    fast machine may miss it on a loaded one). Raise it to let a real but small loss pass.

    `planning_time`: relative growth of the p95 planning time allowed (1.0 = may double). Default 1.0:
    planning time is wall-clock time, and CI machines are shared, throttled and differ from the one that
    made the baseline; a 2x slowdown is what a real regression (an algorithmic change, a lost cache, a
    debug build) looks like, while 30 % is an ordinary noisy neighbour.
    `planning_time_abs_s`: absolute slack added on top (seconds). Default 0.005: for planners that answer
    in about a millisecond, 1 ms -> 3 ms is scheduler noise, not a regression. The limit is
    `baseline_p95 * (1 + planning_time) + planning_time_abs_s`.

    `duration`: relative growth of the p95 trajectory duration allowed. Default 0.05: duration is
    deterministic for time-optimal retimers and analytic planners (any growth is a real change, so the
    limit stays tight), while sampling planners' paths vary with how far they got in their time; 5 % is
    above that jitter on the shipped scenarios and well below a planner that got worse. The limit is
    `baseline_p95 * (1 + duration)`.

    Each may be `inf` to leave a quantity ungated; none may be negative.
    """

    success_drop: float = 0.0
    planning_time: float = 1.0
    planning_time_abs_s: float = 0.005
    duration: float = 0.05

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or math.isnan(v) or v < 0:
                raise ConfigError(f"tolerance {f.name} must be a number >= 0 (or inf), got {v!r}")

    @classmethod
    def parse(cls, text: str) -> Tolerance:
        """A Tolerance from the CLI's `--tolerance` text: comma-separated `key=value` pairs, e.g.
        "success=0.05,planning_time=0.5,duration=0.1,planning_time_abs_s=0.01". Keys not given keep their
        defaults; a value may end in `%` ("duration=10%" is 0.1) or be `inf`. An unknown key, a repeated
        key or a bad number raises ConfigError (one line naming the allowed keys)."""
        allowed = ", ".join(_KEYS)
        values: dict[str, float] = {}
        for part in text.split(","):
            if not part.strip():
                continue
            key, sep, raw = part.partition("=")
            key, raw = key.strip(), raw.strip()
            name = _KEYS.get(key) or _ALIASES.get(key)
            if not sep or name is None:
                what = f"unknown key {key!r}" if sep else f"{part.strip()!r} is not key=value"
                raise ConfigError(f"--tolerance {text!r}: {what}; allowed keys: {allowed} (e.g. {_EXAMPLE!r})")
            if name in values:
                raise ConfigError(f"--tolerance {text!r}: {key!r} is given twice; allowed keys: {allowed}")
            try:
                v = float(raw[:-1]) / 100 if raw.endswith("%") else float(raw)
            except ValueError:
                v = math.nan
            if math.isnan(v) or v < 0:
                raise ConfigError(
                    f"--tolerance {text!r}: {key}={raw!r} is not a number >= 0; allowed keys: {allowed} "
                    f"(e.g. {_EXAMPLE!r})"
                )
            values[name] = v
        return cls(**values)

    def describe(self) -> str:
        """One line for a report: what each limit allows."""
        return (
            f"success may drop {_pp(self.success_drop)}, p95 planning time may grow "
            f"{_pct(self.planning_time)} + {_seconds(self.planning_time_abs_s)}, p95 duration may grow "
            f"{_pct(self.duration)}"
        )


DEFAULT_TOLERANCE = Tolerance()


@dataclass(frozen=True)
class GateCheck:
    """One planner, one quantity: baseline and current value over the same `n` paired runs, and `limit`,
    the worst current value allowed (the lowest success rate, or the highest p95 in seconds).

    The paired test on those runs: `worse` and `better` count the runs that got worse or better (successes
    lost and gained; runs slower or faster, trajectories longer or shorter; the rest tie), `p_value` is the
    two-sided p of the exact McNemar test (success) or of the Wilcoxon signed-rank test on the log-ratios
    now/baseline (times), None when fewer than MIN_DISCORDANT runs differ. `beyond`: the value is past its
    limit; `significant`: p < SIGNIFICANCE and the difference is a worsening. `min_n`: the fewest paired runs
    this quantity is judged on (MIN_SUCCESS_RUNS, MIN_P95_RUNS).

    `verdict`: 'regressed' when beyond and significant; 'not_enough_runs' when n < min_n (the values are
    shown, never judged); 'n/a' when there is nothing to compare (a planner with no successful paired run has
    no duration); else 'ok'."""

    planner: str
    quantity: Quantity
    baseline: float | None
    now: float | None
    limit: float | None
    verdict: Verdict
    n: int
    p_value: float | None = None
    worse: int = 0
    better: int = 0
    min_n: int = 0
    beyond: bool = False
    significant: bool = False

    @property
    def verdict_text(self) -> str:
        """The verdict as the table shows it: 'REGRESSED', 'not enough runs (n = 4; need >= 20)', 'ok' (or
        'ok: not significant' beyond the limit, 'ok: within tolerance' significantly worse), 'n/a'."""
        if self.verdict == "regressed":
            return "REGRESSED"
        if self.verdict == "not_enough_runs":
            return f"not enough runs (n = {self.n}; need >= {self.min_n})"
        if self.verdict == "ok" and self.beyond:
            return "ok: not significant"
        if self.verdict == "ok" and self.significant:
            return "ok: within tolerance"
        return self.verdict

    @property
    def test_text(self) -> str:
        """The paired test in words: 'exact McNemar p = 0.031', 'Wilcoxon signed-rank p < 0.001', or why
        there is no p."""
        differ = self.worse + self.better
        if self.p_value is None:
            return "no run differs" if not differ else f"no test: {differ} differ, fewer than {MIN_DISCORDANT}"
        test = "exact McNemar" if self.quantity == "success_rate" else "Wilcoxon signed-rank on log-ratios"
        return f"{test} {p_text(self.p_value)}"

    @property
    def change(self) -> float | None:
        """Success rate: the absolute change (-0.25 = 25 points lower). Times: the relative change
        (0.3 = 30 % longer), None when the baseline is 0 or a value is missing."""
        if self.baseline is None or self.now is None:
            return None
        if self.quantity == "success_rate":
            return self.now - self.baseline
        return None if self.baseline == 0 else self.now / self.baseline - 1.0

    def to_json(self) -> dict[str, Any]:
        return {**asdict(self), "change": self.change}


@dataclass(frozen=True)
class GateReport:
    """The gate's outcome: a check per (planner, quantity), how many runs were paired, and how many had
    no partner (only in this sweep / only in the baseline: reported, never failing by themselves).
    `environment_changes`: one line per difference between where the baseline ran and where this sweep
    ran (`twin.environment.environment_changes`), or a line saying the baseline recorded none;
    `environment_compared`: both records were there to compare. Neither changes the verdict."""

    checks: list[GateCheck]
    matched: int
    only_new: int
    only_baseline: int
    tolerance: Tolerance = field(default=DEFAULT_TOLERANCE)
    environment_changes: list[str] = field(default_factory=list)
    environment_compared: bool = False

    @property
    def passed(self) -> bool:
        """True when no check regressed."""
        return not self.regressions

    @property
    def regressions(self) -> list[GateCheck]:
        return [c for c in self.checks if c.verdict == "regressed"]

    @property
    def not_judged(self) -> list[GateCheck]:
        """The checks with too few paired runs to judge (shown, never failing)."""
        return [c for c in self.checks if c.verdict == "not_enough_runs"]

    def render(self) -> str:
        """A markdown table (readable as plain text in a CI log, rendered in a job summary) with a verdict
        line above it, each check's n, paired counts, p and verdict in it, the rule and each regression spelled
        out below it."""
        bad = self.regressions
        head = (
            f"regression gate: FAILED, {len(bad)} of {len(self.checks)} checks regressed"
            if bad
            else f"regression gate: passed, none of {len(self.checks)} checks regressed"
        )
        unjudged = self.not_judged
        if unjudged:
            head += f" ({len(unjudged)} not judged: not enough runs)"
        lines = [
            head,
            f"runs compared: {self.matched} in both sweeps, {self.only_new} only in this sweep, "
            f"{self.only_baseline} only in the baseline (unpaired runs are not checked)",
            f"tolerance: {self.tolerance.describe()}",
            *self._environment_lines(),
            "",
        ]
        header = ["planner", "quantity", "n", "baseline", "now", "change", "limit", "worse/better", "p", "verdict"]
        right = {2, 3, 4, 5, 6, 7, 8}
        body = [
            [
                c.planner.replace("|", "\\|"),
                c.quantity,
                str(c.n),
                *_cells(c),
                "-" if c.verdict == "n/a" else f"{c.worse}/{c.better}",
                _p_cell(c),
                c.verdict_text,
            ]
            for c in self.checks
        ]
        widths = [max(len(r[i]) for r in [header, *body]) for i in range(len(header))]

        def row(cells: list[str]) -> str:
            return (
                "| "
                + " | ".join(
                    c.rjust(w) if i in right else c.ljust(w) for i, (c, w) in enumerate(zip(cells, widths, strict=True))
                )
                + " |"
            )

        lines.append(row(header))
        lines.append(
            "|" + "|".join("-" * (w + 1) + ":" if i in right else "-" * (w + 2) for i, w in enumerate(widths)) + "|"
        )
        lines += [row(r) for r in body]
        lines += [
            "",
            f"a check regresses when its value is beyond the limit AND the paired runs are significantly worse "
            f"(two-sided p < {SIGNIFICANCE:g}; success: exact McNemar test on the runs one sweep solved and the "
            "other did not; times: Wilcoxon signed-rank test on the log-ratios now/baseline); worse/better: paired "
            f"runs that got worse/better; judged from {MIN_SUCCESS_RUNS} paired runs (success) and "
            f"{MIN_P95_RUNS} (a p95) on",
        ]
        if bad:
            lines += ["", "regressions:"]
            for c in bad:
                base, now, _, limit = _cells(c)
                lines.append(
                    f"- {c.planner}: {_LABEL[c.quantity]} {base} -> {now} (limit {limit}, n={c.n}, {c.worse} "
                    f"{_WORSE[c.quantity]}, {c.better} {_BETTER[c.quantity]}, {c.test_text})"
                )
        return "\n".join(lines) + "\n"

    def _environment_lines(self) -> list[str]:
        if self.environment_compared and not self.environment_changes:
            return ["environment: as the baseline's (twin commit, Python, backends, CPU model, cores)"]
        if not self.environment_compared:
            return self.environment_changes
        return [
            "environment changed since the baseline (the verdict stands; a timing change may come from this, "
            "not from the code):",
            *(f"- {line}" for line in self.environment_changes),
        ]

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict: passed, the run counts, the tolerance, every check (with its change) and what
        changed in the environment."""
        return {
            "passed": self.passed,
            "matched": self.matched,
            "only_new": self.only_new,
            "only_baseline": self.only_baseline,
            "tolerance": asdict(self.tolerance),
            "checks": [c.to_json() for c in self.checks],
            "environment_compared": self.environment_compared,
            "environment_changes": list(self.environment_changes),
        }


_LABEL: dict[str, str] = {
    "success_rate": "success rate",
    "planning_time_p95_s": "p95 planning time",
    "duration_p95_s": "p95 duration",
}
_WORSE = {"success_rate": "lost", "planning_time_p95_s": "slower", "duration_p95_s": "longer"}
_BETTER = {"success_rate": "gained", "planning_time_p95_s": "faster", "duration_p95_s": "shorter"}


# ---- the gate -------------------------------------------------------------------------------------
def _baseline_file(path: str | Path) -> Path:
    p = Path(path)
    return p / RESULTS_FILE if p.is_dir() and (p / RESULTS_FILE).is_file() else p


def load_baseline(path: str | Path) -> list[dict[str, Any]]:
    """The rows of a baseline sweep: its results.jsonl, or the output folder that holds one. A missing
    file, or one that holds no result rows, raises ConfigError in one line."""
    p = _baseline_file(path)
    if not p.is_file():
        what = "is a folder without a " + RESULTS_FILE if p.is_dir() else "does not exist"
        raise ConfigError(f"baseline {p} {what}; pass the {RESULTS_FILE} of an earlier `twin compare` run")
    try:
        rows = read_results(p)
    except OSError as e:
        raise ConfigError(f"cannot read the baseline {p}: {e.strerror}") from None
    except ConfigError as e:
        raise ConfigError(f"baseline {p} is not a {RESULTS_FILE} of `twin compare`: {e}") from None
    if not rows:
        raise ConfigError(
            f"baseline {p} holds no result rows; pass the {RESULTS_FILE} of an earlier `twin compare` run"
        )
    for i, r in enumerate(rows, 1):
        missing = [k for k in ("planner", "success") if k not in r]
        if missing:
            raise ConfigError(f"baseline {p}: row {i} has no {missing[0]!r}: not a {RESULTS_FILE} of `twin compare`")
    return rows


def load_baseline_environment(path: str | Path) -> dict[str, Any] | None:
    """Where the baseline ran: the environment recorded in the compare.json beside its results.jsonl
    (`path` as `load_baseline` takes it); None when there is none."""
    return recorded_environment(_baseline_file(path))


def check_shares_runs(baseline_rows: Iterable[dict[str, Any]], run_ids: Iterable[str], *, baseline: str | Path) -> int:
    """How many of the sweep's `run_ids` the baseline holds (its 'skipped' rows are no runs); ConfigError in
    one line, naming the baseline and both counts, when it holds none: a gate that compares nothing must
    not pass, and this says so before the sweep runs rather than after it."""
    ids = set(run_ids)
    old = {r.get("run_id") for r in latest_rows(baseline_rows) if r.get("status") != "skipped"}
    shared = len(ids & old)
    if not shared:
        raise ConfigError(
            f"baseline {baseline} shares no run with this sweep: none of its {len(old)} run ids is among this "
            f"sweep's {len(ids)} (a run id hashes the planner block, scenario, scene config and seed); was it "
            "made from another config?"
        )
    return shared


def gate(
    rows: Iterable[dict[str, Any]],
    baseline_rows: Iterable[dict[str, Any]],
    tolerance: Tolerance = DEFAULT_TOLERANCE,
    *,
    environment: Mapping[str, Any] | None = None,
    baseline_environment: Mapping[str, Any] | None = None,
) -> GateReport:
    """Compare this sweep's rows with a baseline's, run id by run id (the last row of each id on each
    side; 'skipped' rows are no runs), and check per planner, over the paired runs: the success rate
    (may drop by `tolerance.success_drop`), the p95 planning time over runs that finished a plan on both
    sides, and the p95 duration over runs successful on both sides (may grow as `Tolerance` says). A check
    regresses when it is beyond that limit and its paired test says the runs got significantly worse; with
    fewer than MIN_SUCCESS_RUNS (success) or MIN_P95_RUNS (a p95) paired runs it is 'not_enough_runs'.

    `environment`, `baseline_environment`: where each sweep ran (`twin.environment.environment()`
    records); the report lists what differs, or says that the baseline recorded nothing, and the verdict
    does not depend on it. Planners are checked in the order they first appear in `rows`. Raises
    ConfigError when no run id of this sweep is in the baseline."""
    new = {r["run_id"]: r for r in latest_rows(rows) if r.get("status") != "skipped"}
    old = {r["run_id"]: r for r in latest_rows(baseline_rows) if r.get("status") != "skipped"}
    paired = [rid for rid in new if rid in old]
    if not paired:
        raise ConfigError(
            f"no run of this sweep is in the baseline: none of its {len(new)} run ids is among the baseline's "
            f"{len(old)} (a run id hashes the planner block, scenario, scene config and seed); was it made "
            "from another config?"
        )
    planners = list(dict.fromkeys(str(new[rid].get("planner")) for rid in paired))
    checks: list[GateCheck] = []
    for planner in planners:
        pairs = [(old[rid], new[rid]) for rid in paired if str(new[rid].get("planner")) == planner]
        checks.append(_success_check(planner, pairs, tolerance))
        timed = [
            (t0, t1)
            for o, n in pairs
            if (t0 := _num(o, "timing", "planning_time_s")) is not None
            and (t1 := _num(n, "timing", "planning_time_s")) is not None
        ]
        checks.append(
            _growth_check(planner, "planning_time_p95_s", timed, tolerance.planning_time, tolerance.planning_time_abs_s)
        )
        durations = [
            (d0, d1)
            for o, n in pairs
            if o.get("success")
            and n.get("success")
            and (d0 := _num(o, "metrics", "duration_s")) is not None
            and (d1 := _num(n, "metrics", "duration_s")) is not None
        ]
        checks.append(_growth_check(planner, "duration_p95_s", durations, tolerance.duration, 0.0))
    compared = environment is not None and baseline_environment is not None
    changes = environment_changes(baseline_environment, environment) if compared else []
    if environment is not None and baseline_environment is None:
        changes = [
            "environment: the baseline recorded none (no compare.json beside it, or made by an older twin), so a "
            "timing change may come from the machine or the backends as well as from the code"
        ]
    return GateReport(
        checks=checks,
        matched=len(paired),
        only_new=len(new) - len(paired),
        only_baseline=sum(1 for rid in old if rid not in new),
        tolerance=tolerance,
        environment_changes=changes,
        environment_compared=compared,
    )


def _num(row: dict[str, Any], group: str, key: str) -> float | None:
    v = (row.get(group) or {}).get(key)
    if v is None or isinstance(v, bool):
        return None
    try:
        x = float(v)
    except (TypeError, ValueError):
        return None
    return x if math.isfinite(x) else None


def _verdict(n: int, min_n: int, beyond: bool, significant: bool) -> Verdict:
    """The rule: too few runs are never judged; a regression is beyond the limit AND significantly worse."""
    if n < min_n:
        return "not_enough_runs"
    return "regressed" if beyond and significant else "ok"


def _success_check(planner: str, pairs: list[tuple[dict[str, Any], dict[str, Any]]], tol: Tolerance) -> GateCheck:
    """The success rate over the paired runs; its test: the exact McNemar test (`stats.sign_test`) on the
    runs solved in the baseline only (lost) against those solved now only (gained)."""
    n = len(pairs)
    lost = sum(1 for o, r in pairs if o.get("success") and not r.get("success"))
    gained = sum(1 for o, r in pairs if r.get("success") and not o.get("success"))
    before = sum(1 for o, _ in pairs if o.get("success")) / n
    now = sum(1 for _, r in pairs if r.get("success")) / n
    limit = max(0.0, before - tol.success_drop)
    beyond = now < limit - _EPS
    p = sign_test(gained, lost)
    significant = p is not None and p < SIGNIFICANCE and lost > gained
    verdict = _verdict(n, MIN_SUCCESS_RUNS, beyond, significant)
    return GateCheck(
        planner, "success_rate", before, now, limit, verdict, n, p, lost, gained, MIN_SUCCESS_RUNS, beyond, significant
    )


def _p95(values: np.ndarray) -> float:
    return float(np.percentile(values, 95))  # linear, as summary.md's p95


def _log_ratio_test(before: np.ndarray, now: np.ndarray) -> tuple[int, int, float | None, bool]:
    """The paired test of a time: the Wilcoxon signed-rank test (`stats.signed_rank`) on log(now / before),
    pairs that `stats.is_tie` calls equal counted as ties. Returns the runs slower now, the runs faster now,
    the two-sided p (None below MIN_DISCORDANT runs that differ) and whether the signed ranks lean to slower
    (the side a small p is about)."""
    from scipy.stats import rankdata

    tie = is_tie(now, before)
    ratio = np.where(tie, 0.0, np.log(np.maximum(now, _TINY_S)) - np.log(np.maximum(before, _TINY_S)))
    zero = np.zeros_like(ratio)
    t = signed_rank(ratio, zero)  # a 'win' is a lower log-ratio: faster now
    d = ratio[~is_tie(ratio, zero)]
    ranks = rankdata(np.abs(d))
    slower = float(ranks[d > 0].sum()) > float(ranks[d < 0].sum())
    return t.losses, t.wins, t.p_value, slower


def _growth_check(
    planner: str, quantity: Quantity, pairs: list[tuple[float, float]], rel: float, abs_s: float
) -> GateCheck:
    """The p95 of a time over the paired runs against `before * (1 + rel) + abs_s`; its test: the Wilcoxon
    signed-rank test on the paired log-ratios (`_log_ratio_test`)."""
    if not pairs:
        return GateCheck(planner, quantity, None, None, None, "n/a", 0, min_n=MIN_P95_RUNS)
    a = np.array(pairs, dtype=float)
    before, now = _p95(a[:, 0]), _p95(a[:, 1])
    limit = math.inf if math.isinf(rel) else before * (1.0 + rel) + abs_s
    beyond = now > limit + _EPS * max(1.0, abs(limit))
    slower, faster, p, leans_slower = _log_ratio_test(a[:, 0], a[:, 1])
    significant = p is not None and p < SIGNIFICANCE and leans_slower
    verdict = _verdict(len(pairs), MIN_P95_RUNS, beyond, significant)
    return GateCheck(
        planner, quantity, before, now, limit, verdict, len(pairs), p, slower, faster, MIN_P95_RUNS, beyond, significant
    )


# ---- formatting -----------------------------------------------------------------------------------
def _pp(x: float) -> str:
    return "any amount" if math.isinf(x) else f"{100 * x:.3g} points"


def _pct(x: float) -> str:
    return "without limit" if math.isinf(x) else f"{100 * x:.3g}%"


def _seconds(v: float) -> str:
    if math.isinf(v):
        return "inf"
    a = abs(v)
    if a == 0:
        return "0 s"
    if a < 1e-3:
        return f"{v * 1e6:.3g} us"
    if a < 1:
        return f"{v * 1e3:.3g} ms"
    return f"{v:.3g} s"


def _p_cell(c: GateCheck) -> str:
    """The p column: the p-value, or '-' (n/a, or fewer than MIN_DISCORDANT runs differ: no test)."""
    if c.p_value is None:
        return "-"
    return "<0.001" if c.p_value < 1e-3 else f"{c.p_value:.3f}"


def _cells(c: GateCheck) -> tuple[str, str, str, str]:
    """(baseline, now, change, limit) of a check as table cells."""
    if c.quantity == "success_rate":

        def rate(v: float | None) -> str:
            return "-" if v is None else f"{100 * v:.0f}% ({round(v * c.n)}/{c.n})"

        ch = c.change
        change = "-" if ch is None else f"{100 * ch:+.0f} pp"
        limit = "-" if c.limit is None else f">= {100 * c.limit:.0f}%"
        return rate(c.baseline), rate(c.now), change, limit
    ch = c.change
    change = "-" if ch is None else f"{100 * ch:+.1f}%" if abs(ch) < 0.1 else f"{100 * ch:+.0f}%"
    if ch is None and c.baseline is not None and c.now is not None:
        change = f"+{_seconds(c.now - c.baseline)}"
    limit = "-" if c.limit is None else f"<= {_seconds(c.limit)}"
    b = "-" if c.baseline is None else _seconds(c.baseline)
    n = "-" if c.now is None else _seconds(c.now)
    return b, n, change, limit
