"""roboplan (0.7.0: a C++ RRT-Connect on pinocchio + coal) as a peer planner on twin's problem sets: for
bench/bench_mbm.py (issue 41), and a small CLI of its own.

    python bench/roboplan_peer.py [--scenes box,cage] [--problems N] [--time-limit 10]
                                  [--robot-urdf twin|spherized|both] [--check N] [--recheck] [--shortcut]
                                  [--out FILE.json]

roboplan's wheels pin another pinocchio than twin's croc extra, so it lives in its own virtual environment,
bench/.roboplan-venv (made on first use: `python -m venv` + `pip install roboplan==0.7.0`), and plans through
bench/roboplan_driver.py (imports nothing from twin; JSON in, JSON out), as bench_ompl.py runs mplib.

What roboplan is given, for each problem set: the URDF twin plans with for the set (`robot.model: ur5`: twin's
urdf/ur5.urdf, primitives only, or with `robot.urdf=` another model, such as MBM's spheres-only
ur5_spherized.urdf), visual elements dropped (no meshes are read); no SRDF: the self pairs twin's
planning scene never checks (its `excluded_pairs`: for urdf/ur5.urdf the set's `allowed_self_collisions`)
are disabled with `Scene.setCollisions`, as are the set's static links against the obstacles and the
obstacles against each other; twin's fingers at the set's gripper opening; each problem's world (boxes,
cylinders, spheres) in the URDF root's frame (`base_pose`: twin's base frame in the root's, for a URDF rooted
elsewhere, such as the spherized one's offset_link). Joint goals only; a held object is refused.

The CLI prints per scene: problems, valid (start and goal collision-free in roboplan's scene), solved, the
median and 95th percentile of planning time (around `RRT.plan` only), the per-check cost (the median time of
one `Scene.hasCollisions` of a random configuration in the scene's first world) and, with --recheck, what
twin's planning scene says of roboplan's paths, re-checked every 0.01 rad of joint motion and 1 cm of tool
travel (twin's judge's resolution): how many collide, how many miss the goal.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
ROBOPLAN_VENV = ROOT / "bench" / ".roboplan-venv"
DRIVER = Path(__file__).resolve().with_name("roboplan_driver.py")
ROBOPLAN_REQUIREMENT = "roboplan==0.7.0"
CONFIG = "robocup"  # the scene config bench_mbm.py plans MBM in (its robot cell; the set's world replaces its own)
RESOLUTION_RAD = 0.01  # twin's judge: every 0.01 rad of joint motion ...
RESOLUTION_M = 0.01  # ... and 1 cm of tool travel

__all__ = [
    "check_cost",
    "plan_problem_set",
    "recheck",
    "roboplan_python",
    "robot_spec",
    "run_driver",
    "twin_cell",
]


def _required_python() -> Path:
    """`roboplan_python()`, or RuntimeError saying why roboplan is not available."""
    py = roboplan_python()
    if isinstance(py, str):
        raise RuntimeError(f"roboplan is not available: {py}")
    return py


def roboplan_python() -> Path | str:
    """The roboplan venv's python, created on first use; or a string saying why it is unavailable."""
    py = ROBOPLAN_VENV / "bin" / "python"
    probe = "import roboplan.core, roboplan.rrt"
    if py.exists() and subprocess.run([str(py), "-c", probe], capture_output=True, check=False).returncode == 0:
        return py
    print(
        f"roboplan: creating {ROBOPLAN_VENV.relative_to(ROOT)} (python -m venv + pip install "
        f"{ROBOPLAN_REQUIREMENT}) ...",
        file=sys.stderr,
        flush=True,
    )
    try:
        subprocess.run([sys.executable, "-m", "venv", str(ROBOPLAN_VENV)], check=True, capture_output=True, text=True)
        (ROBOPLAN_VENV / ".gitignore").write_text("# created by bench/roboplan_peer.py\n*\n")
        pip = subprocess.run(
            [str(py), "-m", "pip", "install", "-q", ROBOPLAN_REQUIREMENT],
            capture_output=True,
            text=True,
            timeout=900,
            check=False,
        )
        if pip.returncode != 0:
            return f"pip install {ROBOPLAN_REQUIREMENT} failed: {(pip.stderr or pip.stdout).strip().splitlines()[-1:]}"
        check = subprocess.run([str(py), "-c", probe], capture_output=True, text=True, check=False)
        if check.returncode != 0:
            return f"roboplan installed but does not import: {check.stderr.strip().splitlines()[-1:]}"
    except (OSError, subprocess.SubprocessError) as e:
        return f"could not create the venv: {e}"
    return py


