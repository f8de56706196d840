"""The `twin` command line: a thin layer that parses, calls one library function, and reports.

A user mistake (bad config, unknown name, bad value, missing file) prints one line and exits 2.
Exit 1 is a result that fell short, never a mistake: `twin plan` when the planner found no solution, `twin
run` when an object was not placed (a script or CI job sees a failed run without reading the table),
`twin compare --baseline` when the gate fails, `twin check-planner` when a rule breaks.
Exit 3 is a plugin that failed: it raised an exception of its own or broke the planner contract (`twin plan`;
`twin run` when a stage failed so, even one a retry recovered from: the stage fails with the plugin's exception
and the run goes on). One line names the plugin and the exception; `-v` adds its traceback.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import os
import re
import sys
import textwrap
import time
from collections import Counter
from collections.abc import Callable, Iterable, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, NoReturn

# light (most are loaded by `import twin` already); what one command needs loads in it, so `--help` stays fast
from twin import tasks  # `tasks.run_task`, looked up when a run starts (tests put a stand-in there)
from twin.cli_exchange import COMMANDS as EXCHANGE_COMMANDS
from twin.cli_exchange import add_parsers as add_exchange_parsers
from twin.config import load_config
from twin.config.loader import apply_override
from twin.errors import ConfigError, InvalidRequestError, PlanningError, TwinError
from twin.faults import fault_overrides
from twin.registry import default_registry
from twin.timing import format_breakdown, process_age_s
from twin.transforms import matrix_to_rpy
from twin.types import JointGoal, MotionRequest, Pose, PoseGoal

if TYPE_CHECKING:
    from twin.compare import DryRun
    from twin.progress import ProgressClock

__all__ = ["build_parser", "main"]

EXIT_OK, EXIT_NO_SOLUTION, EXIT_USAGE = 0, 1, 2
EXIT_NOT_PLACED = EXIT_NO_SOLUTION  # `twin run`: an object did not end in its bin
EXIT_PLUGIN_ERROR = 3  # a plugin raised an exception of its own or broke its contract


# a comma-separated list of numbers as a user types it, e.g. "-0.5,-1.5708,1.5708" (inf/nan included, so
# that `_floats` can say what is wrong with them rather than argparse calling the value an option)
_NUMBER = r"[-+]?(?:\d+\.?\d*(?:[eE][-+]?\d+)?|\.\d+(?:[eE][-+]?\d+)?|inf|infinity|nan)"
_NUMBER_LIST = re.compile(rf"\s*{_NUMBER}\s*(?:,\s*{_NUMBER}\s*)*,?\s*", re.IGNORECASE)


class _Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (and exit 2), like every other user mistake, and a vector
    option takes a value that begins with a minus sign (`--start -0.5,-1.57,...`), as users type it."""

    def error(self, message: str) -> NoReturn:
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(EXIT_USAGE)

    def parse_known_args(self, args: Iterable[str] | None = None, namespace: Any = None) -> tuple[Any, list[str]]:
        """Join `--start -0.5,...` into `--start=-0.5,...` first: argparse reads a separate value that
        begins with '-' (and is not one plain number) as another option and reports a missing argument."""
        argv = list(sys.argv[1:] if args is None else args)
        return super().parse_known_args(self._join_vector_values(argv), namespace)

    def _join_vector_values(self, argv: list[str]) -> list[str]:
        vector_options = {o for o, a in self._option_string_actions.items() if getattr(a.type, "is_vector", False)}
        if not vector_options:
            return argv
        out: list[str] = []
        i = 0
        while i < len(argv):
            arg = argv[i]
            if arg == "--":  # everything after it is positional
                out.extend(argv[i:])
                break
            option = self._vector_option(arg, vector_options)
            if (
                option is not None
                and i + 1 < len(argv)
                and argv[i + 1].startswith("-")
                and _NUMBER_LIST.fullmatch(argv[i + 1])
            ):
                out.append(f"{option}={argv[i + 1]}")
                i += 2
                continue
            out.append(arg)
            i += 1
        return out

    def _vector_option(self, arg: str, vector_options: set[str]) -> str | None:
        """The vector option `arg` names, exactly or as the unique abbreviation argparse would accept."""
        if arg in vector_options:
            return arg
        if not arg.startswith("--") or "=" in arg or not self.allow_abbrev:
            return None
        matches = [o for o in self._option_string_actions if o.startswith(arg)]
        return matches[0] if len(matches) == 1 and matches[0] in vector_options else None


def _floats(text: str, n: int, what: str) -> list[float]:
    parts = [p for p in text.replace(" ", "").split(",") if p]
    try:
        vals = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{what} must be {n} comma-separated numbers, got {text!r}") from None
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise argparse.ArgumentTypeError(
            f"{what} must be {n} comma-separated finite numbers, got {len(vals)} in {text!r}"
        )
    return vals


def _joint_vector(text: str) -> list[float]:
    return _floats(text, 6, "joint angles (rad)")


def _pose_vector(text: str) -> list[float]:
    return _floats(text, 6, "pose x,y,z,roll,pitch,yaw (m, rad)")


def _position_vector(text: str) -> list[float]:
    return _floats(text, 3, "position x,y,z (m)")


