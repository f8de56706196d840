"""Task-run benchmark (issue 8): success rate, mean simulated cycle time per object, wall time per run.

    python bench/bench_tasks.py [--seeds 10] [--planner NAME] [--config configs/robocup.yaml ...]

The seed-002 report: 100 % bottle/can/spam, 0/5 marker, mean cycle ~21.5 s simulated (~51 s wall).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from twin.config import load_config  # noqa: E402
from twin.tasks import run_task  # noqa: E402
from twin.tasks.cell import stage_block  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument(
        "--config", action="append", default=None, help="config(s) to run (default: both reference systems)"
    )
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--planner", default=None, help="transfer planner (default: the config's)")
    args = ap.parse_args()
    for cfg in args.config or ["configs/robocup.yaml", "configs/warehouse.yaml"]:
        settings = load_config(ROOT / cfg)
        per_class: dict[str, list[bool]] = defaultdict(list)
        cycles, walls, sims = [], [], []
        t0 = time.perf_counter()
        for seed in range(args.seeds):
            r = run_task(settings, seed=seed, planner=args.planner)
            walls.append(r.wall_time_s)
            sims.append(r.sim_time_s)
            for o in r.objects:
                per_class[o.cls].append(o.placed)
                if o.placed:
                    cycles.append(o.cycle_time_s)
            failed = [(o.id, o.error) for o in r.objects if not o.placed]
            print(
                f"{cfg} seed {seed}: {r.success_rate:.0%} placed, sim {r.sim_time_s:.1f} s, "
                f"wall {r.wall_time_s:.1f} s {failed or ''}",
                flush=True,
            )
        allp = [p for v in per_class.values() for p in v]
        print(f"\n{cfg} ({args.seeds} seeds, transfer planner {stage_block(settings, 'transfer', args.planner).name}):")
        print(f"  success rate {sum(allp) / len(allp):.1%} ({sum(allp)}/{len(allp)} objects)")
        for cls, v in sorted(per_class.items()):
            print(f"    {cls:15s} {sum(v)}/{len(v)}")
        if cycles:
            print(
                f"  mean simulated cycle time per placed object {statistics.mean(cycles):.1f} s"
                f" (median {statistics.median(cycles):.1f} s)"
            )
        print(
            f"  wall time per run: mean {statistics.mean(walls):.1f} s, simulated {statistics.mean(sims):.1f} s; "
            f"total {time.perf_counter() - t0:.0f} s\n"
        )


if __name__ == "__main__":
    main()
