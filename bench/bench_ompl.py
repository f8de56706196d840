"""Benchmark of the OMPL planners (issue 5), and the same queries planned by mplib. A plain script: prints
numbers, asserts nothing.

    python bench/bench_ompl.py [--queries 20] [--time-limit 1.0] [--planners ompl.rrtconnect,ompl.prm]
                               [--straight blocked|free|any] [--no-mplib] [--no-limits]

Queries: seeded random top-down TCP poses, drawn by `twin_ompl.scenarios` as in tests/test_ompl.py.
RoboCup scene: table <-> table and table <-> inside a bin; warehouse scene: carrying a 50 mm cube from
behind the (perceived) obstacle box to the robot's side of it or back. Half joint goals, half pose goals.
By default only queries whose straight joint motion collides are kept (`--straight blocked`; `any` keeps
every query, `--all-queries` is its old name), so every planner has to search. The issue's speed number
(RRT-Connect solves >= 99 % within 1 s) is the success column of `ompl.rrtconnect` at the default
`--time-limit 1.0`; the tests check success and correctness only, with a generous cap.

First, the time limits (moved here from tests/test_ompl.py, which asserts no wall-clock time): how long
infeasible queries take to be rejected (the issue: well under 0.2 s, before any sampling) and how far past
its limit a query without a path returns (the issue: within 50 ms), printed beside those budgets.

Prints per planner and scene: success rate, median / p95 planning time (everything `plan()` does:
checks, sampling, shortcutting, retiming, the final fine check), median path length (joint-space L2, rad)
and trajectory duration, and how many returned trajectories an independent FCL check every 0.002 rad /
1 mm of TCP travel finds colliding. `ompl.rrtconnect (no final check)` is the same planner without its
clearance and final check, which is what mplib does.

mplib (OMPL RRTConnect + FCL + TOPP-RA in C++) pins numpy < 2, so it lives in its own virtual environment,
bench/.mplib-venv (created here on first use with `python -m venv` + `pip install mplib`; it ignores
itself in git), and plans through bench/mplib_driver.py in a subprocess: same URDF, the self-collision
pairs our scene excludes (as an SRDF), the cell's boxes, the held cube, the same start and goal
configurations (a pose goal's collision-free IK solutions) and time limit. Its trajectories are checked
with the same fine FCL check. Printed last: median planning time of ompl.rrtconnect / median of mplib,
and issue 14's goals (median <= 0.5x and p95 <= 1.0x mplib at range 1, no collision under the fine
re-check, success >= mplib's).

`--before` plans every query twice, with `collision.sphere_filter` off (FCL checks every configuration, as
before issue 14) and on, and prints both side by side per planner with the speed-up and whether the plans
are the same (they must be: the filter changes what a check costs, never its answer).
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np

from twin.config import PlannerBlock
from twin.errors import DependencyMissing
from twin.planning import first_collision, make_planner, plan_with
from twin.registry import Kind
from twin.robot.urdf_model import pose_from_xyz_rpy, read_fixture_shapes
from twin.types import JointGoal, MotionRequest, Pose, PoseGoal
from twin_ompl.scenarios import QueryCell as Cell
from twin_ompl.scenarios import top_down

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
MPLIB_VENV = BENCH / ".mplib-venv"
FINE_RAD, FINE_M = 0.002, 0.002


# ---- time limits (the clock half of tests/test_ompl.py) ------------------------------------------------------
FAIL_FAST_BUDGET_S = 0.2
TIMEOUT_OVERSHOOT_S = 0.05


def bench_limits(warehouse: Cell, repeats: int = 5) -> None:
    """Print how fast infeasible queries are rejected and how punctually a query without a path times out."""
    planner = make_planner(PlannerBlock(name="ompl.rrtconnect"), warehouse.ctx)
    start = warehouse.queries(1, seed=11, straight="any")[0][0]
    inside = top_down(-0.42, 0.24, 0.10, 0.0)  # the TCP (and the cube) inside the obstacle box
    q_inside = warehouse.kin.ik(inside, all_wraps=False)[0]
    lim = warehouse.limits
    cases = [
        ("joint goal in the obstacle", MotionRequest(start, JointGoal(q_inside), lim, time_limit_s=1.0)),
        ("pose goal in the obstacle", MotionRequest(start, PoseGoal(Pose.from_matrix(inside)), lim, time_limit_s=1.0)),
        (
            "pose goal out of reach",
            MotionRequest(start, PoseGoal(Pose.from_matrix(top_down(-1.6, 0.0, 0.2, 0.0))), lim),
        ),
        ("start in collision", MotionRequest(q_inside, JointGoal(start), lim)),
        (
            "joint goal outside the limits",
            MotionRequest(start, JointGoal(np.array([0.0, -1.0, 3.5, 0.0, 0.0, 0.0])), lim),
        ),
    ]
    print(f"infeasible queries, ompl.rrtconnect (budget {FAIL_FAST_BUDGET_S * 1e3:.0f} ms), best / worst of {repeats}:")
    for label, req in cases:
        times, status = [], ""
        for _ in range(repeats):
            res = plan_with(planner, req, warehouse.scene, warehouse.ctx)
            times.append(res.planning_time_s)
            status = res.status.value
        flag = "ok" if max(times) < FAIL_FAST_BUDGET_S else "SLOW"
        print(f"  {label:32s} {status:14s} {min(times) * 1e3:7.2f} / {max(times) * 1e3:7.2f} ms  {flag}")

    cell = Cell("robocup")  # tall walls along y = 0 on both sides of the base: no path from y > 0 to y < 0
    for name, x in (("wall_front", (-1.2, -0.14)), ("wall_back", (0.14, 1.2))):
        cell.scene.add_box_bounds(name, (x[0], -0.01, -0.5), (x[1], 0.01, 2.5))
    a = cell.ik_near_home(top_down(-0.45, 0.25, 0.2, 0.0))
    b = cell.ik_near_home(top_down(-0.45, -0.25, 0.2, 0.0))
    if a is None or b is None:
        print("  (no query without a path: IK failed)")
        return
    walled = make_planner(PlannerBlock(name="ompl.rrtconnect"), cell.ctx)
    print(f"query without a path (allowed overshoot {TIMEOUT_OVERSHOOT_S * 1e3:.0f} ms):")
    for limit in (0.25, 0.5, 1.0):
        res = plan_with(walled, MotionRequest(a, JointGoal(b), cell.limits, time_limit_s=limit), cell.scene, cell.ctx)
        over = res.planning_time_s - limit
        flag = "ok" if over <= TIMEOUT_OVERSHOOT_S else "LATE"
        print(
            f"  limit {limit:4.2f} s: "
            f"{res.status.value:8s} after {res.planning_time_s:6.3f} s (overshoot {over * 1e3:+6.1f} ms)  {flag}"
        )


# ---- our planners ------------------------------------------------------------------------------------------
def fine_collides(cell: Cell, traj: Any) -> bool:
    return first_collision(traj, cell.scene, cell.kin, max_step_rad=FINE_RAD, max_step_m=FINE_M) is not None


def run_ours(cell: Cell, block: PlannerBlock, queries: list[Any], time_limit: float) -> dict[str, Any] | str:
    try:
        planner = make_planner(block, cell.ctx)
    except DependencyMissing as e:
        return str(e).split(". ")[0]
    rows = []
    for k, (start, goal, _) in enumerate(queries):
        req = MotionRequest(start, goal, cell.limits, time_limit_s=time_limit, seed=k)
        res = plan_with(planner, req, cell.scene, cell.ctx)
        ok = res.success
        rows.append(
            {
                "ok": ok,
                "time_s": res.planning_time_s,
                "length": float(res.info.get("path_length_rad", math.nan)) if ok else math.nan,
                "duration": res.trajectory.duration if ok and res.trajectory is not None else math.nan,
                "fine_hit": bool(ok and fine_collides(cell, res.trajectory)),
                "status": res.status.value,
            }
        )
    return summarize(rows)


def summarize(rows: list[dict[str, Any]]) -> dict[str, Any]:
    t = np.array([r["time_s"] for r in rows])
    ok = np.array([r["ok"] for r in rows])
    length = np.array([r["length"] for r in rows])
    dur = np.array([r["duration"] for r in rows])
    failures: dict[str, int] = {}
    for r in rows:
        if not r["ok"]:
            failures[r["status"]] = failures.get(r["status"], 0) + 1
    return {
        "n": len(rows),
        "success": float(ok.mean()) if rows else math.nan,
        "median_s": float(np.median(t)) if rows else math.nan,
        "p95_s": float(np.percentile(t, 95)) if rows else math.nan,
        "length": float(np.nanmedian(length)) if ok.any() else math.nan,
        "duration": float(np.nanmedian(dur)) if ok.any() else math.nan,
        "fine_hits": int(sum(r["fine_hit"] for r in rows)),
        "failures": failures,
        "times": t.tolist(),
        "durations": dur.tolist(),
    }


def print_row(label: str, s: dict[str, Any] | str) -> None:
    if isinstance(s, str):
        print(f"  {label:34s} unavailable: {s}")
        return
    fails = ", ".join(f"{k} {v}" for k, v in sorted(s["failures"].items()))
    print(
        f"  {label:34s} {s['success'] * 100:5.1f}%  {s['median_s'] * 1e3:7.1f}  {s['p95_s'] * 1e3:7.1f}"
        f"  {s['length']:6.2f}  {s['duration']:5.2f}  {s['fine_hits']:3d}  {fails}"
    )


# ---- mplib --------------------------------------------------------------------------------------------------
def mplib_python() -> Path | str:
    """The mplib venv's python, created on first use; or a string saying why it is unavailable."""
    py = MPLIB_VENV / "bin" / "python"
    if (
        py.exists()
        and subprocess.run([str(py), "-c", "import mplib"], capture_output=True, check=False).returncode == 0
    ):
        return py
    print(f"mplib: creating {MPLIB_VENV.relative_to(ROOT)} (python -m venv + pip install mplib) ...", flush=True)
    try:
        subprocess.run([sys.executable, "-m", "venv", str(MPLIB_VENV)], check=True, capture_output=True, text=True)
        (MPLIB_VENV / ".gitignore").write_text("# created by bench/bench_ompl.py\n*\n")
        pip = subprocess.run(
            [str(py), "-m", "pip", "install", "-q", "mplib"], capture_output=True, text=True, timeout=900, check=False
        )
        if pip.returncode != 0:
            return f"pip install mplib failed: {(pip.stderr or pip.stdout).strip().splitlines()[-1:]}"
        check = subprocess.run([str(py), "-c", "import mplib"], capture_output=True, text=True, check=False)
        if check.returncode != 0:
            return f"mplib installed but does not import: {check.stderr.strip().splitlines()[-1:]}"
    except (OSError, subprocess.SubprocessError) as e:
        return f"could not create the venv: {e}"
    return py


