"""The field's own benchmark on the twin: MotionBenchMaker's UR5 suite (7 scenes x 100 problems), planned by
twin's planners through twin's judge, beside the numbers VAMP publishes for it (issues 30, 41). A plain script:
it prints tables and asserts nothing.

    python bench/bench_mbm.py [--planners compiled.rrtconnect,ompl.rrtconnect,rrtconnect-exact,roboplan]
                              [--time-limit 10] [--workers N] [--scenes box,cage] [--problems N]
                              [--out out/bench-mbm] [--robot-urdf twin|spherized]

`--planners`: twin planner names (as `twin compare` takes them; `ompl.rrtconnect` searches on twin's planning
model, its default `collision_model: spheres`), `rrtconnect-exact` (ompl.rrtconnect with `collision_model: exact`,
searching on the FCL scene) and `roboplan` (roboplan 0.7.0's C++
RRT-Connect as a peer, in its own venv, bench/roboplan_peer.py; skipped with a one-line reason when that venv
cannot be made). Default: all four, in ONE run on the same problems.

`--scenes` and `--problems N` pick a subset of the suite: those scenes (a name not in MBM's UR5 suite is a
one-line error listing the ones that are), the first N problems of each (MBM's file order).

The problems are `twin.problems.mbm`'s (vamp-planner 0.6.4's source distribution, fetched by pip into twin's
cache once, each scene imported as `twin problems import-moveit DIR --robot ur5` does: a world per problem),
planned by `twin compare` for `robot.model: ur5` (twin's
primitive UR5 with its 2F-85-like gripper, or with `--robot-urdf spherized` MBM's own spheres-only model of the
UR5 and its Robotiq gripper, the one VAMP checks) without execution: every plan is re-checked by the judge every
0.01 rad / 1 cm of tool travel against the problem's scene and must end on the joint goal.

Per scene and over all scenes, per planner: valid (start and goal FCL-free in twin's model), solved, planning
time median/p95 ("planning": compiled.rrtconnect's `search_time_s`, the compiled search alone; the others'
whole plan() call; roboplan's `RRT.plan`), total time median/p95 (the whole plan() call: search, simplify,
retime, verify, plus the judge's final check: the time to an executable, judged trajectory; roboplan: plan +
its shortcutting, no retiming, no judge), the median joint path length, and "refused": paths the planner
returned as solved that twin's FCL judge turned down (`final_check_collision`; roboplan: its solved paths that
twin's re-check at the judge's resolution finds colliding, `roboplan_peer.recheck`). Then VAMP's published
numbers, what differs from VAMP's setup, ratios, and the cover's price: problems valid in the exact model whose
start or goal the planning model (0 clearance) calls touching.

compiled.rrtconnect's step times come from the comparison's rows (`step_times_s`: each planner's own
`<step>_time_s` from its result's info).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any, NoReturn

import numpy as np

from twin.compare import compare_spec_from_dict, run_comparison
from twin.problems import ProblemSet, load_problem_set, save_problem_set
from twin.problems.mbm import SCENES, mbm_problem_set, mbm_spherized_urdf
from twin.progress import ProgressClock

# VAMP's README (0.6.4): UR5, its vectorised RRT-Connect, AMD Ryzen 9 7950X; and what its 0.6.4 sphere model
# says is valid (VAMP's own C++ check compiled from the sdist, issue 30's note)
VAMP = {
    "valid_published": 608,
    "valid_0.6.4_model": 689,
    "planning_median_us": 39.0,
    "total_median_us": 111.5,
    "total_p95_us": 837.0,
}
# the problems (MBM's file numbers) VAMP 0.6.4's own check finds invalid in its ur5_spherized.urdf: its C++
# collision code compiled from the sdist, run on the 700 problems (issue 30's note); 689 valid
VAMP_INVALID = {
    "bookshelf_small": (9, 22, 30, 88),
    "bookshelf_tall": (18, 24, 67, 92, 97),
    "bookshelf_thin": (76,),
    "table_under_pick": (62,),
}
INVALID = {"start_in_collision", "goal_in_collision"}


def _problem_number(row: dict[str, Any], numbers: dict[str, list[int]]) -> int:
    """MBM's file number (NNNN of sceneNNNN.yaml) of a row's problem."""
    return numbers[row["scenario"]][int(row["case"].rpartition("#")[2])]


def _validity_lines(rows: list[dict[str, Any]], numbers: dict[str, list[int]], scenes: list[str]) -> list[str]:
    """Which problems twin finds invalid, beside those VAMP's check does; which valid ones nobody solved."""
    mine = {(r["scenario"], _problem_number(r, numbers)) for r in rows if r.get("failure") in INVALID}
    vamp = {(s, k) for s in scenes for k in VAMP_INVALID.get(s, ())}
    lines = [
        f"invalid here: {len(mine)}; in VAMP 0.6.4's own check of its sphere model: {len(vamp)}; "
        f"both {len(mine & vamp)}, only here {sorted(mine - vamp)}, only VAMP's {sorted(vamp - mine)}"
    ]
    solved = {(r["scenario"], _problem_number(r, numbers)) for r in rows if r.get("success")}
    valid = {(r["scenario"], _problem_number(r, numbers)) for r in rows} - mine
    lines.append(f"valid, solved by no planner: {', '.join(f'{s}#{k:04d}' for s, k in sorted(valid - solved)) or '-'}")
    return lines