# ---- problem sets ------------------------------------------------------------------------------------------


def _set_path(problem_set: Any, folder: Path) -> Path:
    """A file of the problem set: a path as it is, a ProblemSet written into `folder` (twin's cells read files)."""
    if isinstance(problem_set, (str, Path)):
        return Path(problem_set)
    from twin.problems import save_problem_set

    return save_problem_set(problem_set, folder / f"{problem_set.name}.json")


def _overrides(urdf: str | Path | None, robot_model: str) -> tuple[str, ...]:
    return (f"robot.model={robot_model}",) + ((f"robot.urdf={Path(urdf).resolve()}",) if urdf else ())


def _cell(path: Path, index: int, urdf: str | Path | None, robot_model: str) -> Any:
    from twin.problems.cells import cell_for

    return cell_for(CONFIG, _overrides(urdf, robot_model), "box", problems=str(path), problem_index=index)


def twin_cell(problem_set: str | Path, index: int, urdf: str | Path | None = None, *, robot_model: str = "ur5") -> Any:
    """twin's cell of problem `index` of a problem-set file: the cell `twin compare` (and bench_mbm.py) plans
    it in (`twin.problems.cells.cell_for` on the robocup config, `robot.model`, `robot.urdf` when given)."""
    return _cell(Path(problem_set), index, urdf, robot_model)


def robot_spec(problem_set: str | Path, urdf: str | Path | None = None, *, robot_model: str = "ur5") -> dict[str, Any]:
    """The robot part of the driver's spec, as twin's planning scene of the set has it (module docstring):
    urdf, arm_joints, fixed_positions, excluded_pairs, static_links, base_pose."""
    path = Path(problem_set)
    cell = _cell(path, 0, urdf, robot_model)
    scene = cell.scene
    model = scene.model
    from twin.problems import load_problem_set

    ps = load_problem_set(path)
    opening = scene.gripper_opening
    return {
        "urdf": str(model.source),
        "arm_joints": list(model.arm_joints),
        "fixed_positions": dict.fromkeys(model.gripper_joints, 0.5 * opening),
        "excluded_pairs": [list(p) for p in sorted(scene.excluded_pairs)],
        "static_links": [s for s in ps.robot.static_links if s in model.link_index],
        "base_pose": np.linalg.inv(model.root_pose).tolist(),
    }


def _obstacles(world: Any) -> list[dict[str, Any]]:
    out = []
    for obj in world.objects:
        for i, prim in enumerate(obj.primitives):
            size = {
                "box": lambda p: list(p.size),
                "cylinder": lambda p: [p.radius, p.length],
                "sphere": lambda p: [p.radius],
            }[prim.shape](prim)
            out.append(
                {"name": f"{obj.name}_{i}", "shape": prim.shape, "size": size, "pose": prim.pose.matrix().tolist()}
            )
    return out


def driver_spec(
    problem_set: str | Path,
    robot: dict[str, Any],
    *,
    first: int | None = None,
    time_limit_s: float | None = None,
    seed: int | None = None,
    rrt: dict[str, Any] | None = None,
    shortcut: bool = False,
) -> dict[str, Any]:
    """The driver's SPEC (roboplan_driver.py) of the first `first` problems of a problem-set file (all: None);
    `time_limit_s` / `seed` replace every problem's own when given."""
    from twin.problems import load_problem_set

    ps = load_problem_set(problem_set)
    if ps.world.held_object is not None or any(p.world and p.world.held_object for p in ps.problems):
        raise ValueError(f"{problem_set}: a held object is not passed to roboplan")
    problems = []
    for i, p in enumerate(ps.problems[:first]):
        if p.goal.kind != "joint":
            raise ValueError(f"{problem_set}: problem {p.id} has a {p.goal.kind} goal; only joint goals go to roboplan")
        problems.append(
            {
                "id": p.id,
                "start": list(p.start),
                "goal": list(p.goal.joints),
                "obstacles": _obstacles(ps.world_of(i)),
                "time_limit_s": p.time_limit_s if time_limit_s is None else time_limit_s,
                "seed": p.seed if seed is None else seed,
            }
        )
    return dict(robot, problems=problems, rrt=dict(rrt or {}), shortcut=shortcut, seed=0 if seed is None else seed)