def mplib_spec(cell: Cell, queries: list[Any], time_limit: float, rrt_range: float = 0.1) -> dict[str, Any]:
    scene, s = cell.scene, cell.settings
    boxes = []
    shapes = [
        (f.name, sh)
        for f in s.world.fixtures
        if f.known
        for sh in read_fixture_shapes(s.resolve(f.urdf), pose_from_xyz_rpy(f.position, f.rpy))
    ]
    for name, sh in shapes:
        if sh.kind != "box":
            raise SystemExit(f"fixture {name}: only boxes are passed to mplib, got {sh.kind}")
        boxes.append({"name": f"{name}_{len(boxes)}", "size": list(sh.size), "pose": sh.pose.tolist()})
    for name, (size, T) in scene.boxes().items():
        boxes.append({"name": name, "size": size.tolist(), "pose": T.tolist()})
    held = scene.attached_box()
    model = scene.model
    half = scene.gripper_opening / 2.0  # each finger moves half the opening (RobotModel convention)
    return {
        "urdf": str(s.resolve(s.robot.urdf)),
        "move_group": scene.tcp_link,
        "excluded_pairs": [list(p) for p in sorted(scene.excluded_pairs)],
        "arm_joints": list(model.arm_joints),
        "static_links": [
            ln for ln in model.link_names if model.rigid_parent(ln, movable=model.arm_joints) == model.root
        ],
        "fixed_qpos": dict.fromkeys(model.gripper_joints, half),
        "boxes": boxes,
        "attached_box": None if held is None else {"size": held[1].tolist(), "pose": held[2].tolist()},
        "vel": cell.limits.max_joint_vel.tolist(),
        "acc": cell.limits.max_joint_acc.tolist(),
        "time_limit_s": time_limit,
        "time_step_s": 0.01,
        "rrt_range": rrt_range,  # mplib's default is 0.1
        "queries": [{"start": a.tolist(), "goals": g.tolist()} for a, _, g in queries],
    }