REFUSED = "final_check_collision"  # twin's FCL judge turned down a trajectory the planner called a success
JUDGE_OTHER = ("final_check_goal", "limit_violation")  # the judge's other verdicts on a planner's success
COMPILED = "compiled.rrtconnect"
SEARCH_KEY = "search"  # compiled.rrtconnect's "planning": the compiled search alone (row["step_times_s"])
ROBOPLAN = "roboplan"
# planner words of --planners that are not a registered planner's name: a labelled block of one
ALIASES: dict[str, dict[str, Any]] = {
    "rrtconnect-exact": {
        "name": "ompl.rrtconnect",
        "params": {"collision_model": "exact"},
        "label": "rrtconnect-exact",
    },
}
DEFAULT_PLANNERS = f"{COMPILED},ompl.rrtconnect,rrtconnect-exact,{ROBOPLAN}"


def planner_blocks(text: str) -> tuple[list[Any], list[str], list[str]]:
    """(twin compare planner blocks, their labels, peers) of --planners 'a,b': a name as it is, an ALIASES
    word as its block, `roboplan` a peer; each once, in the order given."""
    words = list(dict.fromkeys(w.strip() for w in text.split(",") if w.strip()))
    blocks: list[Any] = []
    labels: list[str] = []
    peers: list[str] = []
    for w in words:
        if w == ROBOPLAN:
            peers.append(w)
        elif w in ALIASES:
            blocks.append(dict(ALIASES[w]))
            labels.append(ALIASES[w]["label"])
        else:
            blocks.append(w)
            labels.append(w)
    return blocks, labels, peers


def _plan_time(row: dict[str, Any]) -> float:
    """A row's "planning" time: compiled.rrtconnect's search alone, the others' whole plan() call."""
    steps = row.get("step_times_s") or {}
    if row["planner"] == COMPILED and steps.get(SEARCH_KEY) is not None:
        return float(steps[SEARCH_KEY])
    return float(row["timing"]["planning_time_s"])


def _total_time(row: dict[str, Any]) -> float:
    """A row's time to an executable, judged trajectory: the whole plan() call plus the judge's final check."""
    t = row["timing"]
    return float(t["planning_time_s"]) + float(t.get("final_check_time_s") or 0.0)


