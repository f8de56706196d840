"""The field's own benchmark on the twin: MotionBenchMaker's UR5 suite (7 scenes x 100 problems), planned by
twin's planners through twin's judge, beside the numbers VAMP publishes for it (issue 30). A plain script: it
prints a table and asserts nothing.

    python bench/bench_mbm.py [--planners ompl.rrtconnect,ompl.bitstar] [--time-limit 10] [--workers N]
                              [--scenes box,cage] [--problems N] [--out out/bench-mbm]
                              [--robot-urdf twin|spherized]

`--scenes` and `--problems N` pick a subset of the suite: those scenes (a name not in MBM's UR5 suite is a
one-line error listing the ones that are), the first N problems of each (MBM's file order).

The problems are `twin.problems.mbm`'s (vamp-planner 0.6.4's source distribution, fetched by pip into twin's
cache once, each scene imported as `twin problems import-moveit DIR --robot ur5` does: a world per problem),
planned by `twin compare` for `robot.model: ur5` (twin's
primitive UR5 with its 2F-85-like gripper, or with `--robot-urdf spherized` MBM's own spheres-only model of the
UR5 and its Robotiq gripper, the one VAMP checks) without execution: every plan is re-checked by the judge every
0.01 rad / 1 cm of tool travel against the problem's scene and must end on the joint goal.

Per scene: the problems, those valid in twin's model (start and goal collision-free), and per planner the
problems solved, the median and 95th percentile of planning time and the median joint path length.
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


def _row_stats(rows: list[dict[str, Any]]) -> tuple[int, int, str]:
    """(valid, solved, 'median p95 path') of one planner's rows of one scene."""
    valid = [r for r in rows if r.get("failure") not in INVALID]
    solved = [r for r in valid if r.get("success")]
    t = np.array([r["timing"]["planning_time_s"] for r in solved], dtype=float)
    path = [r["metrics"]["joint_path_length_rad"] for r in solved if r["metrics"].get("joint_path_length_rad")]
    if not solved:
        return len(valid), 0, f"{'-':>9} {'-':>9} {'-':>7}"
    return (
        len(valid),
        len(solved),
        f"{1e3 * np.median(t):9.1f} {1e3 * np.percentile(t, 95):9.1f} {np.median(path) if path else float('nan'):7.2f}",
    )


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
    ap.add_argument("--planners", default="ompl.rrtconnect", help="comma-separated planner names")
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
    return ap.parse_args(argv)


def main() -> int:
    args = parse_args()
    out = Path(args.out)
    scenes: list[str] = args.scenes
    t0 = time.perf_counter()
    overrides = ["robot.model=ur5"]
    if args.robot_urdf == "spherized":
        overrides.append(f"robot.urdf={mbm_spherized_urdf()}")
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
    planners = [p.strip() for p in args.planners.split(",") if p.strip()]
    spec = {
        "name": "mbm-ur5",
        "time_limit_s": args.time_limit,
        "execute": False,
        "planners": planners,
        "scenarios": scenarios,
    }
    t1 = time.perf_counter()
    progress = SceneProgress({s: len(numbers[s]) * len(planners) for s in scenes})
    result = run_comparison(
        compare_spec_from_dict(spec), out_dir=out, workers=args.workers, plots=False, on_row=progress
    )
    plan_s = time.perf_counter() - t1

    model = "MBM's ur5_spherized.urdf" if args.robot_urdf == "spherized" else "twin's urdf/ur5.urdf"
    print(f"\nMotionBenchMaker UR5 on twin ({os.cpu_count()} CPUs here), {model}, time limit {args.time_limit:g} s")
    print(f"imported {len(scenes)} scenes in {import_s:.1f} s; planned {len(result.rows)} runs in {plan_s:.0f} s\n")
    head = f"{'scene':<18} {'problems':>8} {'valid':>5}  {'planner':<22} {'solved':>7} "
    head += f"{'med ms':>9} {'p95 ms':>9} {'path':>7}"
    print(head)
    print("-" * len(head))
    totals: dict[str, list[int]] = {}
    valid_total = n_total = 0
    for scene in scenes:
        mine = [r for r in result.rows if r["scenario"] == scene]
        n = len({r["case"] for r in mine})
        first = True
        for planner in planners:
            rows = [r for r in mine if r["planner"] == planner]
            valid, solved, stats = _row_stats(rows)
            if first:
                valid_total += valid
                n_total += n
            lead = f"{scene:<18} {n:>8} {valid:>5}" if first else " " * 33
            print(f"{lead}  {planner:<22} {solved:>3}/{valid:<3} {stats}")
            t = totals.setdefault(planner, [0, 0])
            t[0] += solved
            t[1] += valid
            first = False
    print("-" * len(head))
    for planner, (solved, valid) in totals.items():
        rows = [r for r in result.rows if r["planner"] == planner]
        _, _, stats = _row_stats(rows)
        print(f"{'all':<18} {n_total:>8} {valid_total:>5}  {planner:<22} {solved:>3}/{valid:<3} {stats}")
    print(
        f"\nVAMP (README, vectorised RRT-Connect, Ryzen 9 7950X): valid {VAMP['valid_published']}/700 (its 0.6.4 "
        f"sphere model: {VAMP['valid_0.6.4_model']}), solved all valid; "
        f"planning median {VAMP['planning_median_us']:g} us, with simplification median "
        f"{VAMP['total_median_us']:g} us, p95 {VAMP['total_p95_us']:g} us"
    )
    print("\n".join(_validity_lines(result.rows, numbers, scenes)))
    for planner in totals:
        rows = [r for r in result.rows if r["planner"] == planner and r.get("success")]
        if rows:
            med = float(np.median([r["timing"]["planning_time_s"] for r in rows]))
            ratio = med / (VAMP["total_median_us"] * 1e-6)
            print(f"{planner}: median planning {1e3 * med:.1f} ms = {ratio:.0f}x VAMP's total median")
    return 0


if __name__ == "__main__":
    sys.exit(main())