def run_mplib(py: Path, cell: Cell, queries: list[Any], time_limit: float, rrt_range: float) -> dict[str, Any] | str:
    spec = mplib_spec(cell, queries, time_limit, rrt_range)
    proc = subprocess.run(
        [str(py), str(BENCH / "mplib_driver.py")],
        input=json.dumps(spec),
        capture_output=True,
        text=True,
        timeout=60 + 3 * time_limit * len(queries),
        check=False,
    )
    if proc.returncode != 0:
        return f"driver failed: {proc.stderr.strip().splitlines()[-3:]}"
    answer = json.loads(proc.stdout.strip().splitlines()[-1])
    rows = []
    for r in answer["results"]:
        q = np.array(r["q"]) if r["ok"] else np.zeros((0, 6))
        ok = bool(r["ok"]) and q.shape[0] > 0
        hit = bool(ok and not cell.scene.check_path(q, resolution_rad=FINE_RAD).free)
        length = float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum()) if ok else math.nan
        rows.append(
            {
                "ok": ok,
                "time_s": r["time_s"],
                "length": length,
                "duration": (q.shape[0] - 1) * spec["time_step_s"] if ok else math.nan,
                "fine_hit": hit,
                "status": "success" if ok else r["status"][:40],
            }
        )
    out = summarize(rows)
    out["ompl_median_s"] = float(np.median([r["ompl_s"] for r in answer["results"]]))
    out["topp_median_s"] = float(np.median([r["topp_s"] for r in answer["results"] if r["ok"]] or [math.nan]))
    out["version"] = answer.get("mplib_version", "?")
    out["setup_s"] = answer.get("setup_s", math.nan)
    return out


