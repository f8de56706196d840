"""The problem-set round trip (issue 16): export a problem set from each reference scene, plan it with
`twin compare` and with mplib (bench/mplib_driver.py, its own venv), and check both planned the same
problems. A plain script: prints numbers side by side, asserts nothing but the identity of the problems.

    python bench/bench_problems.py [--count 10] [--seed 0] [--planners ompl.rrtconnect,ompl.bitstar]
                                   [--out out/bench-problems] [--no-mplib]

Per scene: the problem file, then per planner the success rate, median / p95 planning time and median
trajectory duration; mplib's rows are its RRTConnect (+ shortcutting + TOPP-RA) on the same file, with
its paths re-checked by twin's FCL scene built from the same file every 0.002 rad. "same problems" means
the starts, goals (joint; pose as a 4x4) and obstacles (shape, size, pose) the driver read equal the ones
twin's compare rows carry, to 1e-12.
"""

from __future__ import annotations

import argparse
import json
import math
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from twin.compare import compare_spec_from_dict, run_comparison
from twin.config import load_config
from twin.problems import export_problem_set, load_problem_set, save_problem_set
from twin.problems.world import planning_scene, settings_for
from twin.transforms import pose_from_xyz_rpy

BENCH = Path(__file__).resolve().parent
sys.path.insert(0, str(BENCH))
from bench_ompl import mplib_python  # noqa: E402 - a sibling script, not a package

# scene -> (config, random-query settings): the blocked scenarios of configs/compare.yaml
SCENES: dict[str, tuple[str, dict[str, Any]]] = {
    "warehouse-blocked": ("warehouse", {"goal": "joint", "straight": "blocked"}),
    "robocup-blocked": (
        "robocup",
        {
            "goal": "joint",
            "straight": "blocked",
            "region_x": [-0.60, -0.05],
            "region_y": [-0.55, 0.55],
            "region_z": [0.05, 0.30],
            "min_clearance_m": 0.01,
        },
    ),
}
FINE_RAD = 0.002


def _stats(ok: list[bool], times: list[float], durations: list[float]) -> str:
    t = np.asarray(times, dtype=float)
    d = [v for v in durations if v is not None and math.isfinite(v)]
    return (
        f"{100 * np.mean(ok):5.1f}%  {1e3 * np.median(t):8.1f}  {1e3 * np.percentile(t, 95):8.1f}  "
        f"{np.median(d) if d else math.nan:6.2f}"
    )


def _query_pose(q: dict[str, Any]) -> np.ndarray:
    return pose_from_xyz_rpy(q["goal_pose"][:3], q["goal_pose"][3:])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--count", type=int, default=10, help="problems per scene")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--planners", default="ompl.rrtconnect,ompl.bitstar", help="comma-separated planner names")
    ap.add_argument("--out", default="out/bench-problems", help="folder for the problem files and the sweeps")
    ap.add_argument("--time-limit", type=float, default=1.0)
    ap.add_argument("--no-mplib", action="store_true")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    planners = [p.strip() for p in args.planners.split(",") if p.strip()]
    py = None if args.no_mplib else mplib_python()
    print(f"{args.count} problems per scene, seed {args.seed}, time limit {args.time_limit:g} s")
    print(f"  {'planner':30s} {'success':>7s}  {'med ms':>8s}  {'p95 ms':>8s}  {'dur s':>6s}")
    for name, (config, random) in SCENES.items():
        ps = export_problem_set(
            config, count=args.count, seed=args.seed, name=name, random=random, time_limit_s=args.time_limit
        )
        path = save_problem_set(ps, out / f"{name}.json")
        spec = compare_spec_from_dict(
            {"name": name, "planners": planners, "scenarios": [{"name": name, "problems": str(path.resolve())}]}
        )
        result = run_comparison(spec, out_dir=out / name, workers=None, plots=False)
        print(f"{name}: {path} ({len(ps.world.objects)} objects)")
        for p in planners:
            rows = [r for r in result.rows if r["planner"] == p]
            print(
                f"  {p:30s} "
                + _stats(
                    [bool(r["success"]) for r in rows],
                    [r["timing"]["planning_time_s"] or 0.0 for r in rows],
                    [r["metrics"]["duration_s"] for r in rows],
                )
            )
        if py is None or isinstance(py, str):
            print(f"  {'mplib':30s} unavailable: {py or 'skipped (--no-mplib)'}")
            continue
        run = subprocess.run(
            [str(py), str(BENCH / "mplib_driver.py"), "--problems", str(path)],
            capture_output=True,
            text=True,
            timeout=120 + 3 * args.time_limit * args.count,
            check=False,
        )
        if run.returncode != 0:
            print(f"  {'mplib':30s} driver failed: {run.stderr.strip().splitlines()[-3:]}")
            continue
        answer = json.loads(run.stdout.strip().splitlines()[-1])
        described = json.loads(
            subprocess.run(
                [sys.executable, str(BENCH / "mplib_driver.py"), "--problems", str(path), "--describe"],
                capture_output=True,
                text=True,
                check=True,
            ).stdout
        )
        rows = [r for r in result.rows if r["planner"] == planners[0]]
        same = all(
            np.allclose(q["start"], r["query"]["start"], atol=1e-12)
            and (
                np.allclose(q["goals"][0], r["query"]["goal"], atol=1e-12)
                if "goals" in q
                else np.allclose(q["goal_pose"], _query_pose(r["query"]), atol=1e-12)
            )
            for q, r in zip(described["queries"], rows, strict=True)
        )
        scene = planning_scene(load_problem_set(path), settings_for(ps, load_config(config)))
        oks, hits = [], 0
        for r in answer["results"]:
            q = np.asarray(r["q"], dtype=float)
            ok = bool(r["ok"]) and q.shape[0] > 0
            hit = bool(ok and not scene.check_path(q, resolution_rad=FINE_RAD).free)
            hits += hit
            oks.append(ok and not hit)
        durations = [(len(r["q"]) - 1) * 0.01 if r["ok"] else math.nan for r in answer["results"]]
        label = f"mplib {answer.get('mplib_version', '?')} RRTConnect"
        print(f"  {label:30s} " + _stats(oks, [r["time_s"] for r in answer["results"]], durations))
        print(f"  same problems in both: {same}; mplib paths colliding under the fine re-check: {hits}")


if __name__ == "__main__":
    main()