def twin_stats(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """One twin planner's rows (any scenes): valid, solved, plan / total seconds and path lengths of the
    solved ones, refused (final_check_collision) and the judge's other verdicts on claimed successes."""
    valid = [r for r in rows if r.get("failure") not in INVALID]
    solved = [r for r in valid if r.get("success")]
    failures: dict[str, int] = {}
    for r in valid:
        if not r.get("success"):
            failures[str(r.get("failure"))] = failures.get(str(r.get("failure")), 0) + 1
    return {
        "n": len(rows),
        "valid": len(valid),
        "solved": len(solved),
        "plan": [_plan_time(r) for r in solved],
        "total": [_total_time(r) for r in solved],
        "path": [r["metrics"]["joint_path_length_rad"] for r in solved if r["metrics"].get("joint_path_length_rad")],
        "refused": sum(r.get("failure") == REFUSED for r in rows),
        "judge_other": sum(r.get("failure") in JUDGE_OTHER for r in rows),
        "failures": failures,
    }


def peer_stats(rows: list[dict[str, Any]]) -> dict[str, Any]:
    """roboplan's rows after `roboplan_peer.recheck`, as `twin_stats`: valid in twin's model (twin_valid),
    solved (ok) among those, plan = RRT.plan, total = RRT.plan + its shortcutting, refused = solved paths twin's
    re-check finds colliding, judge_other = solved paths that do not run from start to goal."""
    valid = [r for r in rows if r.get("twin_valid")]
    solved = [r for r in valid if r.get("ok")]
    failures: dict[str, int] = {}
    for r in valid:
        if not r.get("ok"):
            failures[str(r.get("status"))] = failures.get(str(r.get("status")), 0) + 1
    paths = [np.asarray(r["path"], dtype=float) for r in solved if r.get("path")]
    return {
        "n": len(rows),
        "valid": len(valid),
        "own_valid": sum(bool(r.get("start_valid") and r.get("goal_valid")) for r in rows),
        "solved": len(solved),
        "plan": [float(r["planning_time_s"]) for r in solved],
        "total": [float(r["planning_time_s"]) + float(r.get("shortcut_s") or 0.0) for r in solved],
        "path": [float(np.linalg.norm(np.diff(q, axis=0), axis=1).sum()) for q in paths if q.shape[0] > 1],
        "refused": sum(not r.get("twin_free", True) for r in solved),
        "judge_other": sum(not r.get("twin_ends", True) for r in solved),
        "failures": failures,
    }


def _ms(values: list[float]) -> str:
    """'median p95' in ms (three decimals: compiled code plans in microseconds), or dashes."""
    if not values:
        return f"{'-':>9} {'-':>9}"
    return f"{1e3 * float(np.median(values)):9.3f} {1e3 * float(np.percentile(values, 95)):9.3f}"


def stats_cells(st: dict[str, Any]) -> str:
    """The planner's cells of a table line: solved, plan med/p95, total med/p95, path, refused."""
    path = f"{float(np.median(st['path'])):7.2f}" if st["path"] else f"{'-':>7}"
    return f"{st['solved']:>3}/{st['valid']:<3} {_ms(st['plan'])} {_ms(st['total'])} {path} {st['refused']:>7}"


def _median(values: list[float]) -> float | None:
    return float(np.median(values)) if values else None


def ratio_lines(overall: dict[str, dict[str, Any]]) -> list[str]:
    """compiled.rrtconnect's medians against roboplan's and ompl.rrtconnect's, and OMPL on spheres against
    OMPL exact (planning and total), for the planners that ran and solved something."""
    out = []

    def ratio(a: str, b: str, what: str, key: str) -> None:
        if a in overall and b in overall:
            ma, mb = _median(overall[a][key]), _median(overall[b][key])
            if ma and mb:
                r = ma / mb
                how = f"{1 / r:.3g}x faster" if r < 1 else f"{r:.3g}x slower"
                out.append(f"  {what}: {a} {1e3 * ma:.3f} ms / {b} {1e3 * mb:.3f} ms = {r:.3g} ({a} {how})")

    for key in ("plan", "total"):
        name = "planning median" if key == "plan" else "total median"
        ratio(COMPILED, ROBOPLAN, name, key)
        ratio(COMPILED, "ompl.rrtconnect", name, key)
        ratio("ompl.rrtconnect", "rrtconnect-exact", name, key)
        if key == "plan" and COMPILED in overall:
            m = _median(overall[COMPILED]["plan"])
            if m:
                out.append(f"  planning median: {COMPILED} / VAMP = {m / (VAMP['planning_median_us'] * 1e-6):.3g}")
        if key == "total" and COMPILED in overall:
            m = _median(overall[COMPILED]["total"])
            if m:
                out.append(f"  total median: {COMPILED} / VAMP = {m / (VAMP['total_median_us'] * 1e-6):.3g}")
    return out


def cover_price(sets: dict[str, Path], urdf: str | None) -> dict[str, dict[str, Any]]:
    """Per scene: the problems valid in the exact model (start and goal FCL-free in twin's planning scene of
    each problem, the cell `twin compare` plans it in) and those of them whose start or goal the planning model
    (`PlanningScene.sphere_model()`, 0 clearance) calls touching: {"valid", "touching", "start", "goal",
    "which" (MBM numbers)}."""
    from roboplan_peer import twin_cell  # lazy: the bench folder is on sys.path when this runs as a script

    out = {}
    for scene, path in sets.items():
        ps = load_problem_set(path)
        row = {"valid": 0, "touching": 0, "start": 0, "goal": 0, "which": []}
        for i, prob in enumerate(ps.problems):
            cell = twin_cell(path, i, urdf)
            start, goal = np.asarray(prob.start, dtype=float), np.asarray(prob.goal.joints, dtype=float)
            if cell.scene.in_collision(start) or cell.scene.in_collision(goal):
                continue
            row["valid"] += 1
            model = cell.scene.sphere_model()
            s, g = model.in_collision(start), model.in_collision(goal)
            row["start"] += s
            row["goal"] += g
            if s or g:
                row["touching"] += 1
                row["which"].append(int(prob.id.rpartition("#")[2]))
        out[scene] = row
    return out


def warm_compiled(path: Path, urdf: str | None) -> float:
    """Plan the first problem of a set with compiled.rrtconnect in this process, so that numba's on-disk cache
    of its search (compiled on a machine's first use: tens of seconds, inside the first request's search time,
    since the planner's warm-up does not reach the search) is there before the workers start; they then only
    load it. Seconds taken."""
    from roboplan_peer import twin_cell  # lazy: the bench folder is on sys.path when this runs as a script

    from twin.config import PlannerBlock
    from twin.planning import limits_from_settings, make_context, make_planner, plan_with
    from twin.types import JointGoal, MotionRequest

    t = time.perf_counter()
    cell = twin_cell(path, 0, urdf)
    context = make_context(cell.settings, robot=cell.robot)
    planner = make_planner(PlannerBlock(name=COMPILED), context)
    prob = load_problem_set(path).problems[0]
    request = MotionRequest(
        start=prob.start,
        goal=JointGoal(prob.goal.joints),
        limits=limits_from_settings(cell.settings),
        time_limit_s=10.0,
        seed=prob.seed,
    )
    plan_with(planner, request, cell.scene, context)
    return time.perf_counter() - t


def run_roboplan(
    sets: dict[str, Path], urdf: str | None, time_limit_s: float
) -> tuple[dict[str, list[dict[str, Any]]], str | None, float]:
    """roboplan on each scene's problems (its RRT-Connect, then its shortcutting), re-checked by twin:
    ({scene: rows}, None, wall s), or ({}, why it was skipped, 0)."""
    try:
        import roboplan_peer
    except ImportError as e:
        return {}, f"bench/roboplan_peer.py does not import: {e}", 0.0
    py = roboplan_peer.roboplan_python()
    if isinstance(py, str):
        return {}, py, 0.0
    rows: dict[str, list[dict[str, Any]]] = {}
    t0 = time.perf_counter()
    watch = ProgressClock()
    for i, (scene, path) in enumerate(sets.items()):
        try:
            planned = roboplan_peer.plan_problem_set(path, urdf, time_limit_s=time_limit_s, shortcut=True, python=py)
        except RuntimeError as e:
            return {}, f"roboplan failed on {scene}: {str(e).splitlines()[0][:200]}", 0.0
        rows[scene] = roboplan_peer.recheck(planned, path, urdf)
        ok = sum(bool(r.get("ok")) for r in rows[scene])
        print(f"[roboplan {watch.stamp(i + 1, len(sets))}] {scene}: {ok}/{len(planned)} solved", file=sys.stderr)
    return rows, None, time.perf_counter() - t0


def scene_list(text: str) -> list[str]:
    """The MBM scenes of 'a,b' in the order given, each once; an unknown name or none is an error that lists
    the allowed ones."""
    scenes = list(dict.fromkeys(s.strip() for s in text.split(",") if s.strip()))
    unknown = [s for s in scenes if s not in SCENES]
    if unknown or not scenes:
        what = f"unknown scene {', '.join(map(repr, unknown))}" if unknown else "no scene given"
        raise argparse.ArgumentTypeError(f"{what}; MotionBenchMaker's UR5 scenes: {', '.join(SCENES)}")
    return scenes


def positive_int(text: str) -> int:
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return n


def first_problems(ps: ProblemSet, n: int | None) -> ProblemSet:
    """`ps` with its first `n` problems only (all of them when `n` is None or not fewer than it has)."""
    return ps if n is None or n >= len(ps.problems) else ps.model_copy(update={"problems": ps.problems[:n]})


def subset_sets(sets: dict[str, Path], n: int | None, folder: Path) -> dict[str, Path]:
    """Each scene's problem-set file cut to its first `n` problems, written into `folder` as
    `<scene>-first<n>.json` (a set with no more than `n` problems is used as it is)."""
    out = {}
    for scene, path in sets.items():
        ps = load_problem_set(path)
        cut = first_problems(ps, n)
        out[scene] = path if cut is ps else save_problem_set(cut, folder / f"{scene}-first{n}.json").resolve()
    return out


class SceneProgress:
    """Progress of the sweep on stderr while it runs (the table comes at the end): a line when a scene's runs are
    all in, and one at every tenth of all the runs, each with the elapsed time and an estimate of the time left,
    '[300/700 01:23 eta 01:51] cage done: 97/100 solved'. `expected`: runs per scene (problems x planners)."""

    def __init__(
        self,
        expected: dict[str, int],
        *,
        clock: Callable[[], float] = time.monotonic,
        write: Callable[[str], None] = lambda line: print(line, file=sys.stderr, flush=True),
    ):
        self.expected = expected
        self.watch = ProgressClock(clock=clock)
        self.write = write
        self.runs: dict[str, int] = dict.fromkeys(expected, 0)
        self.solved: dict[str, int] = dict.fromkeys(expected, 0)
        self._tenth = 0

    def __call__(self, row: dict[str, Any], done: int, total: int) -> None:
        """`run_comparison`'s `on_row`."""
        scene = row["scenario"]
        self.runs[scene] = self.runs.get(scene, 0) + 1
        self.solved[scene] = self.solved.get(scene, 0) + bool(row.get("success"))
        stamp = self.watch.stamp(done, total)
        if self.runs[scene] == self.expected.get(scene):
            self.write(f"[{stamp}] {scene} done: {self.solved[scene]}/{self.runs[scene]} solved")
        elif done * 10 // max(1, total) > self._tenth:
            self.write(f"[{stamp}] {scene}: {self.runs[scene]}/{self.expected.get(scene, '?')} runs")
        self._tenth = done * 10 // max(1, total)


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, not the usage too
        self.exit(2, f"{self.prog}: error: {message}\n")


def parse_args(argv: Sequence[str] | None = None) -> argparse.Namespace:
    ap = _Parser(prog="bench_mbm.py", description=__doc__.split("\n\n")[0])
    ap.add_argument(
        "--planners",
        default=DEFAULT_PLANNERS,
        help=f"comma-separated: twin planner names, {', '.join(ALIASES)}, {ROBOPLAN} (default: {DEFAULT_PLANNERS})",
    )
    ap.add_argument("--time-limit", type=float, default=10.0, help="planning time limit per problem, s")
    ap.add_argument("--workers", type=int, default=None, help="parallel runs (default: all CPUs)")
    ap.add_argument(
        "--scenes", type=scene_list, default=list(SCENES), help="comma-separated MBM scenes (default: all seven)"
    )
    ap.add_argument(
        "--problems", type=positive_int, default=None, metavar="N", help="the first N problems of each scene"
    )
    ap.add_argument("--out", default="out/bench-mbm", help="folder for the comparison")
    ap.add_argument(
        "--robot-urdf",
        choices=("twin", "spherized"),
        default="twin",
        help="collision model: twin's primitive UR5 (default) or MBM's ur5_spherized.urdf (VAMP's)",
    )
    ap.add_argument("--no-cover-price", action="store_true", help="skip the cover's price (item 3; ~25 ms a problem)")
    return ap.parse_args(argv)


def _differences(args: argparse.Namespace, workers: int | None) -> str:
    model = (
        "MBM's ur5_spherized.urdf (VAMP's spheres), checked by FCL"
        if args.robot_urdf == "spherized"
        else "twin's primitive UR5 with its 2F-85-like gripper (VAMP: MBM's spherized UR5 + Robotiq)"
    )
    return (
        f"What differs from VAMP's setup: robot model {model}; {os.cpu_count()} cores of this machine shared by "
        f"{workers if workers is not None else os.cpu_count()} worker process(es) (VAMP: one core of a Ryzen 9 "
        "7950X); twin planners run in a Python process (plan() entered from Python, numba for compiled.rrtconnect, "
        "OMPL's C++ behind Python callbacks for ompl.*); 'total' includes the time parameterisation (toppra), the "
        "planner's own continuous/FCL verification and twin's FCL judge at 0.01 rad / 1 cm (VAMP's 'total' is "
        "search + simplification only); problems are planned with each problem's seed, one run each; roboplan "
        "runs serially in its own process after the twin planners (one core), without retiming or judge."
    )


def main() -> int:
    args = parse_args()
    out = Path(args.out)
    scenes: list[str] = args.scenes
    blocks, labels, peers = planner_blocks(args.planners)
    t0 = time.perf_counter()
    overrides = ["robot.model=ur5"]
    urdf = None
    if args.robot_urdf == "spherized":
        urdf = str(mbm_spherized_urdf())
        overrides.append(f"robot.urdf={urdf}")
    sets = {}
    watch = ProgressClock()
    for i, scene in enumerate(scenes):  # fetched and imported on first use (minutes), then read from the cache
        sets[scene] = mbm_problem_set(f"ur5/{scene}")
        print(f"[import {watch.stamp(i + 1, len(scenes))}] {scene}", file=sys.stderr, flush=True)
    sets = subset_sets(sets, args.problems, out / "problems")
    numbers = {s: [int(p.id.rpartition("#")[2]) for p in load_problem_set(sets[s]).problems] for s in scenes}
    scenarios = [
        {
            "name": scene,
            "scene": "robocup",
            "overrides": overrides,
            "problems": str(sets[scene]),
            "time_limit_s": args.time_limit,
        }
        for scene in scenes
    ]
    import_s = time.perf_counter() - t0
    rows: list[dict[str, Any]] = []
    plan_s = 0.0
    warm_s = warm_compiled(next(iter(sets.values())), urdf) if COMPILED in labels else None
    load = [os.getloadavg()[0]]
    if blocks:
        spec = {
            "name": "mbm-ur5",
            "time_limit_s": args.time_limit,
            "execute": False,
            "planners": blocks,
            "scenarios": scenarios,
        }
        t1 = time.perf_counter()
        progress = SceneProgress({s: len(numbers[s]) * len(blocks) for s in scenes})
        result = run_comparison(
            compare_spec_from_dict(spec), out_dir=out, workers=args.workers, plots=False, on_row=progress
        )
        rows = result.rows
        plan_s = time.perf_counter() - t1
        load.append(os.getloadavg()[0])
    peer_rows: dict[str, list[dict[str, Any]]] = {}
    peer_note = None
    peer_s = 0.0
    if ROBOPLAN in peers:
        peer_rows, peer_note, peer_s = run_roboplan(sets, urdf, args.time_limit)
    price = None if args.no_cover_price else cover_price(sets, urdf)

    model = "MBM's ur5_spherized.urdf" if args.robot_urdf == "spherized" else "twin's urdf/ur5.urdf"
    print(f"\nMotionBenchMaker UR5 on twin ({os.cpu_count()} CPUs here), {model}, time limit {args.time_limit:g} s")
    print(
        f"imported {len(scenes)} scenes in {import_s:.1f} s; twin planners: {len(rows)} runs in {plan_s:.0f} s "
        f"(--workers {args.workers if args.workers is not None else 'all'})"
        + (f"; roboplan: {sum(map(len, peer_rows.values()))} runs in {peer_s:.0f} s" if peer_rows else "")
    )
    print(
        "load average (1 min) before / after the twin sweep: "
        + " / ".join(f"{x:.2f}" for x in load)
        + " (this machine is shared: other processes' load slows every planner here)"
    )
    if warm_s is not None:
        print(f"{COMPILED}: numba cache warmed in this process before the sweep ({warm_s:.1f} s); workers load it")
    if ROBOPLAN in peers and peer_note:
        print(f"roboplan skipped: {peer_note}")
    print(
        f"plan: planning time ({COMPILED}: its search_time_s, the compiled search alone; ompl.*: the whole plan() "
        "call; roboplan: RRT.plan); total: the whole plan() call (search, simplify, retime, verify) + the judge's "
        "final check (roboplan: RRT.plan + shortcut); path: median joint path length, rad; refused: claimed "
        "solutions twin's FCL judge turned down (final_check_collision; roboplan: twin's re-check)\n"
    )
    names = labels + ([ROBOPLAN] if peer_rows else [])
    head = f"{'scene':<18} {'problems':>8} {'valid':>5}  {'planner':<20} {'solved':>7} "
    head += f"{'plan med':>9} {'plan p95':>9} {'total med':>9} {'total p95':>9} {'path':>7} {'refused':>7}"
    units = f"{'':<18} {'':>8} {'':>5}  {'':<20} {'':>7} {'ms':>9} {'ms':>9} {'ms':>9} {'ms':>9} {'rad':>7} {'':>7}"
    print(head)
    print(units)
    print("-" * len(head))

    def stats(name: str, scene: str | None) -> dict[str, Any]:
        if name == ROBOPLAN:
            return peer_stats([r for s, rs in peer_rows.items() if scene in (None, s) for r in rs])
        return twin_stats([r for r in rows if r["planner"] == name and scene in (None, r["scenario"])])

    def block(scene: str | None) -> None:
        n = len(numbers[scene]) if scene else sum(map(len, numbers.values()))
        first = True
        for name in names:
            st = stats(name, scene)
            lead = f"{scene or 'all':<18} {n:>8} {st['valid']:>5}" if first else " " * 33
            print(f"{lead}  {name:<20} {stats_cells(st)}")
            first = False

    for scene in scenes:
        block(scene)
    print("-" * len(head))
    block(None)
    vamp = (
        f"{'VAMP (published)':<18} {700:>8} {VAMP['valid_published']:>5}  {'vamp rrtc (7950X)':<20} "
        f"{'all':>7} {1e-3 * VAMP['planning_median_us']:9.3f} {'-':>9} {1e-3 * VAMP['total_median_us']:9.3f} "
        f"{1e-3 * VAMP['total_p95_us']:9.3f} {'-':>7} {'-':>7}"
    )
    print(vamp)
    print(
        f"\nVAMP (README, vectorised RRT-Connect, Ryzen 9 7950X, one core): valid {VAMP['valid_published']}/700 (its "
        f"0.6.4 sphere model: {VAMP['valid_0.6.4_model']}), solved all valid; planning median "
        f"{VAMP['planning_median_us']:g} us, with simplification median {VAMP['total_median_us']:g} us, p95 "
        f"{VAMP['total_p95_us']:g} us"
    )
    print(_differences(args, args.workers))
    overall = {name: stats(name, None) for name in names}
    for name in names:
        st = overall[name]
        fails = ", ".join(f"{k} {v}" for k, v in sorted(st["failures"].items())) or "none"
        extra = f"; its own scene calls {st['own_valid']} valid" if "own_valid" in st else ""
        print(
            f"{name}: valid unsolved by reason: {fails}; other judge verdicts on claimed successes: "
            f"{st['judge_other']}{extra}"
        )
    over = [
        (name, sum(_total_time(r) > args.time_limit for r in rows if r["planner"] == name and r.get("success")))
        for name in labels
    ]
    if any(k for _, k in over):
        print("solved, but the total past the time limit: " + ", ".join(f"{n} {k}" for n, k in over if k))
    lines = ratio_lines(overall)
    if lines:
        print("\nratios (over all scenes):")
        print("\n".join(lines))
    if COMPILED in labels:
        steps = ("model", "search", "simplify", "certify", "retime", "verify")
        solved = [r for r in rows if r["planner"] == COMPILED and r.get("success")]
        parts = []
        for step in steps + ("final_check",):
            v = [r["step_times_s"][step] for r in solved if (r.get("step_times_s") or {}).get(step) is not None]
            if v:
                parts.append(f"{step} {1e3 * float(np.median(v)):.3f}")
        if parts:
            print(f"\n{COMPILED} step medians over its solved runs, ms: " + ", ".join(parts))
    if rows:
        print("\n" + "\n".join(_validity_lines(rows, numbers, scenes)))
    if price is not None:
        print(
            "\nthe cover's price: problems valid in the exact model (start and goal FCL-free) whose start or goal "
            "the planning model (sphere_model(), 0 clearance) calls touching"
        )
        print(f"{'scene':<18} {'valid':>5} {'touching':>8} {'start':>5} {'goal':>5}  MBM numbers")
        for scene, p in price.items():
            which = ", ".join(f"{k:04d}" for k in p["which"]) or "-"
            print(f"{scene:<18} {p['valid']:>5} {p['touching']:>8} {p['start']:>5} {p['goal']:>5}  {which}")
        tot = {k: sum(p[k] for p in price.values()) for k in ("valid", "touching", "start", "goal")}
        print(f"{'all':<18} {tot['valid']:>5} {tot['touching']:>8} {tot['start']:>5} {tot['goal']:>5}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