# ---- main ---------------------------------------------------------------------------------------------------
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--queries", type=int, default=20, help="queries per scene")
    ap.add_argument("--time-limit", type=float, default=1.0, help="planning time limit per query, s")
    ap.add_argument("--planners", default="all", help="comma-separated ompl.* names (default: every registered one)")
    ap.add_argument(
        "--straight",
        choices=("blocked", "free", "any"),
        default="blocked",
        help="which queries: straight joint motion blocked (default), free, or any",
    )
    ap.add_argument("--all-queries", action="store_true", help="the same as --straight any")
    ap.add_argument("--no-mplib", action="store_true", help="skip the mplib comparison")
    ap.add_argument("--no-limits", action="store_true", help="skip the fail-fast and timeout measurements")
    ap.add_argument("--seed", type=int, default=2024)
    ap.add_argument(
        "--before",
        action="store_true",
        help="also plan every query with the sphere filter off (collision.sphere_filter: false, FCL checks every "
        "configuration, as before issue 14) and print both side by side",
    )
    args = ap.parse_args()

    straight = "any" if args.all_queries else args.straight
    cells = [Cell("robocup"), Cell("warehouse")]
    if not args.no_limits:
        bench_limits(cells[1])
        print()
    names = sorted(n for n in cells[0].ctx.registry.names([Kind.PLANNER]) if n.startswith("ompl."))
    if args.planners != "all":
        names = [n.strip() for n in args.planners.split(",")]
    blocks = [(n, PlannerBlock(name=n)) for n in names]
    if "ompl.rrtconnect" in names:
        blocks.insert(
            names.index("ompl.rrtconnect") + 1,
            (
                "ompl.rrtconnect (no final check)",
                PlannerBlock(name="ompl.rrtconnect", params={"verify_resolution_rad": 0, "clearance_m": 0}),
            ),
        )
    queries = {c.name: c.queries(args.queries, args.seed + i, straight) for i, c in enumerate(cells)}
    which = {"any": "all", "blocked": "straight joint motion blocked", "free": "straight joint motion free"}[straight]
    print(
        f"{args.queries} queries per scene ({which}), time limit {args.time_limit:g} s, "
        f"seeds per query 0..{args.queries - 1}"
    )
    header = (
        f"  {'planner':34s} {'succ':>6s}  {'med ms':>7s}  {'p95 ms':>7s}  {'len':>6s}  {'dur s':>5s}  hit  failures"
    )

    results: dict[str, dict[str, Any]] = {}
    before: dict[str, dict[str, Any]] = {}
    for cell in cells:
        print(f"\n{cell.name}:\n{header}")
        for label, block in blocks:
            if args.before:
                cell.scene.sphere_filter = False
                b = run_ours(cell, block, queries[cell.name], args.time_limit)
                cell.scene.sphere_filter = True
                before.setdefault(label, {})[cell.name] = b
                print_row(f"{label} [FCL only]", b)
            s = run_ours(cell, block, queries[cell.name], args.time_limit)
            results.setdefault(label, {})[cell.name] = s
            print_row(label, s)
            sys.stdout.flush()

    print("\nall scenes:\n" + header)
    for label, _ in blocks:
        per = results[label]
        if any(isinstance(v, str) for v in per.values()):
            print_row(label, next(v for v in per.values() if isinstance(v, str)))
            continue
        print_row(label, merge(list(per.values())))
    if args.before:
        print_before_after(blocks, before, results)

    if args.no_mplib:
        return
    print("\nmplib:")
    py = mplib_python()
    if isinstance(py, str):
        print(f"  mplib is not available here ({py}); skipping the comparison.")
        return
    print(header)
    mplib_runs: dict[str, dict[str, Any]] = {}
    for rrt_range in (0.1, 1.0):  # mplib's default range, and ours
        label = f"mplib range {rrt_range:g}"
        mp: dict[str, Any] = {}
        for cell in cells:
            s = run_mplib(py, cell, queries[cell.name], args.time_limit, rrt_range)
            mp[cell.name] = s
            print_row(f"{label} [{cell.name}]", s)
        if any(isinstance(v, str) for v in mp.values()):
            print(f"  {label}: failed on a scene; no ratio.")
            continue
        mp["all"] = merge([mp[c.name] for c in cells])
        print_row(f"{label} [all]", mp["all"])
        for c in cells:
            print(
                f"    [{c.name}] median OMPL part {mp[c.name]['ompl_median_s'] * 1e3:.1f} ms, "
                f"TOPP-RA part {mp[c.name]['topp_median_s'] * 1e3:.1f} ms"
            )
        mplib_runs[label] = mp
    if not mplib_runs:
        return
    print("\nratio of median planning time, ours / mplib (same queries, same time limit):")
    for label in ("ompl.rrtconnect", "ompl.rrtconnect (no final check)"):
        if label not in results or any(isinstance(v, str) for v in results[label].values()):
            continue
        ours = dict(results[label], all=merge([results[label][c.name] for c in cells]))
        for mlabel, mp in mplib_runs.items():
            parts = ", ".join(f"{c.name}: {ours[c.name]['median_s'] / mp[c.name]['median_s']:.2f}" for c in cells)
            print(f"  {label:34s} / {mlabel:16s} {ours['all']['median_s'] / mp['all']['median_s']:.2f}  ({parts})")
    label = "ompl.rrtconnect"
    best = mplib_runs.get("mplib range 1")
    if label in results and best is not None and not any(isinstance(v, str) for v in results[label].values()):
        ours = merge([results[label][c.name] for c in cells])
        mp = best["all"]
        print("\nissue 14's goals for ompl.rrtconnect against mplib range 1 (same queries):")
        goals = [
            ("median planning time <= 0.5x", ours["median_s"] / mp["median_s"], 0.5),
            ("p95 planning time <= 1.0x", ours["p95_s"] / mp["p95_s"], 1.0),
        ]
        for what, ratio, bound in goals:
            print(f"  {what:32s} {ratio:5.2f}x  {'met' if ratio <= bound else 'NOT MET'}")
        hits = ours["fine_hits"]
        print(f"  {'0 collisions (fine re-check)':32s} {hits:5d}   {'met' if hits == 0 else 'NOT MET'}")
        ok = ours["success"] >= mp["success"]
        print(
            f"  {'success >= mplib':32s} {ours['success'] * 100:5.1f}% vs {mp['success'] * 100:.1f}%  "
            f"{'met' if ok else 'NOT MET'}"
        )