def run_driver(
    python: Path, spec: dict[str, Any], *, check_cost: int = 0, timeout: float | None = None
) -> dict[str, Any]:
    """Run roboplan_driver.py in roboplan's venv on `spec`; its JSON answer (RuntimeError when it fails)."""
    cmd = [str(python), str(DRIVER)] + (["--check-cost", str(check_cost)] if check_cost else [])
    done = subprocess.run(cmd, input=json.dumps(spec), capture_output=True, text=True, timeout=timeout, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"roboplan_driver.py failed ({done.returncode}): {done.stderr.strip()[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def plan_problem_set(
    problem_set: str | Path | Any,
    urdf: str | Path | None = None,
    *,
    first: int | None = None,
    time_limit_s: float | None = 10.0,
    seed: int | None = None,
    rrt: dict[str, Any] | None = None,
    shortcut: bool = False,
    robot_model: str = "ur5",
    python: Path | None = None,
) -> list[dict[str, Any]]:
    """Plan a twin problem set (a file, or a ProblemSet) with roboplan: one row per problem, in order,
    {"scene" (the set's name), "case" (the problem's index in the set), "id", "ok", "status",
    "planning_time_s" (around RRT.plan only; 0 when not planned), "path" ([[6], ...] from start to goal, [] when
    not solved), "start_valid", "goal_valid" (in roboplan's scene), "setup_s", "shortcut_s",
    "roboplan_version"}.

    `urdf`: the robot's collision model (None: the set's, as twin loads it for `robot.model: <robot_model>`;
    e.g. `twin.problems.mbm.mbm_spherized_urdf()`). `first`: the first N problems only. `time_limit_s` and
    `seed` replace the problems' own unless None. `rrt`: roboplan RRTOptions fields over the driver's
    defaults (RRT-Connect, roboplan's range 3.0 and 0.05 edge resolution). `shortcut`: roboplan's
    PathShortcutter after a plan (timed apart, in shortcut_s). RuntimeError when roboplan is not available."""
    python = python or _required_python()
    with tempfile.TemporaryDirectory() as tmp:
        path = _set_path(problem_set, Path(tmp))
        robot = robot_spec(path, urdf, robot_model=robot_model)
        spec = driver_spec(path, robot, first=first, time_limit_s=time_limit_s, seed=seed, rrt=rrt, shortcut=shortcut)
        answer = run_driver(python, spec)
        from twin.problems import load_problem_set

        name = load_problem_set(path).name
    rows = []
    for i, r in enumerate(answer["results"]):
        rows.append(dict(r, scene=name, case=i, roboplan_version=answer["roboplan_version"]))
    return rows


def check_cost(
    problem_set: str | Path | Any,
    urdf: str | Path | None = None,
    *,
    checks: int = 1000,
    first: int | None = 1,
    robot_model: str = "ur5",
    python: Path | None = None,
    compare: bool = False,
) -> list[dict[str, Any]]:
    """The cost of one collision check in roboplan's scene of each of the first `first` problems' worlds:
    [{"id", "obstacles" (primitives), "checks", "median_us", "mean_us", "colliding"}], over `checks` seeded
    random configurations within the arm's joint limits. `compare`: also "twin_colliding" and "disagree",
    twin's planning scene's verdict on the same configurations (a check of the model handed to roboplan:
    frames, shapes, excluded pairs), and "twin_median_us", twin's own per-check cost there (in_collision,
    one configuration per call)."""
    python = python or _required_python()
    with tempfile.TemporaryDirectory() as tmp:
        path = _set_path(problem_set, Path(tmp))
        spec = driver_spec(path, robot_spec(path, urdf, robot_model=robot_model), first=first)
        spec["return_samples"] = compare
        results = run_driver(python, spec, check_cost=checks)["results"]
        for i, r in enumerate(results if compare else []):
            scene = _cell(path, i, urdf, robot_model).scene
            qs = np.asarray(r.pop("samples"), dtype=float)
            theirs = np.asarray(r.pop("hits"), dtype=bool)
            ours = np.asarray(scene.in_collision_batch(qs), dtype=bool)
            r["twin_colliding"] = int(ours.sum())
            r["disagree"] = int((ours != theirs).sum())
            times = []
            for q in qs:
                t = time.perf_counter()
                scene.in_collision(q)
                times.append(time.perf_counter() - t)
            r["twin_median_us"] = 1e6 * float(np.median(times))
        return results


# ---- twin's re-check ---------------------------------------------------------------------------------------


