"""Wall time of a whole `twin compare` sweep (issue 15), this checkout against another revision on the same
config, side by side in one run; and whether both sweeps wrote the same rows apart from their timings.

    python bench/bench_compare.py [--config compare] [--against REV] [--workers 2]

`--against REV` (a git revision, e.g. HEAD~5 or a tag) checks that revision out into a temporary worktree
and runs the same sweep there with this virtualenv (its packages and plugins first on the path). Without
it only this checkout is timed. Prints: runs, wall time, runs per second, and for two sweeps the speed-up
and the rows that differ (a row is its run id plus everything but `timing`; the optimising planners'
rows depend on wall-clock time only through their time limits, so a differing row is worth a look).
"""

from __future__ import annotations

import argparse
import json
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


def _same(a: dict[str, Any], b: dict[str, Any]) -> bool:
    """Whether two rows agree on every field both have (timings aside): a newer revision may add fields."""
    for k in a.keys() & b.keys() - {"timing", "run_id"}:
        if isinstance(a[k], dict) and isinstance(b[k], dict):
            if not _same(a[k], b[k]):
                return False
        elif a[k] != b[k]:
            return False
    return True


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="compare", help="comparison config (default: the full compare.yaml)")
    ap.add_argument("--against", default=None, metavar="REV", help="git revision to time on the same config")
    ap.add_argument("--workers", type=int, default=2)
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
        shutil.rmtree(tmp, ignore_errors=True)
    print(f"twin compare {args.config}, {args.workers} workers")
    print(f"  {'revision':20s} {'runs':>6s} {'wall s':>8s} {'runs/s':>7s}")
    for label, wall, rows in results:
        print(f"  {label:20s} {len(rows):6d} {wall:8.1f} {len(rows) / wall:7.2f}")
    if len(results) == 2:
        (_, w0, r0), (_, w1, r1) = results
        print(f"  speed-up: {w0 / w1:.2f}x")
        by_key = {(r["planner"], r["case"], r["seed"]): r for r in r0}
        differ = [k for r in r1 if not _same(by_key.get(k := (r["planner"], r["case"], r["seed"])) or {}, r)]
        example = f", e.g. {differ[:3]}" if differ else ""
        print(f"  rows that differ apart from timings: {len(differ)} of {len(r1)}{example}")


if __name__ == "__main__":
    main()