def print_before_after(
    blocks: list[tuple[str, PlannerBlock]], before: dict[str, dict[str, Any]], after: dict[str, dict[str, Any]]
) -> None:
    """Per planner, both scenes pooled: FCL only (before) and sphere filter + FCL (after), the speed-up, and
    whether the plans are the same (same successes, same trajectory durations)."""
    print("\nbefore (FCL checks every configuration) and after (sphere filter, then FCL), both scenes:")
    print(f"  {'planner':34s} {'succ':>13s}  {'median ms':>15s}  {'p95 ms':>15s}  {'speed-up':>8s}  same plans")
    for label, _ in blocks:
        b, a = before.get(label, {}), after.get(label, {})
        if not b or any(isinstance(v, str) for v in (*b.values(), *a.values())):
            continue
        mb, ma = merge(list(b.values())), merge(list(a.values()))
        db, da = np.array(mb["durations"]), np.array(ma["durations"])
        same = db.shape == da.shape and bool(np.all((np.isnan(db) & np.isnan(da)) | (np.abs(db - da) <= 1e-9)))
        print(
            f"  {label:34s} {mb['success'] * 100:5.1f}/{ma['success'] * 100:5.1f}%  "
            f"{mb['median_s'] * 1e3:7.1f}/{ma['median_s'] * 1e3:7.1f}  "
            f"{mb['p95_s'] * 1e3:7.1f}/{ma['p95_s'] * 1e3:7.1f}"
            f"  {mb['median_s'] / ma['median_s']:7.2f}x  {'yes' if same else 'no'}"
        )


def merge(summaries: list[dict[str, Any]]) -> dict[str, Any]:
    """Pool per-scene summaries (times re-pooled for the quantiles; medians of length/duration averaged)."""
    t = np.concatenate([np.array(s["times"]) for s in summaries])
    n = sum(s["n"] for s in summaries)
    failures: dict[str, int] = {}
    for s in summaries:
        for k, v in s["failures"].items():
            failures[k] = failures.get(k, 0) + v
    return {
        "n": n,
        "success": sum(s["success"] * s["n"] for s in summaries) / n,
        "median_s": float(np.median(t)),
        "p95_s": float(np.percentile(t, 95)),
        "length": _nanmean([s["length"] for s in summaries]),
        "duration": _nanmean([s["duration"] for s in summaries]),
        "fine_hits": sum(s["fine_hits"] for s in summaries),
        "failures": failures,
        "times": t.tolist(),
        "durations": [d for s in summaries for d in s["durations"]],
    }


def _nanmean(values: list[float]) -> float:
    v = np.array(values, dtype=float)
    return float(v[~np.isnan(v)].mean()) if (~np.isnan(v)).any() else math.nan


if __name__ == "__main__":
    os.environ.setdefault("PYTHONWARNINGS", "ignore")
    main()
