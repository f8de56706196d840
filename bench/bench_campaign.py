"""A robustness campaign (issue 39): a task on hundreds of seeds no test uses, under a named fault set
(`twin.faults`: nominal, stress), in parallel (local workers, or `--backend ray` on a cluster), and the loss
taxonomy of every object not placed (`twin.campaign.LOSS_CLASSES`) with the worst seeds and their first
failure. Each planner given is the task's transfer planner in turn (default: the config's own).

    python bench/bench_campaign.py --config robocup --faults stress --seeds 200 [--first-seed 1000]
        [--planner NAME | --planner '{name: croc, params: {mode: whole_arm}, label: croc-whole-arm}' ...]
        [--workers 2] [--backend local|ray] [--out DIR] [--resume] [--least 6]

Seeds from 1000 up are kept for campaigns: no test or tuning uses them. The runs go through `twin compare`'s
runner, so `--out DIR` (default out/campaign-<config>-<faults>) holds results.jsonl (a crash loses nothing
finished; `--resume` goes on) and campaign.json (the tables' numbers). A worst seed is reproduced with
`twin run CONFIG --seed N --faults NAME [--planner ...]`.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path
from typing import Any

import yaml

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from twin.campaign import campaign_spec, render, summarize  # noqa: E402
from twin.compare.runner import read_results, run_comparison  # noqa: E402
from twin.progress import ProgressClock  # noqa: E402


def _planner(text: str) -> dict[str, Any]:
    """A planner name, or a YAML flow mapping of a whole block (name, params, label)."""
    value = yaml.safe_load(text)
    if isinstance(value, str):
        return {"name": value}
    if not isinstance(value, dict) or "name" not in value:
        raise argparse.ArgumentTypeError(f"{text!r}: give a planner name or a mapping with a name")
    return value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="robocup", help="the task's config (a path or a shipped name)")
    ap.add_argument("--faults", default="nominal", help="the fault set (twin.faults)")
    ap.add_argument("--seeds", type=int, default=200)
    ap.add_argument("--first-seed", type=int, default=1000, help="seeds first-seed .. first-seed + seeds - 1")
    ap.add_argument("--planner", type=_planner, action="append", default=None, help="transfer planner(s)")
    ap.add_argument("--workers", type=int, default=None, help="runs at once (default: the CPUs)")
    ap.add_argument("--backend", choices=["local", "ray"], default="local")
    ap.add_argument("--out", default=None)
    ap.add_argument("--resume", action="store_true")
    ap.add_argument("--least", type=int, default=None, help="count the seeds that placed fewer objects than this")
    args = ap.parse_args()
    seeds = list(range(args.first_seed, args.first_seed + args.seeds))
    spec = campaign_spec(args.config, faults=args.faults, seeds=seeds, planners=args.planner)
    out = Path(args.out or f"out/{spec.name}")
    clock = ProgressClock()
    t0 = time.perf_counter()

    def progress(row: dict[str, Any], done: int, total: int) -> None:
        placed = sum(bool(o.get("placed")) for o in (row.get("task") or {}).get("objects", []))
        why = "" if row.get("success") else " - " + str(row.get("reason", ""))[:100]
        print(f"{clock.stamp(done, total)}  {row['planner']} seed {row['seed']}: {placed} placed{why}", flush=True)

    run_comparison(
        spec,
        out_dir=out,
        workers=args.workers,
        backend=args.backend,
        resume=args.resume,
        plots=False,
        on_row=progress,
    )
    wall = time.perf_counter() - t0
    rows = [r for r in read_results(out / "results.jsonl") if r["seed"] in set(seeds)]
    summaries = summarize(rows)
    print()
    print(
        f"campaign {spec.name}: {args.config}, fault set {args.faults}, seeds {seeds[0]}..{seeds[-1]},"
        f" {len(rows)} runs in {wall:.0f} s wall ({args.workers or 'all'} workers, {args.backend})"
    )
    print(render(summaries, least=args.least))
    (out / "campaign.json").write_text(
        json.dumps(
            {
                "config": args.config,
                "faults": args.faults,
                "seeds": [seeds[0], seeds[-1]],
                "wall_s": wall,
                "summaries": [s.to_json() for s in summaries],
            },
            indent=1,
        )
    )


if __name__ == "__main__":
    main()