def _count(text: str) -> int:
    """A positive integer argument (a count)."""
    value = _seed(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a positive integer, got {text!r}")
    return value


def _seed(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer, got {text!r}") from None
    if value < 0:
        raise argparse.ArgumentTypeError(f"must be a non-negative integer, got {text!r}")
    if value > 2**63 - 1:
        raise argparse.ArgumentTypeError(f"must be below 2**63, got {text!r}")
    return value


# argument types whose values are comma-separated numbers: their options accept a leading minus sign
_joint_vector.is_vector = True  # type: ignore[attr-defined]
_pose_vector.is_vector = True  # type: ignore[attr-defined]
_position_vector.is_vector = True  # type: ignore[attr-defined]


def _add_config_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", help="YAML config file (see configs/)")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a config value by dotted key, e.g. --set world.objects.lying_probability=0.5",
    )
    p.add_argument(
        "--seed", type=_seed, default=None, help="scene seed, a non-negative integer (default: the config's seed)"
    )
    p.add_argument(
        "--faults",
        default=None,
        metavar="NAME",
        help="a named fault set on top of the config (twin.faults: nominal, stress), before any --set",
    )


_AFTER = "_after_command"  # where -v/-q given after the command land, until `_MainParser` adds them in


def _add_verbosity(p: argparse.ArgumentParser, *, after_command: bool) -> None:
    """-v/-q on the main parser and on every command's: `twin -v run X` and `twin run X -v` parse the same.
    After the command they default to SUPPRESS and land apart (argparse copies a command's namespace over
    the main one), so `twin -v run X -v` counts two."""
    suffix, quiet = (_AFTER, argparse.SUPPRESS) if after_command else ("", False)
    p.add_argument(
        "-v",
        "--verbose",
        dest="verbose" + suffix,
        action="count",
        default=argparse.SUPPRESS if after_command else 0,
        help="log more on stderr: -v what each step does (info), -vv debug; before or after the command",
    )
    p.add_argument(
        "-q",
        "--quiet",
        dest="quiet" + suffix,
        action="store_true",
        default=quiet,
        help="log errors only, and show no progress display; before or after the command",
    )


class _MainParser(_Parser):
    """The `twin` parser: -v/-q given after the command are added to those given before it."""

    def parse_known_args(self, args: Iterable[str] | None = None, namespace: Any = None) -> tuple[Any, list[str]]:
        ns, rest = super().parse_known_args(args, namespace)
        ns.verbose = getattr(ns, "verbose", 0) + vars(ns).pop("verbose" + _AFTER, 0)
        ns.quiet = bool(getattr(ns, "quiet", False) or vars(ns).pop("quiet" + _AFTER, False))
        if ns.verbose and ns.quiet:
            self.error("-v/--verbose and -q/--quiet exclude each other")
        return ns, rest


def build_parser() -> argparse.ArgumentParser:
    parser = _MainParser(
        prog="twin",
        description="A PyBullet digital twin of a UR5e sorting cell: plan, run and compare motion planners.",
    )
    _add_verbosity(parser, after_command=False)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    _add_planners_parser(sub)
    _add_scene_parser(sub)
    _add_plan_parser(sub)
    _add_run_parser(sub)
    _add_compare_parser(sub)
    _add_perceive_parser(sub)
    _add_calibrate_parser(sub)
    _add_replay_parser(sub)
    _add_check_planner_parser(sub)
    _add_dataset_parser(sub)
    add_exchange_parsers(sub)
    for p in {id(p): p for p in sub.choices.values()}.values():  # `twin run X -v` as `twin -v run X`
        _add_verbosity(p, after_command=True)
    return parser


def _add_planners_parser(sub: Any) -> None:
    """`twin planners`."""
    p = sub.add_parser("planners", help="list every registered planner, retimer and detector")
    p.add_argument("--json", dest="json_path", default=None, help="also write the list to this JSON file")


def _add_scene_parser(sub: Any) -> None:
    """`twin scene`."""
    p = sub.add_parser("scene", help="build a scene and render it from the configured camera and an overview")
    _add_config_args(p)
    p.add_argument("--snapshot", required=True, help="output PNG (camera view | overview side by side)")


def _add_plan_parser(sub: Any) -> None:
    """`twin plan`."""
    p = sub.add_parser("plan", help="plan one motion query with a named planner")
    _add_config_args(p)
    p.add_argument(
        "--planner",
        required=True,
        help="registered planner name, e.g. ruckig.movej (see `twin planners`); its parameters: "
        "--set planners.transfer.params.KEY=VALUE",
    )
    p.add_argument("--start", required=True, type=_joint_vector, help="six comma-separated joint angles, rad")
    goal = p.add_mutually_exclusive_group(required=True)
    goal.add_argument("--goal", type=_joint_vector, help="six comma-separated joint angles, rad")
    goal.add_argument(
        "--goal-pose", type=_pose_vector, help="tcp pose in the base frame: x,y,z,roll,pitch,yaw (m, rad)"
    )
    goal.add_argument(
        "--goal-position",
        type=_position_vector,
        help="tcp position in the base frame, orientation free (a task's transfer goal): x,y,z (m)",
    )
    p.add_argument(
        "--position-tolerance",
        type=float,
        default=None,
        metavar="M",
        help="with --goal-position: how near the tcp must end, m (default: the config's task.transfer_tolerance_m)",
    )
    p.add_argument("--time-limit", type=float, default=1.0, help="planning time limit, s (default 1)")
    p.add_argument(
        "--json", dest="json_path", default=None, help="write status, reason, planning_time_s and t, q, qd, qdd here"
    )


def _add_run_parser(sub: Any) -> None:
    """`twin run`."""
    p = sub.add_parser("run", help="run a sorting task end to end (perception to placed objects) and judge it")
    _add_config_args(p)
    p.add_argument(
        "--planner",
        default=None,
        help="transfer planner name: replaces the config's planners.transfer block, whose params and retimer were "
        "the old planner's; give the new one's with --set planners.transfer.params.KEY=VALUE (checked by it)",
    )
    p.add_argument("--gui", action="store_true", help="open PyBullet's window")
    p.add_argument(
        "--record", default=None, metavar="PATH", help="write a video of the run (.mp4 or .gif) from an overview camera"
    )
    p.add_argument(
        "--speed",
        type=float,
        default=None,
        metavar="X",
        help="with --record: the video plays X times faster than the run (default 1: real time)",
    )
    p.add_argument(
        "--rerun",
        default=None,
        metavar="OUT.rrd",
        help="write a Rerun recording of the run (3-D cell over simulated time, stages, plans, verdicts; open it"
        " with `rerun OUT.rrd`; needs twin[viz])",
    )
    p.add_argument(
        "--rerun-serve",
        action="store_true",
        help="watch the run live in Rerun's web viewer, served on 127.0.0.1 (the address is printed; the server keeps"
        " serving after the run until stopped; needs twin[viz])",
    )
    p.add_argument("--json", dest="json_path", default=None, help="write the run summary here")


def _add_compare_parser(sub: Any) -> None:
    """`twin compare`."""
    p = sub.add_parser(
        "compare", help="compare planners: planners x scenarios x seeds -> results.jsonl, summary, plots"
    )
    p.add_argument("config", help="comparison YAML (see configs/compare.yaml, configs/compare-smoke.yaml)")
    p.add_argument(
        "--set",
        dest="overrides",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="override a comparison config value by dotted key, e.g. --set seeds=[0]",
    )
    p.add_argument("--out", default=None, metavar="DIR", help="output folder (default: out/<name> of the config)")
    p.add_argument(
        "--workers", type=int, default=None, metavar="N", help="parallel runs (default: all CPUs; 0: in this process)"
    )
    p.add_argument(
        "--backend", choices=("local", "ray"), default="local", help="local process pool (default) or Ray (twin[ray])"
    )
    p.add_argument(
        "--resume",
        action="store_true",
        help="continue the sweep in DIR: skip runs already in results.jsonl, rerun those that ended in 'error'",
    )
    p.add_argument(
        "--force",
        action="store_true",
        help="with --resume: accept a changed config (its changed runs are run anew; old rows leave the summary)",
    )
    p.add_argument(
        "--dry-run",
        action="store_true",
        help="check every planner block and scenario and count the runs; run and write nothing",
    )
    p.add_argument(
        "--export-ompl",
        default=None,
        metavar="DIR",
        help="also write the results as OMPL benchmark logs and a Planner Arena database (twin export)",
    )
    p.add_argument(
        "--latex", default=None, metavar="OUT.tex", help="also write the summary as a booktabs table (twin report)"
    )
    p.add_argument(
        "--baseline",
        default=None,
        metavar="RESULTS.jsonl",
        help="regression gate: exit 1 when a planner's success drops or its p95 planning time or duration grows "
        "beyond the tolerance on the runs this sweep shares with the baseline AND a paired test says the change is "
        "significant (p < 0.05); a check with too few paired runs (success: 6, a p95: 20) says 'not enough runs'",
    )
    p.add_argument(
        "--tolerance",
        default=None,
        metavar="KEY=VALUE,...",
        help="with --baseline, how large a change matters: success=0 (drop), planning_time=1.0 (relative growth of "
        "the p95), planning_time_abs_s=0.005, duration=0.05 (relative)",
    )


def _add_perceive_parser(sub: Any) -> None:
    """`twin perceive`."""
    p = sub.add_parser(
        "perceive", help="run the configured perception pipeline on a seeded scene and score it against ground truth"
    )
    _add_config_args(p)
    p.add_argument(
        "--detector", default=None, help="detector plugin (replaces perception.detector.name), e.g. geometric, oracle"
    )
    p.add_argument(
        "--json", dest="json_path", default=None, help="write objects, false_positives, calibration, timings here"
    )


def _add_dataset_parser(sub: Any) -> None:
    """`twin dataset`."""
    p = sub.add_parser(
        "dataset",
        help="labelled images from the task's camera (YOLO and COCO), labels from the renderer's segmentation",
    )
    _add_config_args(p)
    p.add_argument("--images", type=_count, required=True, help="number of images")
    p.add_argument("--out", required=True, metavar="DIR", help="output folder (images, labels, coco, card)")
    p.add_argument("--views", type=_count, default=4, help="camera poses per scene seed (default 4)")
    p.add_argument(
        "--min-visible",
        type=float,
        default=0.3,
        help="label an object when at least this fraction of it is visible (default 0.3)",
    )
    p.add_argument(
        "--clutter", type=_seed, default=4, help="up to this many extra objects per scene, from the seed (default 4)"
    )
    p.add_argument(
        "--min-objects",
        type=_seed,
        default=1,
        help="each scene keeps from this many to all of the config's objects, from the seed, so tables with few"
        " objects left are seen too (default 1; the config's object count or more keeps all)",
    )


def _add_calibrate_parser(sub: Any) -> None:
    """`twin calibrate`."""
    p = sub.add_parser(
        "calibrate", help="estimate the camera-to-base transform from the base ArUco marker; error against the truth"
    )
    _add_config_args(p)
    p.add_argument("--json", dest="json_path", default=None, help="write the calibration (errors and poses) here")


def _add_replay_parser(sub: Any) -> None:
    """`twin replay`."""
    p = sub.add_parser(
        "replay", help="run one comparison row again with a Rerun recording, and say what differs from the stored row"
    )
    p.add_argument("results", help="a sweep's results.jsonl (or its folder, with the compare.json beside it)")
    p.add_argument("run_id", help="the row's run_id (the summary lists the replay command of each failed row)")
    p.add_argument("--rerun", required=True, metavar="OUT.rrd", help="where the recording goes (needs twin[viz])")


def _add_check_planner_parser(sub: Any) -> None:
    """`twin check-planner`."""
    p = sub.add_parser(
        "check-planner", help="check a planner against the planner contract (twin.testing.check_planner)"
    )
    p.add_argument("name", help="registered planner name, e.g. ompl.rrtconnect (see `twin planners`)")
    p.add_argument(
        "--config",
        default=None,
        help="config (a file or a shipped name) whose scene and limits are used (default: robocup)",
    )
    p.add_argument(
        "--seed", type=_seed, default=0, help="seed of the queries and requests, a non-negative integer (default 0)"
    )
    p.add_argument("--time-limit", type=float, default=1.0, help="the requests' planning time limit, s (default 1)")
    p.add_argument(
        "--param",
        dest="params",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        help="a planner parameter (validated by the planner), e.g. --param mode=whole_arm; repeatable",
    )
    p.add_argument(
        "--json", dest="json_path", default=None, help="write the verdict of every rule and the requests asked here"
    )


def _settings(args: argparse.Namespace, *, transfer_planner: str | None = None) -> Any:
    """The config with `--set` overrides; `transfer_planner` (`--planner`) swaps the whole `planners.transfer`
    block before them, so `--set planners.transfer.params.K=V` reaches it and is validated by its own model
    (twin.config.swap_planner)."""
    overrides = [*(fault_overrides(args.faults) if args.faults else ()), *args.overrides]
    planners = {"transfer": transfer_planner} if transfer_planner is not None else None
    settings = load_config(args.config, overrides, planners=planners)
    if args.seed is not None:
        settings = settings.model_copy(update={"seed": args.seed})
    return settings


def _write_json(path: str, data: Any) -> None:
    try:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_text(json.dumps(data, indent=1))
    except OSError as e:
        raise ConfigError(f"cannot write {path}: {e.strerror}") from None


def _cmd_planners(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    entries = default_registry().entries()
    # asking each entry imports its backend (never builds a planner): a name whose backend is missing
    # or lacks the class is listed as unavailable, with the reason
    available = {e.name: e.availability() for e in entries}
    table = Table(title="registered plugins")
    for col in ("name", "kind", "provided by", "available", "description"):
        table.add_column(col)
    for e in entries:
        a = available[e.name]
        table.add_row(e.name, e.kind.value, e.provider, "yes" if a else f"no: {a.reason}", e.description)
    Console(width=200).print(table)
    if args.json_path:
        _write_json(
            args.json_path,
            [
                {
                    "name": e.name,
                    "kind": e.kind.value,
                    "provider": e.provider,
                    "description": e.description,
                    "available": available[e.name].available,
                    "unavailable_reason": available[e.name].reason or None,
                }
                for e in entries
            ],
        )
    return EXIT_OK


def _cmd_scene(args: argparse.Namespace) -> int:
    from twin.snapshot import save_snapshot  # lazy: cli start-up

    settings = _settings(args)
    out = save_snapshot(settings, args.snapshot)
    print(f"wrote {out}")
    return EXIT_OK


def _plan_goal(args: argparse.Namespace, settings: Any) -> Any:
    """The goal of `twin plan`: joints, a tcp pose, or a tcp position within a tolerance (orientation free)."""
    if args.position_tolerance is not None and args.goal_position is None:
        raise InvalidRequestError("--position-tolerance goes with --goal-position (a joint or pose goal is exact)")
    if args.goal is not None:
        return JointGoal(args.goal)
    if args.goal_pose is not None:
        x, y, z, roll, pitch, yaw = args.goal_pose
        return PoseGoal(Pose.from_xyz_rpy((x, y, z), (roll, pitch, yaw)))
    tol = settings.task.transfer_tolerance_m if args.position_tolerance is None else args.position_tolerance
    if not (math.isfinite(tol) and tol > 0):
        raise InvalidRequestError(f"--position-tolerance must be a positive number of metres, got {tol}")
    # the orientation is free; the pose's (tool pointing down, as a task's transfer ends) only tells a planner
    # that starts from an IK solution which one to try first
    return PoseGoal(
        Pose.from_xyz_rpy(tuple(args.goal_position), (math.pi, 0.0, 0.0)),
        position_tolerance_m=tol,
        orientation_tolerance_rad=None,
    )


def _scene_line(scene: Any) -> str:
    """The planning scene's objects on one line; the perceived ones (`known: false`) marked."""
    boxes = scene.boxes()
    names = [f"{n} (known: false, as a box)" if n in boxes else n for n in scene.names()]
    return f"scene: {', '.join(names) or 'empty'}"


def _cmd_plan(args: argparse.Namespace) -> int:
    from twin.collision import PlanningScene  # lazy: fcl
    from twin.planning import limits_from_settings, plan  # lazy: cli start-up

    settings = _settings(args, transfer_planner=args.planner)
    goal = _plan_goal(args, settings)
    if not args.time_limit > 0:
        raise InvalidRequestError(f"--time-limit must be positive, got {args.time_limit}")
    request = MotionRequest(
        start=args.start,
        goal=goal,
        limits=limits_from_settings(settings),
        time_limit_s=args.time_limit,
        seed=settings.seed,
    )
    # the cell `twin compare` and `twin problems export` plan in: obstacles marked `known: false` included
    scene = PlanningScene.from_settings(settings)
    if getattr(args, "verbose", False):
        print(_scene_line(scene))
    block = settings.planners.transfer
    assert block is not None  # `--planner` is required and made the transfer block
    result = plan(settings, block, request, scene=scene)
    traj = result.trajectory
    summary = {
        "planner": args.planner,
        "status": result.status.value,
        "reason": result.reason,
        "planning_time_s": result.planning_time_s,
        "duration_s": traj.duration if traj is not None else None,
        "t": traj.t.tolist() if traj is not None else [],
        "q": traj.q.tolist() if traj is not None else [],
        "qd": traj.qd.tolist() if traj is not None else [],
        "qdd": traj.qdd.tolist() if traj is not None else [],
    }
    if args.json_path:
        _write_json(args.json_path, summary)
    line = f"{args.planner}: {result.status.value} in {result.planning_time_s * 1e3:.1f} ms"
    line += f", duration {traj.duration:.3f} s" if traj is not None else f" ({result.reason})"
    print(line)
    return EXIT_OK if result.success else EXIT_NO_SOLUTION


def _cmd_run(args: argparse.Namespace) -> int:
    from rich.console import Console
    from rich.table import Table

    from twin.environment import environment  # lazy: cli start-up
    from twin.progress import RunDisplay  # lazy: cli start-up

    startup = process_age_s()  # interpreter start, imports and argument parsing, before the run's own clock
    if args.speed is not None and args.record is None:
        raise ConfigError(
            f"--speed {args.speed:g} goes with --record PATH (the video it speeds up); give both or neither"
        )
    settings = _settings(args, transfer_planner=args.planner)
    # stage, objects done, elapsed and time left on stderr where it is a terminal; gone when the run ends
    with RunDisplay(f"{settings.name} seed {settings.seed}", enabled=not args.quiet) as shown:
        summary = tasks.run_task(  # `--planner` is in `settings.planners.transfer` already
            settings,
            gui=args.gui,
            record=args.record,
            record_speed=1.0 if args.speed is None else args.speed,
            rerun=args.rerun,
            rerun_serve=args.rerun_serve,
            config_name=str(args.config),
            on_stage=shown.stage,
            on_objects=shown.objects,
        )
    timings = dict(summary.timings)
    if startup is not None:
        timings = {"startup": startup, **timings}
    total = sum(timings.values())
    if args.json_path:
        data = summary.to_json()
        data["timings"] = timings
        data["command_wall_time_s"] = total
        data["environment"] = environment()  # where it ran: twin's commit, Python, backends, machine
        # what ran, beside the planner blocks (`planners`): the config as named and every change made to it
        data["config_path"] = str(Path(str(args.config)).resolve()) if Path(str(args.config)).is_file() else None
        data["overrides"] = _run_overrides(args)
        _write_json(args.json_path, data)
    table = Table(
        title=_ran_title(args, settings, summary.seed),
        caption="perception err: how far (xy) perception's first estimate of the object was from where it lay",
    )
    for col in ("object", "class", "colour", "target", "placed", "cycle s", "perception err mm", "error"):
        table.add_column(col)
    for o in summary.objects:
        table.add_row(
            o.id,
            o.cls,
            o.color or "",
            o.target_bin,
            "yes" if o.placed else "no",
            f"{o.cycle_time_s:.1f}",
            "" if o.pose_error_m is None else f"{o.pose_error_m * 1e3:.1f}",
            o.error or "",
        )
    Console(width=200).print(table)
    print(
        f"placed {sum(o.placed for o in summary.objects)}/{len(summary.objects)} "
        f"({summary.success_rate:.0%}), simulated {summary.sim_time_s:.1f} s, wall {summary.wall_time_s:.1f} s"
        f" ({summary.sim_time_s / total:.1f}x real time over the whole command, {total:.1f} s)"
    )
    print(f"time: {format_breakdown(timings, total)}")
    cal = summary.calibration
    if cal is not None and cal.status != "measured":  # a camera pose the run did not measure: say how good it is
        bound = "" if cal.error_bound_m is None else f", good to {cal.error_bound_m * 1e3:.0f} mm"
        print(f"calibration: {cal.status} ({cal.views} views{bound}): {cal.reason}")
    if summary.plugin_errors:  # a bug in a plugin, even one the task recovered from, is not a pass
        print(f"plugin errors: {len(summary.plugin_errors)}, the first: {summary.plugin_errors[0]}")
        return EXIT_PLUGIN_ERROR
    return EXIT_OK if all(o.placed for o in summary.objects) else EXIT_NOT_PLACED


def _run_overrides(args: argparse.Namespace) -> list[str]:
    """The changes a command line made to its config, as typed: `--planner NAME` and every `--set`."""
    planner = [f"--planner {args.planner}"] if getattr(args, "planner", None) else []
    faults = [f"--faults {args.faults}"] if getattr(args, "faults", None) else []
    return planner + faults + [f"--set {o}" for o in args.overrides]


def _ran_title(args: argparse.Namespace, settings: Any, seed: int) -> str:
    """What a run ran, for its table's title: config, seed, each stage group's planner with the parameters the
    config gives it, and the command line's overrides."""
    groups = []
    for group in ("transfer", "movej", "movel"):
        block = settings.planners.block(group)
        given = [f"{k}={v}" for k, v in block.params.items()] + ([f"retimer {block.retimer}"] if block.retimer else [])
        groups.append(f"{group} {block.name}" + (f" ({', '.join(given)})" if given else ""))
    title = f"{args.config} seed {seed}; " + "; ".join(groups)
    overrides = _run_overrides(args)
    return title + (f"; {' '.join(overrides)}" if overrides else "")


def _print_skipped(skipped: list[tuple[str, str]], verb: str) -> None:
    """One line per distinct reason with its count (e.g. every nmpc run on joint-goal queries)."""
    for reason, n in Counter(r for _, r in skipped).items():
        print(f"{verb} {n} runs: {reason}")


def _dry_run_estimate(dry: DryRun, args: argparse.Namespace) -> str:
    """How long the sweep would take: from the rows of a sweep recorded in its output folder, else rough."""
    from twin.compare import read_results  # lazy: cli start-up
    from twin.compare.estimate import estimate_sweep  # lazy: cli start-up

    results = (Path(args.out) if args.out is not None else Path("out") / dry.spec.name) / "results.jsonl"
    try:
        recorded = read_results(results)
    except (OSError, TwinError):  # an unreadable or foreign file: no measurement to go on
        recorded = []
    return estimate_sweep(dry.runs, workers=args.workers, recorded=recorded, source=results).describe()


def progress_line(
    row: dict[str, Any], done: int, total: int, *, width: int = 160, watch: ProgressClock | None = None
) -> str:
    """'[3/26 00:41 eta 05:12] run_id: status (reason)' for a finished run: the sweep's elapsed time and the time
    left at the rate of the runs done so far, from `watch` (without one: '[3/26]'). A long reason is cut at a
    word, never in the middle of a value, and ends in ' ...' when cut (the row in results.jsonl keeps all of it)."""
    counts = f"{done}/{total}" if watch is None else watch.stamp(done, total)
    line = f"[{counts}] {row['run_id']}: {row['status']}"
    if not row.get("success") and row.get("reason"):
        line += f" ({textwrap.shorten(str(row['reason']), width, placeholder=' ...')})"
    return line


def compare_progress(
    *, clock: Callable[[], float] = time.monotonic, write: Callable[[str], None] | None = None
) -> Callable[[dict[str, Any], int, int], None]:
    """`run_comparison`'s `on_row`: a `progress_line` with elapsed time and estimate per finished run, timed by
    `clock` from now, printed (flushed) or given to `write`."""
    from twin.progress import ProgressClock  # lazy: cli start-up

    watch = ProgressClock(clock=clock)

    def on_row(row: dict[str, Any], done: int, total: int) -> None:
        line = progress_line(row, done, total, watch=watch)
        if write is None:
            print(line, flush=True)
        else:
            write(line)

    return on_row


def _cmd_compare(args: argparse.Namespace) -> int:
    from rich.console import Console

    from twin.compare import plan_comparison, run_comparison  # lazy: cli start-up
    from twin.compare.gate import (  # lazy: cli start-up
        Tolerance,
        check_shares_runs,
        gate,
        load_baseline,
        load_baseline_environment,
    )
    from twin.compare.report import summary_table, sweep_tables  # lazy: cli start-up
    from twin.compare.runner import check_run_options, recorded_environment  # lazy: cli start-up

    if args.tolerance is not None and args.baseline is None:
        raise ConfigError("--tolerance goes with --baseline (the results the sweep is gated against)")
    tolerance = Tolerance.parse(args.tolerance) if args.tolerance is not None else Tolerance()
    baseline = load_baseline(args.baseline) if args.baseline is not None else None  # a typo fails before the sweep
    shared = 0
    check_run_options(workers=args.workers, backend=args.backend, resume=args.resume, force=args.force)
    if baseline is not None or args.dry_run:
        dry = plan_comparison(args.config, overrides=args.overrides)  # knows every run id; runs nothing
        if baseline is not None:  # an unrelated baseline fails now, not after the whole sweep ran
            shared = check_shares_runs(baseline, (r.run_id for r in dry.runs), baseline=args.baseline)
    if args.dry_run:
        cases = dry.cases()
        print(
            f"{Path(args.config).name}: {dry.total} runs ({len(dry.spec.planners)} planners, "
            f"{sum(cases.values())} cases, {len(dry.skipped)} pairs skipped); "
            "checked every planner block and scenario, ran nothing"
        )
        print("per planner:")
        for label, n in dry.per_planner().items():
            print(f"  {label:32s} {n:6d}")
        print("per scenario (runs, cases):")
        for name, n in dry.per_scenario().items():
            print(f"  {name:32s} {n:6d}  {cases[name]:4d}")
        _print_skipped(dry.skipped, "would skip")
        if baseline is not None:
            print(f"baseline {args.baseline}: shares {shared} of this sweep's {dry.total} runs")
        print(_dry_run_estimate(dry, args))
        return EXIT_OK

    result = run_comparison(
        args.config,
        out_dir=args.out,
        workers=args.workers,
        backend=args.backend,
        resume=args.resume,
        force=args.force,
        overrides=args.overrides,
        on_row=None if args.quiet else compare_progress(),
    )
    console = Console(width=200)
    console.print(summary_table(result.summary, title=f"{Path(args.config).name}: {len(result.rows)} runs"))
    for table in sweep_tables(result.summary):  # a scenario with a `sweep:`: success and time per level
        console.print(table)
    _print_skipped(result.skipped, "skipped")
    again = f", {result.retried} rerun after an error" if result.retried else ""
    print(
        f"{result.ran} runs done in {result.wall_time_s:.1f} s ({result.resumed} finished before{again}); wrote "
        + ", ".join(str(f) for f in result.files)
    )
    if args.export_ompl is not None:
        from twin.compare.ompl_export import export_planner_arena  # lazy: cli start-up

        files = export_planner_arena(
            result.rows,
            args.export_ompl,
            name=result.spec_name,
            environment=recorded_environment(result.results_path) or {},
        )
        print("Planner Arena export: " + ", ".join(str(f) for f in files))
    if args.latex is not None:
        from twin.compare.latex import write_latex  # lazy: cli start-up

        print(f"LaTeX table: {write_latex(result.summary, args.latex)}")
    if baseline is not None:
        report = gate(
            result.rows,
            baseline,
            tolerance,
            environment=recorded_environment(result.results_path),
            baseline_environment=load_baseline_environment(args.baseline),
        )
        print(report.render())
        return EXIT_OK if report.passed else EXIT_NO_SOLUTION
    return EXIT_OK


_COMMANDS = {"planners": _cmd_planners, "scene": _cmd_scene, "plan": _cmd_plan, "run": _cmd_run}
_COMMANDS["compare"] = _cmd_compare


def _pose_line(T: Any) -> str:
    import numpy as np

    rpy = np.degrees(matrix_to_rpy(np.asarray(T)[:3, :3]))
    xyz = np.asarray(T)[:3, 3]
    return f"xyz [{xyz[0]:+.4f}, {xyz[1]:+.4f}, {xyz[2]:+.4f}] m, rpy [{rpy[0]:+.2f}, {rpy[1]:+.2f}, {rpy[2]:+.2f}] deg"


def _cmd_calibrate(args: argparse.Namespace) -> int:
    from twin.perception.evaluate import run_calibration  # lazy: cv2

    settings = _settings(args)
    rep = run_calibration(settings)
    print(f"camera-to-base (ArUco, {rep.method}, {rep.n_points} points, reprojection {rep.reprojection_px:.2f} px)")
    print(f"  estimate: {_pose_line(rep.T_base_camera)}")
    print(f"  truth:    {_pose_line(rep.T_base_camera_true)}")
    print(f"  error: {rep.translation_error_m * 1e3:.2f} mm, {rep.rotation_error_deg:.3f} deg")
    if args.json_path:
        _write_json(args.json_path, rep.to_dict())
    return EXIT_OK


def _cmd_perceive(args: argparse.Namespace) -> int:
    from twin.perception.evaluate import run_perception  # lazy: cv2
    from twin.tasks.pipelines import TASK_PIPELINES  # lazy: cv2

    settings = _settings(args)
    rep = run_perception(settings, pipelines=TASK_PIPELINES, detector=args.detector)
    fmt = "{:<24} {:<15} {:<15} {:<11} {:<11} {:<7} {:<7} {:>8} {:>8} {:>6}"
    print(fmt.format("object", "class", "estimate", "orient", "estimate", "color", "est", "dxy mm", "yaw deg", "S"))
    for o in rep.objects:

        def show(v: Any, scale: float = 1.0, nd: int = 1) -> str:
            return "-" if v is None else f"{v * scale:.{nd}f}"

        print(
            fmt.format(
                o["name"],
                o["class_true"],
                o["class_est"] or "MISSED",
                o["orientation_true"],
                o["orientation_est"] or "-",
                o["color_true"] or "-",
                o["color_est"] or "-",
                show(o["position_error_m"], 1e3),
                show(o["yaw_error_deg"]),
                f"{o['score']:.1f}",
            )
        )
    cal = rep.calibration
    cal_txt = f"{cal['translation_error_m'] * 1e3:.2f} mm, {cal['rotation_error_deg']:.3f} deg" if cal else "no marker"
    print(f"false positives: {rep.false_positives}; calibration error: {cal_txt}; mean score S: {rep.score_mean:.1f}")
    if rep.obstacle is not None and rep.obstacle["max_face_error_m"] is not None:
        print(
            f"obstacle box: largest face error {rep.obstacle['max_face_error_m'] * 1e3:.1f} mm"
            f" ({rep.obstacle['points']} points)"
        )
    if args.json_path:
        _write_json(args.json_path, rep.to_dict())
    return EXIT_OK


_COMMANDS["perceive"] = _cmd_perceive


def _cmd_dataset(args: argparse.Namespace) -> int:
    from twin.dataset import DatasetOptions, make_dataset  # lazy: cv2, the world
    from twin.progress import ProgressClock  # lazy: cli start-up

    settings = _settings(args)
    opts = DatasetOptions(
        images=args.images,
        seed=settings.seed,
        views=args.views,
        min_visible=args.min_visible,
        clutter=args.clutter,
        min_objects=args.min_objects,
    )
    out = Path(args.out)
    watch = ProgressClock()

    def tick(done: int, total: int) -> None:
        if not args.quiet and (done % 10 == 0 or done == total):
            print(f"[dataset {watch.stamp(done, total)}] {done}/{total} images", file=sys.stderr)

    card = make_dataset(settings, out, opts, config_name=args.config, progress=tick)
    print(card.markdown(), end="")
    print(f"wrote {out}/ (images/, labels/, data.yaml, coco/, card.md, card.json)")
    return EXIT_OK


_COMMANDS["dataset"] = _cmd_dataset
_COMMANDS["calibrate"] = _cmd_calibrate


def _cmd_check_planner(args: argparse.Namespace) -> int:
    """Exit 0 when the planner keeps every rule of the contract, 1 when it breaks one."""
    from rich.console import Console
    from rich.table import Table

    from twin.testing import check_planner, time_slack_s  # lazy: cli start-up

    if not (math.isfinite(args.time_limit) and args.time_limit > 0):
        raise InvalidRequestError(f"--time-limit must be positive, got {args.time_limit}")
    settings = None
    if args.config is not None:
        settings = load_config(args.config)
    planner: str | dict[str, Any] = args.name
    if args.params:
        params: dict[str, Any] = {}
        for item in args.params:
            apply_override(params, item)
        planner = {"name": args.name, "params": params}
    console = Console(stderr=True, quiet=args.quiet)  # -q: no spinner either
    with console.status(f"checking {args.name}") as status:
        report = check_planner(
            planner,
            settings=settings,
            seed=args.seed,
            time_limit_s=args.time_limit,
            config_name=args.config,
            on_progress=lambda text: status.update(f"{args.name}: {text}"),
        )
    if args.json_path:
        _write_json(args.json_path, report.to_json())
    table = Table(
        title=f"{report.planner} ({report.kind}) against the planner contract: {report.config}, seed {report.seed}, "
        f"time limit {report.time_limit_s:g} s (+{time_slack_s(report.time_limit_s):.2f} s slack)"
    )
    for col in ("rule", "check", "verdict", "plugin", "checked", "detail"):
        table.add_column(col)
    mark = {True: "ok", False: "FAIL"}
    for r in report.results:
        table.add_row(str(r.number), r.rule, "pass" if r.passed else "FAIL", mark[r.raw], mark[r.checked], r.detail)
    Console(width=200).print(table)
    n_fail = len(report.failures)
    print(
        f"{report.planner}: {'keeps every rule' if report.ok else f'breaks {n_fail} of {len(report.results)} checks'} "
        f"({len(report.requests)} requests, {report.wall_time_s:.1f} s)"
    )
    return EXIT_OK if report.ok else EXIT_NO_SOLUTION


_COMMANDS["check-planner"] = _cmd_check_planner


def _cmd_replay(args: argparse.Namespace) -> int:
    from twin.compare.replay import replay_row  # lazy: cli start-up
    from twin.rerun_log import rerun_module  # lazy: cli start-up

    if not str(args.rerun).lower().endswith(".rrd"):
        raise ConfigError(f"--rerun must name an .rrd file, got {args.rerun!r}")
    rerun_module()  # a missing SDK fails before the run
    r = replay_row(args.results, args.run_id, args.rerun)
    print(f"{args.run_id}: {r.replayed.get('status')} ({r.replayed.get('reason') or 'no reason'})")
    print(f"recording: {r.recording} (open it with `rerun {r.recording}`)")
    if r.differences:
        print(f"the replayed row differs from the stored one in {len(r.differences)} field(s) that are not times:")
        for d in r.differences[:20]:
            print(f"  {d}")
        return EXIT_NO_SOLUTION
    print("the replayed row equals the stored one (every field but times)")
    return EXIT_OK


_COMMANDS["replay"] = _cmd_replay
_COMMANDS.update(EXCHANGE_COMMANDS)


def _log_level(verbose: int, quiet: bool) -> int:
    """-q: errors only; none: warnings; -v: info; -vv: debug."""
    if quiet:
        return logging.ERROR
    return (logging.WARNING, logging.INFO, logging.DEBUG)[min(verbose, 2)]


class _StderrHandler(logging.StreamHandler):  # type: ignore[type-arg]
    """Writes to whatever `sys.stderr` is when a record comes, so that a log line during `twin run` goes above
    its progress display (which stands in for `sys.stderr` while it shows) instead of through it."""

    def __init__(self) -> None:
        super().__init__(sys.stderr)

    @property
    def stream(self) -> Any:
        return sys.stderr

    @stream.setter
    def stream(self, value: Any) -> None:
        pass


def main(argv: Sequence[str] | None = None) -> int:
    return _main(argv)[0]


def _main(argv: Sequence[str] | None) -> tuple[int, str | None]:
    """(exit code, the command run)."""
    parser = build_parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return EXIT_USAGE, None
    logging.basicConfig(
        level=_log_level(args.verbose, args.quiet),
        format="%(levelname)s %(name)s: %(message)s",
        handlers=[_StderrHandler()],
    )
    try:
        return _COMMANDS[args.command](args), args.command
    except PlanningError as e:  # a plugin's failure, not the user's: its own code, and its traceback with -v
        if getattr(args, "verbose", False):
            import traceback

            traceback.print_exception(e.__cause__ or e, file=sys.stderr)
        sys.stderr.write(f"twin {args.command}: plugin error: {e}\n")
        return EXIT_PLUGIN_ERROR, args.command
    except TwinError as e:
        sys.stderr.write(f"twin {args.command}: error: {e}\n")
        return EXIT_USAGE, args.command


# Commands that leave nothing behind once they return (no worker processes, every file written and closed):
# the `twin` command ends their process at once instead of running the interpreter's teardown, which frees
# every module one by one (~0.25 s after a task run, a twentieth of it: toppra, open3d, scipy, numba).
_ENDS_AT_ONCE = frozenset({"run"})


def console_main() -> NoReturn:
    """The `twin` command (and `python -m twin`): `main`, then the process ends with its exit code."""
    code, command = _main(sys.argv[1:])
    if command in _ENDS_AT_ONCE:
        sys.stdout.flush()
        sys.stderr.flush()
        logging.shutdown()
        os._exit(code)
    raise SystemExit(code)


if __name__ == "__main__":
    console_main()
