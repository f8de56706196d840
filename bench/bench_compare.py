"""Wall time of a whole `twin compare` sweep (issue 15), this checkout against another revision on the same
config, side by side in one run; and whether both sweeps wrote the same rows apart from their timings.

    python bench/bench_compare.py [--config compare] [--against REV] [--workers 2] [--keep DIR]

`--against REV` (a git revision, e.g. HEAD~5 or a tag) checks that revision out into a temporary worktree
and runs the same sweep there with this virtualenv (its packages and plugins first on the path). Without
it only this checkout is timed. `--keep DIR` keeps both sweeps' results. Prints: runs, wall time, runs per
second, and for two sweeps the speed-up and the rows that differ (a row is its run id plus everything but
its wall-clock timings, floats compared to 1e-9 relative; the optimising planners' rows depend on wall-clock
time through their time limits, so they differ between any two sweeps), counted by the first field that
differs.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def sweep(checkout: Path, config: str, workers: int, out: Path) -> tuple[float, list[dict[str, Any]]]:
    """Run `twin compare` from `checkout`; (wall seconds, rows)."""
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(checkout), str(checkout / "plugins")]))
    t0 = time.perf_counter()
    r = subprocess.run(
        [sys.executable, "-m", "twin", "compare", config, "--out", str(out), "--workers", str(workers)],
        cwd=checkout,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    wall = time.perf_counter() - t0
    if r.returncode != 0:
        raise SystemExit(f"twin compare in {checkout} failed: {r.stderr.strip().splitlines()[-3:]}")
    rows = [json.loads(line) for line in (out / "results.jsonl").read_text().splitlines() if line.strip()]
    return wall, rows


# wall-clock measurements, at any depth of a row (a task run's per-planner metrics hold them too); simulated
# times (cycle_time_s, sim_time_s, duration_s) are results and compared
_WALL_CLOCK = {
    "timing",
    "timings",
    "run_id",
    "planning_time_s",
    "wall_time_s",
    "solve_time_median_s",
    "solve_time_max_s",
    "solve_times_s",
    "final_check_time_s",
}


def _difference(a: dict[str, Any], b: dict[str, Any], at: str = "") -> str | None:
    """The first field (dotted) on which two rows disagree among the fields both have, wall-clock timings
    aside (a newer revision may add fields), or None when they agree."""
    for k in sorted(a.keys() & b.keys() - _WALL_CLOCK):
        if isinstance(a[k], dict) and isinstance(b[k], dict):
            inner = _difference(a[k], b[k], f"{at}{k}.")
            if inner is not None:
                return inner
        elif a[k] != b[k] and not _close(a[k], b[k]):
            return f"{at}{k}: {a[k]!r} vs {b[k]!r}"
    return None


def _close(x: Any, y: Any) -> bool:
    """Floats equal to 1e-9 relative: the compiled kinematics and the numpy they replaced round the last bit
    differently, which a metric computed from thousands of samples may show."""
    if isinstance(x, float) and isinstance(y, float):
        return math.isclose(x, y, rel_tol=1e-9, abs_tol=1e-12)
    return False


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="compare", help="comparison config (default: the full compare.yaml)")
    ap.add_argument("--against", default=None, metavar="REV", help="git revision to time on the same config")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--keep", default=None, metavar="DIR", help="keep both sweeps' output directories here")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="bench-compare-"))
    results: list[tuple[str, float, list[dict[str, Any]]]] = []
    try:
        if args.against:
            wt = tmp / "against"
            subprocess.run(["git", "worktree", "add", "-f", "-q", str(wt), args.against], cwd=ROOT, check=True)
            try:
                results.append((args.against, *sweep(wt, args.config, args.workers, tmp / "out-against")))
            finally:
                subprocess.run(["git", "worktree", "remove", "--force", str(wt)], cwd=ROOT, check=False)
        results.append(("this checkout", *sweep(ROOT, args.config, args.workers, tmp / "out-here")))
    finally:
        if args.keep:
            for out in tmp.glob("out-*"):
                shutil.copytree(out, Path(args.keep) / out.name, dirs_exist_ok=True)
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"twin compare {args.config}, {args.workers} workers")
    print(f"  {'revision':20s} {'runs':>6s} {'wall s':>8s} {'runs/s':>7s}   summed run time s: tasks / queries")
    for label, wall, rows in results:
        task_s, query_s = (
            sum(r["timing"].get("wall_time_s") or 0.0 for r in rows if (r.get("kind") == "task") == is_task)
            for is_task in (True, False)
        )
        print(f"  {label:20s} {len(rows):6d} {wall:8.1f} {len(rows) / wall:7.2f}   {task_s:8.1f} / {query_s:8.1f}")
    if len(results) == 2:
        (_, w0, r0), (_, w1, r1) = results
        print(f"  speed-up: {w0 / w1:.2f}x")
        by_key = {(r["planner"], r["case"], r["seed"]): r for r in r0}
        differ = []
        for r in r1:
            k = (r["planner"], r["case"], r["seed"])
            why = _difference(by_key.get(k) or {}, r)
            if why is not None:
                differ.append((k, why))
        kinds = {(r["planner"], r["case"], r["seed"]): r.get("kind") for r in r1}
        n_task = sum(kinds[k] == "task" for k, _ in differ)
        print(
            f"  rows that differ apart from timings: {len(differ)} of {len(r1)} "
            f"({n_task} task runs, {len(differ) - n_task} queries)"
        )
        fields: dict[str, int] = {}
        for _, why in differ:
            fields[why.split(":")[0]] = fields.get(why.split(":")[0], 0) + 1
        for field, n in sorted(fields.items(), key=lambda kv: -kv[1]):
            example = next(f"{k}: {why}" for k, why in differ if why.split(":")[0] == field)
            print(f"    {field}: {n} rows, e.g. {example[:160]}")


if __name__ == "__main__":
    main()