def _dense(path: np.ndarray, kin: Any) -> np.ndarray:
    """The polyline through `path` (m, 6) with points added so that no joint moves more than RESOLUTION_RAD
    and the TCP no more than RESOLUTION_M between neighbours (twin's judge measures TCP chords twice:
    chords under-estimate arcs, so the same here), every waypoint kept."""
    q = np.asarray(path, dtype=float)
    for _ in range(6):
        if q.shape[0] < 2:
            return q
        dq = np.abs(np.diff(q, axis=0)).max(axis=1)
        p = kin.fk_batch(q)[:, :3, 3]
        dp = np.linalg.norm(np.diff(p, axis=0), axis=1)
        units = np.maximum(dq / RESOLUTION_RAD, 2.0 * dp / RESOLUTION_M)
        if units.max() <= 1.0 + 1e-9:
            return q
        out = [q[:1]]
        for a, b, u in zip(q[:-1], q[1:], units, strict=True):
            k = max(1, math.ceil(u - 1e-9))
            out.append(a + np.outer(np.arange(1, k + 1) / k, b - a))
        q = np.concatenate(out)
    return q


def recheck(
    rows: Sequence[dict[str, Any]],
    problem_set: str | Path,
    urdf: str | Path | None = None,
    *,
    robot_model: str = "ur5",
    goal_tolerance_rad: float = 1e-6,
) -> list[dict[str, Any]]:
    """roboplan's rows re-checked in twin's planning scene of each problem (the cell `twin compare` plans the
    set in, `twin.problems.cells.cell_for`): each row gets "twin_valid" (start and goal collision-free there),
    and for a solved one "twin_free" (its path, densified to twin's judge's resolution, collides nowhere),
    "twin_hit" (the first colliding configuration's index into the dense path, or None), "twin_ends"
    (starts at the start and ends within `goal_tolerance_rad` of the goal on every joint), "twin_checked"
    (configurations checked)."""
    from twin.problems import load_problem_set

    path = Path(problem_set)
    ps = load_problem_set(path)
    out = []
    for r in rows:
        i = int(r["case"])
        cell = _cell(path, i, urdf, robot_model)
        scene, prob = cell.scene, ps.problems[i]
        start, goal = np.asarray(prob.start, dtype=float), np.asarray(prob.goal.joints, dtype=float)
        row = dict(r, twin_valid=not scene.in_collision(start) and not scene.in_collision(goal))
        if r.get("ok") and r.get("path"):
            q = np.asarray(r["path"], dtype=float)
            dense = _dense(q, cell.kin)
            hits = np.flatnonzero(scene.in_collision_batch(dense))
            row["twin_checked"] = int(dense.shape[0])
            row["twin_hit"] = int(hits[0]) if hits.size else None
            row["twin_free"] = not hits.size
            row["twin_ends"] = bool(
                np.abs(q[0] - start).max() <= goal_tolerance_rad and np.abs(q[-1] - goal).max() <= goal_tolerance_rad
            )
        out.append(row)
    return out


# ---- CLI ---------------------------------------------------------------------------------------------------


def _ms(values: list[float]) -> str:
    if not values:
        return f"{'-':>8} {'-':>8}"
    return f"{1e3 * float(np.median(values)):8.1f} {1e3 * float(np.percentile(values, 95)):8.1f}"


