"""How long a sweep will take, said before it runs (`twin compare --dry-run`).

From what was measured where there is a measurement: the wall time a recorded sweep (the results.jsonl in the
output folder) took for the same run, else the mean of its runs of the same planner and scenario. Else a rough
figure per kind of run, said to be rough: a task run ~40 s (a whole sorting task in physics: 20 s for
robocup's eight objects on two cores, about a minute for warehouse's nmpc), a motion query ~1 s plus its
planning time limit (configs/compare-smoke.yaml: 26 queries with a 1 s limit in under a minute on 2 cores).
The runs' times are summed and shared among the workers; start-up, and workers left idle by a last long run,
make the real time longer.
"""

from __future__ import annotations

import os
import statistics
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.compare.spec import RunTask

__all__ = ["ROUGH_QUERY_OVERHEAD_S", "ROUGH_TASK_RUN_S", "SweepEstimate", "duration_text", "estimate_sweep"]

ROUGH_TASK_RUN_S = 40.0
ROUGH_QUERY_OVERHEAD_S = 1.0  # added to a query's time limit


@dataclass(frozen=True)
class SweepEstimate:
    """`wall_s`: the estimated time with `workers` runs at a time; `run_s`: the runs' own times, summed;
    `measured`: runs timed from the rows of `source` (their own row or their planner and scenario's mean),
    `rough`: runs given the rough figure of their kind."""

    wall_s: float
    run_s: float
    workers: int
    measured: int
    rough: int
    source: Path | None

    def describe(self) -> str:
        """'estimated time: ~12 min with 4 workers (26 runs, 41 min of run time; 26 timed from the rows of
        out/x/results.jsonl; start-up not counted)'."""
        basis = []
        if self.measured:
            basis.append(f"{self.measured} timed from the rows of {self.source}")
        if self.rough:
            where = "none like them" if self.measured else "no sweep recorded"
            where += f" in {self.source}" if self.source is not None else ""
            basis.append(
                f"{self.rough} at a rough figure ({where}: a task run ~{duration_text(ROUGH_TASK_RUN_S)}, a query"
                f" ~{duration_text(ROUGH_QUERY_OVERHEAD_S)} + its time limit)"
            )
        n = self.measured + self.rough
        return (
            f"estimated time: ~{duration_text(self.wall_s)} with {self.workers} worker{'s' * (self.workers != 1)}"
            f" ({n} runs, {duration_text(self.run_s)} of run time; {'; '.join(basis) or 'nothing to run'};"
            " start-up not counted)"
        )


def duration_text(seconds: float) -> str:
    """'40 s', '12 min', '2 h 08 min': a duration as a person reads an estimate."""
    s = max(0, int(round(seconds)))
    if s < 90:
        return f"{s} s"
    m = int(round(s / 60))
    return f"{m} min" if m < 60 else f"{m // 60} h {m % 60:02d} min"


def _wall_time(row: dict[str, Any]) -> float | None:
    t = (row.get("timing") or {}).get("wall_time_s")
    return float(t) if isinstance(t, int | float) and t >= 0 and row.get("status") != "skipped" else None


def estimate_sweep(
    runs: Sequence[RunTask], *, workers: int | None, recorded: Iterable[dict[str, Any]] = (), source: Path | None = None
) -> SweepEstimate:
    """The estimate for `runs` with `workers` at a time (None: the CPUs this process may use, as `run_comparison`
    takes), from the `recorded` rows of an earlier sweep where they hold the run or its planner and scenario, else
    from the rough figure of the run's kind."""
    own: dict[str, float] = {}
    by_cell: dict[tuple[str, str], list[float]] = {}
    for row in recorded:
        t = _wall_time(row)
        if t is not None:
            own[str(row.get("run_id"))] = t
            by_cell.setdefault((str(row.get("planner")), str(row.get("scenario"))), []).append(t)
    times: list[float] = []
    measured = 0
    for r in runs:
        cell = by_cell.get((r.planner_id, r.scenario))
        if r.run_id in own:
            times.append(own[r.run_id])
        elif cell:
            times.append(statistics.fmean(cell))
        else:
            times.append(ROUGH_TASK_RUN_S if r.kind == "task" else ROUGH_QUERY_OVERHEAD_S + r.time_limit_s)
            continue
        measured += 1
    if workers is None:
        workers = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    workers = max(1, workers)  # 0: in the CLI's own process, one at a time
    total = float(sum(times))
    wall = max(total / workers, max(times, default=0.0))  # no faster than its longest run
    return SweepEstimate(wall, total, workers, measured, len(times) - measured, source)
