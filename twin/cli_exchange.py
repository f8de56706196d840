"""The command line of what twin exchanges with other tools: problem sets in and out (`twin problems`),
results out as OMPL benchmark logs and a Planner Arena database (`twin export`) and as a LaTeX table for a
paper (`twin report --latex`).

Kept apart from `twin.cli` (which runs and compares) so that each stays a thin layer over one library
module: `twin.problems`, `twin.compare.ompl_export` and `twin.compare.latex`.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from twin.config import apply_override
from twin.errors import ConfigError

__all__ = ["COMMANDS", "add_parsers"]

EXIT_OK = 0


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {v}")
    return v


def add_parsers(sub: Any) -> None:
    """Add `problems`, `export` and `report` to the `twin` subcommand parsers `sub`."""
    p = sub.add_parser("problems", help="problem sets: export a scene's queries, import MoveIt scenes (JSON files)")
    psub = p.add_subparsers(dest="problems_command", metavar="ACTION", required=True)
    e = psub.add_parser("export", help="seeded random motion queries of a scene config as a problem-set file")
    e.add_argument("config", help="scene config (a file or a shipped name: robocup, warehouse)")
    e.add_argument("--count", type=_positive_int, required=True, help="number of problems")
    e.add_argument("--seed", type=int, default=0, help="seed of the draw and of each problem (default 0)")
    e.add_argument("--out", required=True, metavar="FILE.json", help="problem-set file to write")
    e.add_argument(
        "--name", default=None, help="set name; the same as a compare scenario's name draws that scenario's queries"
    )
    e.add_argument("--goal", choices=("joint", "pose", "position"), default="joint", help="goal kind (default joint)")
    e.add_argument(
        "--straight",
        choices=("free", "blocked", "any"),
        default="any",
        help="keep queries whose straight joint motion is free / blocked (default any)",
    )
    e.add_argument("--time-limit", type=float, default=1.0, help="planning time limit per problem, s (default 1)")
    e.add_argument(
        "--set",
        dest="random_overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="another random-query setting, e.g. --set region_z=[0.05,0.3] (see RandomQueries)",
    )
    m = psub.add_parser(
        "import-moveit",
        help="a MoveIt PlanningScene YAML + MotionPlanRequest YAMLs, or a directory of MotionBenchMaker "
        "sceneNNNN.yaml/requestNNNN.yaml pairs, as a problem set",
    )
    m.add_argument(
        "scene",
        help="YAML of a moveit_msgs/PlanningScene, or a directory of MotionBenchMaker pairs (each problem in its "
        "own scene: a version-2 problem set)",
    )
    m.add_argument("requests", nargs="*", help="YAML files of moveit_msgs/MotionPlanRequest (not with a directory)")
    m.add_argument(
        "--robot",
        default=None,
        choices=("ur5",),
        help="the MoveIt files' robot: MotionBenchMaker's UR5 (robot.model ur5, its Robotiq joints ignored, "
        "base_link 0.9144 m above its world frame)",
    )
    m.add_argument("--out", required=True, metavar="FILE.json", help="problem-set file to write")
    m.add_argument("--config", default="robocup", help="twin config of the robot (default robocup)")
    m.add_argument("--name", default=None, help="set name (default: the scene's name)")
    m.add_argument("--time-limit", type=float, default=None, help="time limit per problem, s (default: the request's)")
    m.add_argument(
        "--frames",
        choices=("ur_description", "twin"),
        default="ur_description",
        help="what base_link means: ROS's UR description (default; turned 180 deg about z from twin's) or twin's",
    )
    m.add_argument(
        "--ignore-joints",
        action="append",
        default=[],
        metavar="PATTERN",
        help="joints of the start state to ignore (names or globs, e.g. 'robotiq_85_*' in MotionBenchMaker's UR5)",
    )
    s = psub.add_parser("schema", help="print the JSON Schema of problem-set files")
    s.add_argument("--out", default=None, metavar="FILE.json", help="write it here instead")

    x = sub.add_parser("export", help="results.jsonl as OMPL benchmark logs and a Planner Arena database")
    x.add_argument("results", help="a results.jsonl of `twin compare` (or its output folder)")
    x.add_argument("--out", required=True, metavar="DIR", help="folder for the .log files and the .db")
    x.add_argument("--name", default=None, help="experiment name prefix (default: the results folder's name)")

    r = sub.add_parser("report", help="a sweep's results as a table for a paper (booktabs LaTeX)")
    r.add_argument("results", help="a results.jsonl of `twin compare` (or its output folder)")
    r.add_argument(
        "--latex",
        required=True,
        metavar="OUT.tex",
        help="write a booktabs table: per scenario and planner the success rate with its Wilson interval and n, "
        "median planning time and duration with their bootstrap intervals (\\usepackage{booktabs})",
    )
    r.add_argument("--caption", default=None, help="the table's caption, as LaTeX (default: what the columns are)")
    r.add_argument("--label", default=None, help="the table's \\label (default tab:planner-comparison)")


def _cmd_problems(args: argparse.Namespace) -> int:
    from twin.problems import json_schema, save_problem_set  # lazy: cli start-up

    if args.problems_command == "schema":
        text = json.dumps(json_schema(), indent=1) + "\n"
        if args.out:
            Path(args.out).write_text(text, encoding="utf-8")
        else:
            print(text, end="")
        return EXIT_OK
    if args.problems_command == "export":
        from twin.problems import export_problem_set  # lazy: cli start-up

        random: dict[str, Any] = {"goal": args.goal, "straight": args.straight}
        for o in args.random_overrides:
            apply_override(random, o)
        ps = export_problem_set(
            args.config,
            count=args.count,
            seed=args.seed,
            name=args.name,
            random=random,
            time_limit_s=args.time_limit,
        )
    else:
        from twin.problems import problem_set_from_moveit, problem_set_from_moveit_dir  # lazy: cli start-up

        options: dict[str, Any] = {
            "config": args.config,
            "name": args.name,
            "time_limit_s": args.time_limit,
            "frames": args.frames,
            "ignore_joints": tuple(args.ignore_joints),
            "robot": args.robot,
        }
        if Path(args.scene).is_dir():
            if args.requests:
                raise ConfigError(f"{args.scene} is a directory of scene/request pairs: give no request files with it")
            ps = problem_set_from_moveit_dir(args.scene, **options)
        elif not args.requests:
            raise ConfigError("give the MotionPlanRequest YAML files after the scene (or a directory of pairs)")
        else:
            ps = problem_set_from_moveit(args.scene, args.requests, **options)
    path = save_problem_set(ps, args.out)
    own = [p.world for p in ps.problems if p.world is not None]
    if own:
        mean = sum(len(w.objects) for w in own) / len(own)
        print(f"{path}: {len(ps.problems)} problems, {len(own)} in their own scenes ({mean:.3g} objects on average)")
    else:
        n_prims = sum(len(o.primitives) for o in ps.world.objects)
        print(
            f"{path}: {len(ps.problems)} problems, {len(ps.world.objects)} objects ({n_prims} primitives) "
            f"in frame {ps.world.frame}"
        )
    return EXIT_OK


def _cmd_export(args: argparse.Namespace) -> int:
    from twin.compare.ompl_export import export_planner_arena  # lazy: cli start-up
    from twin.compare.runner import (  # lazy: cli start-up
        RESULTS_FILE,
        latest_rows,
        read_results,
        recorded_environment,
    )

    src = Path(args.results)
    path = src / RESULTS_FILE if src.is_dir() else src
    if not path.is_file():
        raise ConfigError(f"no results file at {path} (give a results.jsonl or the folder that holds one)")
    rows = latest_rows(read_results(path))
    name = args.name or path.resolve().parent.name
    # where the rows ran, as their sweep recorded it; not this machine (unknown when nothing was recorded)
    files = export_planner_arena(rows, args.out, name=name, environment=recorded_environment(path) or {})
    print(f"{len(rows)} runs -> " + ", ".join(str(f) for f in files))
    return EXIT_OK


def _cmd_report(args: argparse.Namespace) -> int:
    from twin.compare.latex import DEFAULT_LABEL, latex_report  # lazy: cli start-up

    path, summary = latex_report(args.results, args.latex, caption=args.caption, label=args.label or DEFAULT_LABEL)
    scenarios = len(dict.fromkeys(r.scenario for r in summary.by_scenario))
    print(f"{path}: {len(summary.overall)} planners x {scenarios} scenarios (needs \\usepackage{{booktabs}})")
    return EXIT_OK


COMMANDS = {"problems": _cmd_problems, "export": _cmd_export, "report": _cmd_report}