def main(argv: Sequence[str] | None = None) -> int:
    from twin.problems.mbm import SCENES, mbm_problem_set, mbm_spherized_urdf

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--scenes", default=",".join(SCENES), help="comma-separated MBM UR5 scenes (default: all seven)")
    ap.add_argument("--problems", type=int, default=None, metavar="N", help="the first N problems of each scene")
    ap.add_argument("--time-limit", type=float, default=10.0, help="planning time limit per problem, s")
    ap.add_argument("--seed", type=int, default=None, help="roboplan's RNG seed (default: each problem's own)")
    ap.add_argument("--robot-urdf", choices=("twin", "spherized", "both"), default="twin")
    ap.add_argument("--check", type=int, default=1000, metavar="N", help="collision checks timed per scene (0: none)")
    ap.add_argument("--recheck", action="store_true", help="re-check the paths in twin's planning scene")
    ap.add_argument("--shortcut", action="store_true", help="roboplan's path shortcutting after each plan")
    ap.add_argument(
        "--rrt",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a roboplan RRTOptions field, e.g. collision_check_step_size=0.01 (repeatable)",
    )
    ap.add_argument("--out", default=None, help="write every row (paths too) to this JSON file")
    args = ap.parse_args(argv)
    scenes = [s.strip() for s in args.scenes.split(",") if s.strip()]
    unknown = [s for s in scenes if s not in SCENES]
    if unknown or not scenes:
        ap.error(f"unknown scene(s) {unknown}; MotionBenchMaker's UR5 scenes: {', '.join(SCENES)}")
    rrt: dict[str, Any] = {}
    for item in args.rrt:
        key, _, value = item.partition("=")
        rrt[key.strip()] = json.loads(value.strip().lower() if value.strip().lower() in ("true", "false") else value)
    py = roboplan_python()
    if isinstance(py, str):
        print(f"roboplan is not available here: {py}")
        return 1
    models = {"twin": None, "spherized": mbm_spherized_urdf()}
    chosen = ["twin", "spherized"] if args.robot_urdf == "both" else [args.robot_urdf]
    everything: dict[str, Any] = {}
    for label in chosen:
        urdf = models[label]
        head = f"{'scene':<18} {'probs':>5} {'valid':>5} {'solved':>7} {'med ms':>8} {'p95 ms':>8} "
        head += f"{'check us':>8} {'twin us':>7} {'agree':>9}"
        if args.recheck:
            head += f" {'twin valid':>10} {'collide':>7} {'ends':>5}"
        model = "twin's urdf/ur5.urdf" if urdf is None else f"MBM's {Path(urdf).name}"
        print(
            f"\nroboplan RRT-Connect on MotionBenchMaker UR5, {model}, time limit {args.time_limit:g} s, "
            f"{'RRTOptions ' + json.dumps(rrt) + ', ' if rrt else ''}"
            f"{os.cpu_count()} CPUs here"
        )
        print(head)
        print("-" * len(head))
        rows_all: list[dict[str, Any]] = []
        costs: list[float] = []
        t0 = time.perf_counter()
        for scene in scenes:
            path = mbm_problem_set(f"ur5/{scene}")
            rows = plan_problem_set(
                path,
                urdf,
                first=args.problems,
                time_limit_s=args.time_limit,
                seed=args.seed,
                rrt=rrt,
                shortcut=args.shortcut,
                python=py,
            )
            cost = check_cost(path, urdf, checks=args.check, python=py, compare=True)[0] if args.check else None
            if args.recheck:
                rows = recheck(rows, path, urdf)
            valid = [r for r in rows if r["start_valid"] and r["goal_valid"]]
            solved = [r for r in valid if r["ok"]]
            line = f"{scene:<18} {len(rows):>5} {len(valid):>5} {len(solved):>3}/{len(valid):<3} "
            line += _ms([r["planning_time_s"] for r in solved])
            if cost:
                line += f" {cost['median_us']:8.1f} {cost['twin_median_us']:7.1f}"
                line += f" {cost['checks'] - cost['disagree']:>4}/{cost['checks']:<4}"
            else:
                line += f" {'-':>8} {'-':>7} {'-':>9}"
            if args.recheck:
                tv = sum(r["twin_valid"] for r in rows)
                bad = sum(not r["twin_free"] for r in solved)
                ends = sum(r["twin_ends"] for r in solved)
                line += f" {tv:>10} {bad:>7} {ends:>5}"
            print(line, flush=True)
            rows_all += rows
            if cost:
                costs.append(cost["median_us"])
        valid = [r for r in rows_all if r["start_valid"] and r["goal_valid"]]
        solved = [r for r in valid if r["ok"]]
        print("-" * len(head))
        line = f"{'all':<18} {len(rows_all):>5} {len(valid):>5} {len(solved):>3}/{len(valid):<3} "
        line += _ms([r["planning_time_s"] for r in solved])
        line += f" {float(np.median(costs)):8.1f} {'':>7} {'':>9}" if costs else f" {'-':>8} {'':>7} {'':>9}"
        if args.recheck:
            line += f" {sum(r['twin_valid'] for r in rows_all):>10} {sum(not r['twin_free'] for r in solved):>7}"
            line += f" {sum(r['twin_ends'] for r in solved):>5}"
        print(line)
        version = rows_all[0]["roboplan_version"] if rows_all else "?"
        print(
            f"roboplan {version}; {time.perf_counter() - t0:.0f} s wall; planning time around RRT.plan only; "
            f"check: median of one Scene.hasCollisions, per scene its first problem's world; twin us: "
            "twin's PlanningScene.in_collision there; agree: random configurations on which both say the same"
        )
        if args.recheck:
            print(
                f"re-check: twin's planning scene every {RESOLUTION_RAD} rad / {RESOLUTION_M * 100:g} cm of tool "
                "travel; 'collide': solved paths twin finds in collision; 'ends': paths from start to the goal"
            )
        everything[label] = rows_all
    if args.out:
        Path(args.out).parent.mkdir(parents=True, exist_ok=True)
        Path(args.out).write_text(json.dumps(everything))
    return 0


if __name__ == "__main__":
    sys.exit(main())
