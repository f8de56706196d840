"""Planner comparisons (`twin compare`): planners x scenarios x seeds, measured the same way, resumable.

    from twin.compare import run_comparison
    result = run_comparison("configs/compare-smoke.yaml", out_dir="results/smoke", workers=2)
    result.summary.overall[0].success_rate
    plan_comparison("configs/compare.yaml").per_planner()     # check and count, run nothing (--dry-run)

Modules: `spec` (the config model and the run list), `metrics` (what one run measures), `worker` (one
run, the function every backend executes), `runner` (the sweep, results.jsonl, resume, backends),
`report` (summary.csv, summary.md, rich table; sweep.csv per swept level), `plots` (PNG, sweep_<key>.png per
swept key; the only matplotlib user), `stats` (bootstrap and Wilson intervals, paired tests), `latex` (the
summary as a booktabs table for a paper: `twin report --latex`).
Importing this package loads neither PyBullet, FCL, Ray nor matplotlib.
"""

from __future__ import annotations

from twin.compare.runner import (
    CompareResult,
    DryRun,
    check_spec,
    latest_rows,
    plan_comparison,
    read_results,
    run_comparison,
)
from twin.compare.spec import (
    CompareSpec,
    RunTask,
    compare_spec_from_dict,
    expand_runs,
    load_compare_config,
    run_id,
    run_key,
)

__all__ = [
    "CompareResult",
    "CompareSpec",
    "DryRun",
    "RunTask",
    "check_spec",
    "compare_spec_from_dict",
    "expand_runs",
    "latest_rows",
    "load_compare_config",
    "plan_comparison",
    "read_results",
    "run_comparison",
    "run_id",
    "run_key",
]
