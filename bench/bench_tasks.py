"""Task-run benchmark (issues 8, 15): success rate, simulated cycle time, and how fast a run is as a user
runs it: `twin run CONFIG --seed N --json` in a fresh process per seed (process start included), so the
real-time factor is simulated time / wall time of the whole command. Prints per config the median of each
stage of the run's time breakdown (`timings` in the --json file; twin.timing) beside the median total, and
the process's wall time from start to exit as the bench measures it (the run's own clock stops before the
interpreter's teardown).

    python bench/bench_tasks.py [--seeds 10] [--first-seed 0] [--planner NAME] [--config robocup ...]
        [--set KEY=VALUE ...]
        [--jobs N]

`--set` passes overrides to every run (fault models, e.g. `--set camera.noise.scale=3`); `--jobs` runs
that many seeds at once (for success rates: wall times then share the cores).

The seed-002 report: 100 % bottle/can/spam, 0/5 marker, mean cycle ~21.5 s simulated (~51 s wall).
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent


def run_once(config: str, seed: int, planner: str | None, overrides: tuple[str, ...] = ()) -> dict[str, Any]:
    """One `twin run` in its own process; its --json summary."""
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "run.json"
        cmd = [sys.executable, "-m", "twin", "run", config, "--seed", str(seed), "--json", str(out)]
        if planner:
            cmd += ["--planner", planner]
        for o in overrides:
            cmd += ["--set", o]
        t0 = time.perf_counter()
        r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
        process_wall = time.perf_counter() - t0
        if r.returncode not in (0, 1) or not out.exists():  # 1: an object was not placed, a result like any
            raise SystemExit(f"{' '.join(cmd)} failed: {r.stderr.strip().splitlines()[-3:]}")
        data: dict[str, Any] = json.loads(out.read_text())
        data["process_wall_s"] = process_wall  # the run's own clock stops before the interpreter's exit
        return data


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", action="append", default=None, help="config(s) to run (default: robocup, warehouse)")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first-seed", type=int, default=0, help="seeds first-seed .. first-seed + seeds - 1")
    ap.add_argument("--planner", default=None, help="transfer planner (default: the config's)")
    ap.add_argument("--set", action="append", default=[], metavar="KEY=VALUE", help="override a setting")
    ap.add_argument("--jobs", type=int, default=1, help="seeds run at once")
    args = ap.parse_args()
    for cfg in args.config or ["robocup", "warehouse"]:
        per_class: dict[str, list[bool]] = defaultdict(list)
        cycles, walls, sims, factors, process_walls = [], [], [], [], []
        stages: dict[str, list[float]] = defaultdict(list)
        t0 = time.perf_counter()
        planner = "?"
        with ThreadPoolExecutor(max(1, args.jobs)) as pool:
            seeds = range(args.first_seed, args.first_seed + args.seeds)
            jobs = [pool.submit(run_once, cfg, seed, args.planner, tuple(args.set)) for seed in seeds]
            runs = [j.result() for j in jobs]
        for seed, r in zip(seeds, runs, strict=True):
            planner = r["planner"]
            wall = r["command_wall_time_s"]
            walls.append(wall)
            process_walls.append(r["process_wall_s"])
            sims.append(r["sim_time_s"])
            factors.append(r["sim_time_s"] / wall)
            for k, v in r["timings"].items():
                stages[k].append(v)
            for o in r["objects"]:
                # the detection classes: cubes by colour (RoboCup's 8), as the seeds report them
                label = f"{o['class']}_{o['color']}" if o["class"] == "cube" and o.get("color") else o["class"]
                per_class[label].append(o["placed"])
                if o["placed"]:
                    cycles.append(o["cycle_time_s"])
            failed = [(o["id"], o["error"]) for o in r["objects"] if not o["placed"]]
            print(
                f"{cfg} seed {seed}: {r['success_rate']:.0%} placed, sim {r['sim_time_s']:.1f} s, "
                f"wall {wall:.2f} s ({r['sim_time_s'] / wall:.1f}x real time) {failed or ''}",
                flush=True,
            )
        allp = [p for v in per_class.values() for p in v]
        faults = ", " + " ".join(args.set) if args.set else ""
        print(f"\n{cfg} ({args.seeds} seeds, transfer planner {planner}{faults}):")
        print(f"  success rate {sum(allp) / len(allp):.1%} ({sum(allp)}/{len(allp)} objects)")
        for cls, v in sorted(per_class.items()):
            print(f"    {cls:15s} {sum(v)}/{len(v)}")
        if cycles:
            print(
                f"  mean simulated cycle time per placed object {statistics.mean(cycles):.1f} s"
                f" (median {statistics.median(cycles):.1f} s)"
            )
        print(
            f"  whole command: median {statistics.median(walls):.2f} s wall for {statistics.median(sims):.1f} s "
            f"simulated = {statistics.median(factors):.1f}x real time (min {min(factors):.1f}x); "
            f"bench total {time.perf_counter() - t0:.0f} s"
        )
        print(
            f"  process, start to exit: median {statistics.median(process_walls):.2f} s = "
            f"{statistics.median(s / w for s, w in zip(sims, process_walls, strict=True)):.1f}x real time"
        )
        print("  median seconds per stage:")
        for k, v in sorted(stages.items(), key=lambda kv: -statistics.median(kv[1])):
            print(f"    {k:28s} {statistics.median(v):6.3f}")
        print()


if __name__ == "__main__":
    main()
