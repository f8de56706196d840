"""The comparison runner: planners x scenarios x seeds, one row per finished run, resumable.

Why it looks like this:
* every run is one call of `twin.compare.worker.execute_run(RunTask) -> row`, the same function in a
  local process pool (default), in-process (`workers=0`, for debugging) and on Ray (`backend="ray"`);
  the local pool stops a run that outlives its timeout (`run_timeout_s`) and replaces a worker that dies,
  recording either as an error row, so no planner can hang or end a sweep;
* the main process alone writes `DIR/results.jsonl`: one JSON line per finished run, flushed and
  fsync'd as it arrives, so a crash loses nothing finished;
* `resume=True` reads the file (dropping a line cut short by a crash), skips the run ids it holds and
  appends the rest; a run whose last row ended in status 'error' is run again and its new row replaces
  the old one (the file only grows: readers take the last row per run id, `latest_rows`);
* a run id hashes the run's whole definition, so resuming with a changed config would leave old rows
  beside new ones under the same planner label: that is a ConfigError naming what changed, unless
  `force=True` (the changed runs are run anew; the old rows stay in the file and leave the summary);
* everything a user can get wrong (an unknown planner name, bad params, a missing scene file, a query
  region that cannot yield what it asks for) is a ConfigError before the first run starts, and
  `plan_comparison` (`twin compare --dry-run`) checks exactly that and counts the runs, running nothing.
"""

from __future__ import annotations

import json
import logging
import multiprocessing
import os
import time
from collections import Counter
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from datetime import datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal

from twin.compare.html_report import write_html
from twin.compare.plots import write_plots
from twin.compare.report import summarize, write_summary
from twin.compare.spec import (
    CompareSpec,
    QueryScenario,
    QuerySpec,
    RunTask,
    TaskScenario,
    definitions,
    describe_changes,
    expand_runs,
    load_compare_config,
    run_key,
)
from twin.compare.summary import Provenance
from twin.compare.worker import TASKS_UNAVAILABLE, error_row, execute_run, worker_init
from twin.config import load_config
from twin.environment import environment
from twin.errors import ConfigError, DependencyMissing, UnknownNameError
from twin.planning import accepts_retimer, cannot_reach, declared_goal_kinds, make_context, make_planner, robot_refusal
from twin.problems.cells import cell_for
from twin.problems.sampling import sample_query
from twin.problems.world import check_robot
from twin.registry import Kind, default_registry, validate_params
from twin.resources import config_names, packaged_config
from twin.robot.urdf_model import RobotModel

if TYPE_CHECKING:
    from twin.compare.summary import Summary
    from twin.config import Settings

__all__ = [
    "RESULTS_FILE",
    "CompareResult",
    "DryRun",
    "check_run_options",
    "check_spec",
    "latest_rows",
    "plan_comparison",
    "read_results",
    "recorded_environment",
    "run_comparison",
    "tasks_available",
]

log = logging.getLogger("twin")

RESULTS_FILE = "results.jsonl"
SPEC_FILE = "compare.json"
Backend = Literal["local", "ray"]


@dataclass(frozen=True)
class CompareResult:
    """What a comparison produced: its rows (finished earlier or now), what was skipped, the files."""

    out_dir: Path
    rows: list[dict[str, Any]]
    ran: int  # runs executed by this call
    resumed: int  # runs found finished in results.jsonl and not redone
    skipped: list[tuple[str, str]]  # (run_id, reason) of runs that could not run here
    summary: Any  # twin.compare.summary.Summary
    files: list[Path] = field(default_factory=list)
    wall_time_s: float = 0.0
    retried: int = 0  # runs whose earlier row ended in 'error' and that ran again
    spec_name: str = "compare"  # the comparison's name (experiment names of an export)

    @property
    def results_path(self) -> Path:
        return self.out_dir / RESULTS_FILE


@dataclass(frozen=True)
class DryRun:
    """What `run_comparison` would do with a spec that passed every check: the runs, counted."""

    spec: CompareSpec
    runs: list[RunTask]
    skipped: list[tuple[str, str]]  # (run_id, reason): runs that cannot run here (see `_runnable`)

    @property
    def total(self) -> int:
        return len(self.runs)

    def per_planner(self) -> dict[str, int]:
        """Runs per planner label, in config order."""
        return {p.id: sum(1 for r in self.runs if r.planner_id == p.id) for p in self.spec.planners}

    def per_scenario(self) -> dict[str, int]:
        """Runs per scenario, in config order."""
        return {s.name: sum(1 for r in self.runs if r.scenario == s.name) for s in self.spec.scenarios}

    def cases(self) -> dict[str, int]:
        """Cases (queries x seeds, or task seeds) per scenario: what each planner runs there."""
        return {s.name: len(self.spec.cases(s)) for s in self.spec.scenarios}


# ---- checks before anything runs ----------------------------------------------------------------
def tasks_available() -> bool:
    """True when `twin.tasks.run_task` can be imported (task scenarios run); else they are skipped."""
    try:
        from twin.tasks import run_task  # noqa: F401  # lazy: an availability probe (ImportError: skip tasks)
    except ImportError:
        return False
    return True


def _check_physics_robot(settings: Settings) -> None:
    """ConfigError when the runs execute in physics and the robot URDF cannot (a planning-only model)."""
    from twin.world import physics_parts_missing  # lazy: pybullet (imported with its banner silenced)

    missing = physics_parts_missing(RobotModel.from_urdf(settings.resolve(settings.robot.urdf)))
    if missing:
        raise ConfigError(
            f"robot.urdf {settings.robot.urdf} has no {', '.join(missing)}: it plans but cannot run in physics "
            "(execute: false plans without executing)"
        )


def check_spec(spec: CompareSpec, *, instantiate: bool = True, draw_queries: bool = True) -> None:
    """Raise ConfigError for an unknown planner or retimer name, bad planner params, or a scenario
    config that does not load, before anything runs. With `instantiate`, each planner is also built
    once here, so a missing backend (DependencyMissing, naming the extra) stops the sweep now rather
    than turning every one of its runs into an error row. With `draw_queries`, the first random query
    of each scenario is drawn, so a region that cannot yield what it asks for (`straight: blocked` with
    nothing in the way) is one error now rather than an error row per run."""
    source = spec.source or "<compare config>"
    settings = []
    for i, sc in enumerate(spec.scenarios):
        path = sc.task if isinstance(sc, TaskScenario) else sc.scene
        assert path is not None  # resolved on load
        try:
            settings.append(load_config(path, sc.overrides))
            if isinstance(sc, QueryScenario) and sc.problems is not None:
                check_robot(sc.problem_set, settings[-1], source=sc.problems)
            if isinstance(sc, TaskScenario) or spec.execute:
                _check_physics_robot(settings[-1])
        except ConfigError as e:
            raise ConfigError(f"{source}: scenarios.{i} ({sc.name}): {e}") from None
    registry = default_registry()
    for i, p in enumerate(spec.planners):
        try:
            entry = registry.entry(p.name, (Kind.PLANNER, Kind.RECEDING_HORIZON))
        except UnknownNameError as e:
            raise ConfigError(f"{source}: planners.{i}: {e}") from None
        cls = entry.load()
        try:
            validate_params(entry, cls, p.params)
            if p.retimer is not None:
                if not accepts_retimer(cls):
                    raise ConfigError(f"planner {p.name!r} produces trajectories itself and takes no retimer")
                try:
                    rentry = registry.entry(p.retimer, (Kind.RETIMER,))
                except UnknownNameError as e:
                    raise ConfigError(str(e)) from None
                validate_params(rentry, rentry.load(), p.retimer_params)
            # built for the first scenario whose arm it plans for (the pairs of the others are skipped)
            accepted = [s for s in settings if robot_refusal(p.name, cls, s.robot.model) is None]
            if instantiate and accepted:
                make_planner(p.block(), make_context(accepted[0], registry))
        except (ConfigError, DependencyMissing) as e:
            raise type(e)(f"{source}: planners.{i} ({p.id}): {e}") from None
    if draw_queries:
        _draw_first_queries(spec, source)


def _draw_first_queries(spec: CompareSpec, source: str) -> None:
    """Draw the first random query of every query scenario (first seed), as the worker would."""
    import numpy as np

    for i, sc in enumerate(spec.scenarios):
        if not isinstance(sc, QueryScenario) or sc.random is None or sc.scene is None:
            continue
        seed = spec.seeds_for(sc)[0]
        task = RunTask(
            run_id="",
            planner_id="",
            planner={},
            scenario=sc.name,
            case="",
            kind="query",
            seed=seed,
            config=sc.scene,
            overrides=tuple(sc.overrides),
            query_index=0,
        )
        cell = cell_for(sc.scene, tuple(sc.overrides), sc.unknown_fixtures)
        try:
            sample_query(
                sc.random.model_dump(),
                np.random.default_rng(task.random_seed()),
                scene=cell.scene,
                kin=cell.kin,
                home=np.asarray(cell.settings.robot.home, dtype=float),
                resolution_rad=cell.settings.collision.check_resolution_rad,
            )
        except ConfigError as e:
            raise ConfigError(f"{source}: scenarios.{i} ({sc.name}).random: {e}") from None


# ---- results file ---------------------------------------------------------------------------------
def read_results(path: str | Path, *, repair: bool = False) -> list[dict[str, Any]]:
    """Rows of a results.jsonl. A last line cut short by a crash is dropped (and cut off the file when
    `repair`, so appending continues on a clean line); a broken line elsewhere is a ConfigError."""
    p = Path(path)
    if not p.is_file():
        return []
    data = p.read_bytes()
    rows: list[dict[str, Any]] = []
    keep = 0  # bytes of the file that hold complete rows
    start = 0
    while start < len(data):
        nl = data.find(b"\n", start)
        end = len(data) if nl < 0 else nl
        line = data[start:end]
        if line.strip():
            try:
                row = json.loads(line)
                if not isinstance(row, dict) or "run_id" not in row:
                    raise ValueError("not a result row")
            except ValueError:
                if nl >= 0 and data[nl + 1 :].strip():
                    lineno = data.count(b"\n", 0, start) + 1
                    raise ConfigError(f"{p}: line {lineno} is not a result row; fix or remove it") from None
                log.warning("%s: dropping an incomplete last line (an interrupted write)", p)
                break
            rows.append(row)
        if nl < 0:  # a complete row without its newline: keep it, terminate it when repairing
            if repair:
                with open(p, "ab") as f:
                    f.write(b"\n")
            keep = len(data)
            break
        start = keep = nl + 1
    if repair and keep < len(data):
        with open(p, "r+b") as f:
            f.truncate(keep)
    return rows


def latest_rows(rows: Iterable[dict[str, Any]]) -> list[dict[str, Any]]:
    """The last row of each run id (a rerun replaces an earlier row), in the order run ids first appear."""
    out: dict[str, dict[str, Any]] = {}
    for row in rows:
        out[row["run_id"]] = row
    return list(out.values())


def _row_key(row: dict[str, Any]) -> str:
    return run_key(str(row.get("planner")), str(row.get("case")), int(row.get("seed", 0)))


def _previous_definitions(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    defs = data.get("definitions") if isinstance(data, dict) else None
    return defs if isinstance(defs, dict) else None


def recorded_environment(results: str | Path) -> dict[str, Any] | None:
    """The environment a sweep recorded (twin.environment) in the compare.json beside its results.jsonl
    (`results` is that file or its folder); None when there is none (a sweep from before twin recorded one,
    or rows copied without their folder)."""
    p = Path(results)
    try:
        data = json.loads(((p if p.is_dir() else p.parent) / SPEC_FILE).read_text())
    except (OSError, ValueError):
        return None
    env = data.get("environment") if isinstance(data, dict) else None
    return env if isinstance(env, dict) else None


class _Appender:
    """Appends one JSON line per row and makes it durable before the next one (flush + fsync)."""

    def __init__(self, path: Path) -> None:
        self._f = open(path, "a", encoding="utf-8")  # noqa: SIM115 - held open for the whole sweep, closed by close()

    def write(self, row: dict[str, Any]) -> None:
        self._f.write(json.dumps(row, allow_nan=False) + "\n")
        self._f.flush()
        os.fsync(self._f.fileno())

    def close(self) -> None:
        self._f.close()


# ---- backends -------------------------------------------------------------------------------------
def _mp_context() -> Any:
    methods = multiprocessing.get_all_start_methods()
    return multiprocessing.get_context("forkserver" if "forkserver" in methods else "spawn")


def _run_inline(todo: Sequence[RunTask]) -> Iterator[dict[str, Any]]:
    for t in todo:
        yield execute_run(t)


@dataclass
class _Worker:
    """One worker process of the local backend, the pipe to it, and the run it is busy with."""

    process: Any
    conn: Any
    task: RunTask | None = None
    sent: float = 0.0  # time.monotonic() when the task was sent
    started: float | None = None  # when the worker said it started the run (`_STARTED`); None: not yet


# what a worker sends when it has received a task and starts running it: the run's timeout counts from here, so
# a worker process still starting (a fresh one imports twin first: seconds on a busy machine) uses none of it
_STARTED = "started"
# how long a worker may take to start a run it was sent (process start and imports); a run's own timeout
# counts after that (a worker stuck before its run would otherwise hold the sweep for ever)
_START_TIMEOUT_S = 300.0


def _worker_loop(conn: Any, run: Callable[[RunTask], dict[str, Any]], threads: int) -> None:
    """A local worker: for each task it is sent, say it started (`_STARTED`), run it and send its row back,
    until it is sent None."""
    worker_init(threads)
    while True:
        try:
            task = conn.recv()
        except (EOFError, OSError):
            return
        if task is None:
            return
        conn.send(_STARTED)
        conn.send(run(task))


def _run_local(
    todo: Sequence[RunTask], workers: int, run: Callable[[RunTask], dict[str, Any]] = execute_run
) -> Iterator[dict[str, Any]]:
    """Run `todo` on `workers` processes. A run that outlives its `timeout_s` (a planner ignoring its time
    limit in native code, where nothing else can interrupt it) or whose worker dies (a crash in a native
    library) becomes an error row; its worker is replaced and the sweep goes on. The timeout counts from
    when the worker starts the run (`_STARTED`), not from when it was sent: a fresh worker's start-up is
    no part of any run."""
    from multiprocessing.connection import wait

    ctx = _mp_context()
    queue = list(reversed(todo))
    pool: list[_Worker] = []
    threads = max(1, _default_workers() // max(1, workers))  # each worker's share of the CPUs

    def spawn() -> _Worker:
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_worker_loop, args=(child, run, threads), daemon=True)
        proc.start()
        child.close()
        return _Worker(proc, parent)

    def give(w: _Worker) -> None:
        w.task, w.sent, w.started = (queue.pop() if queue else None), time.monotonic(), None
        if w.task is not None:
            w.conn.send(w.task)

    def deadline(w: _Worker) -> float:
        assert w.task is not None
        return w.sent + _START_TIMEOUT_S if w.started is None else w.started + w.task.timeout_s

    def replace(w: _Worker) -> _Worker:
        w.process.kill()
        w.process.join(5)
        w.conn.close()
        fresh = spawn()
        pool[pool.index(w)] = fresh
        return fresh

    try:
        for _ in range(min(workers, len(queue))):
            pool.append(spawn())
            give(pool[-1])
        while True:
            busy = [w for w in pool if w.task is not None]
            if not busy:
                return
            wait_s = max(0.0, min(deadline(w) for w in busy) - time.monotonic())
            ready = wait([w.conn for w in busy], timeout=wait_s)
            for w in busy:
                task = w.task
                assert task is not None
                if w.conn in ready:
                    try:
                        row = w.conn.recv()
                        if row == _STARTED:  # its timeout counts from now; its row comes later
                            w.started = time.monotonic()
                            continue
                    except (EOFError, OSError):  # the worker died while running it (or starting it)
                        w.process.join(5)
                        code = w.process.exitcode
                        log.warning("run %s: its worker process died (exit code %s)", task.run_id, code)
                        row = error_row(
                            task,
                            f"WorkerDied: the worker process died running this (exit code {code})",
                            wall_time_s=time.monotonic() - (w.sent if w.started is None else w.started),
                        )
                        w = replace(w)
                elif time.monotonic() < deadline(w):
                    continue
                elif w.started is None:
                    log.warning("run %s: its worker did not start it in %.0f s", task.run_id, _START_TIMEOUT_S)
                    row = error_row(
                        task, f"RunTimeout: the worker did not start this run within {_START_TIMEOUT_S:g} s"
                    )
                    w = replace(w)
                else:
                    log.warning("run %s: no result after %.0f s; stopping it", task.run_id, task.timeout_s)
                    row = error_row(
                        task,
                        f"RunTimeout: no result after {task.timeout_s:g} s (the run was stopped; "
                        "a planner that ignores its time limit?)",
                        wall_time_s=task.timeout_s,
                    )
                    w = replace(w)
                give(w)
                yield row
    finally:
        for w in pool:
            if w.task is None and w.process.is_alive():
                try:  # noqa: SIM105 - not contextlib.suppress: a generator's finally may run at interpreter shutdown
                    w.conn.send(None)
                except OSError:
                    pass
        for w in pool:
            w.process.join(2 if w.task is None else 0)
            if w.process.is_alive():
                w.process.kill()
                w.process.join(5)
            w.conn.close()


def _shipped_config_names() -> dict[str, str]:
    """{real path on this machine: file name} of every config twin ships (`twin.resources`)."""
    out: dict[str, str] = {}
    for name in config_names():
        p = packaged_config(name)
        if p is not None:
            out[str(p.resolve())] = p.name
    return out


def _run_on_node(task: RunTask, shipped_config: str | None) -> dict[str, Any]:
    """`execute_run` on a Ray worker. A task's config is an absolute path on the driver; a config twin ships
    (`shipped_config`, its file name) is the same file in this node's own install, wherever that is (a node
    whose venv lives elsewhere would not find the driver's path). A user's own files are read at their path."""
    if shipped_config is not None:
        from dataclasses import replace

        found = packaged_config(shipped_config)
        if found is None:  # an older twin on this node
            return error_row(task, f"ConfigError: the twin on this node ships no config {shipped_config!r}")
        task = replace(task, config=str(found))
    return execute_run(task)


def _ray_connect(ray: Any, address: str) -> None:
    """`ray.init` on a running cluster; a refused connection or token is one line (ConfigError), not a trace.
    Ray reports a wrong or missing token only as a failed connection (and C++ warnings naming
    InvalidAuthToken), so the message says what to check for either."""
    kw: dict[str, Any] = {"include_dashboard": False, "log_to_driver": False, "logging_level": logging.ERROR}
    auth_error = getattr(ray.exceptions, "AuthenticationError", ConnectionError)
    try:
        ray.init(address=address, **kw)
    except (ConnectionError, auth_error, RuntimeError) as e:
        text = " ".join(str(e).split())[:300].rstrip(".")
        if os.environ.get("RAY_AUTH_MODE", "").lower() == "token":
            hint = (
                "is the cluster up (`ray status --address ADDRESS`), and is the token here (RAY_AUTH_TOKEN, "
                "RAY_AUTH_TOKEN_PATH or ~/.ray/auth_token) the cluster's (`ray get-auth-token` on the head)?"
            )
        else:
            hint = (
                "is the cluster up (`ray status --address ADDRESS`)? A cluster with token authentication wants "
                "RAY_AUTH_MODE=token here too, with its token in ~/.ray/auth_token or RAY_AUTH_TOKEN"
            )
        raise ConfigError(f"cannot connect to the Ray cluster at {address}: {text}; {hint}") from None


def _run_ray(todo: Sequence[RunTask], workers: int, address: str | None) -> Iterator[dict[str, Any]]:
    """Run on Ray: on the cluster `address` (or RAY_ADDRESS) names, else on a local Ray of `workers` CPUs
    started for this sweep and stopped after it. Only the driver writes results; every node needs the same
    twin (`pip install 'twin[all]'`), nothing else of the driver's: shipped configs are found in each node's
    own install. A run whose worker or node died is an error row (rerun by `--resume`), as locally."""
    try:
        import ray
    except ImportError as e:
        raise DependencyMissing(
            f"the ray backend needs ray ({e.name or 'ray'} is not installed); install it with `pip install 'twin[ray]'`"
        ) from e
    started = False
    if not ray.is_initialized():
        address = address or os.environ.get("RAY_ADDRESS")
        if address:
            _ray_connect(ray, address)
            if not ray.cluster_resources().get("CPU"):  # type: ignore[no-untyped-call]
                log.warning("the Ray cluster at %s has no CPUs yet: runs wait for a node with CPUs to join", address)
        else:  # a local cluster of `workers` CPUs, started for this sweep and stopped after it
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
        started = True
    try:
        shipped = _shipped_config_names()
        remote = ray.remote(num_cpus=1, max_retries=0)(_run_on_node)
        of_ref = {remote.remote(t, shipped.get(t.config)): t for t in todo}
        pending = list(of_ref)
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                try:
                    row = ray.get(ref)
                except ray.exceptions.RayError as e:  # the worker process or its node died mid-run
                    first = (str(e).strip().splitlines() or [""])[0]
                    row = error_row(of_ref[ref], f"{type(e).__name__}: {first}"[:500])
                yield row
    finally:
        if started:
            ray.shutdown()


# ---- the sweep ------------------------------------------------------------------------------------
def _default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def _load(spec: CompareSpec | str | Path, overrides: Iterable[str]) -> CompareSpec:
    if not isinstance(spec, CompareSpec):
        return load_compare_config(spec, overrides)
    if overrides:
        raise ConfigError("overrides apply to a config file; pass the path, or change the CompareSpec itself")
    return spec


def _goal_kind(run: RunTask) -> str | None:
    """The kind of goal a query run asks for ('joint', 'pose', 'position'); None for a task run."""
    if run.kind != "query":
        return None
    if run.query is not None:
        return QuerySpec.model_validate(run.query).goal_kind
    assert run.random is not None
    return str(run.random["goal"])


def _runnable(runs: Sequence[RunTask]) -> tuple[list[RunTask], list[tuple[str, str]]]:
    """(runs that can run here, (run_id, reason) of the others): task runs when twin.tasks is missing,
    query runs whose goal kind the planner declares it cannot reach (`goal_kinds`, e.g. nmpc: positions
    only), and runs on an arm the planner declares it does not plan for (`robot_models`, e.g. nmpc: the
    UR5e only). Such a pair is not a failure of the planner; it is not a comparison at all."""
    have_tasks = tasks_available()
    classes: dict[str, type] = {}
    arms: dict[tuple[str, tuple[str, ...]], str] = {}  # (config, overrides) -> robot.model
    ok: list[RunTask] = []
    skipped: list[tuple[str, str]] = []
    for r in runs:
        if r.kind == "task" and not have_tasks:
            skipped.append((r.run_id, TASKS_UNAVAILABLE))
            continue
        name = r.planner["name"]
        if name not in classes:
            classes[name] = default_registry().entry(name).load()
        kind = _goal_kind(r)
        if kind is not None:
            kinds = declared_goal_kinds(classes[name])
            if kind not in kinds:
                skipped.append((r.run_id, cannot_reach(r.planner_id, kind, kinds)))
                continue
        key = (r.config, tuple(r.overrides))
        if key not in arms:
            arms[key] = load_config(r.config, r.overrides).robot.model
        refusal = robot_refusal(r.planner_id, classes[name], arms[key])
        if refusal is not None:
            skipped.append((r.run_id, refusal))
            continue
        ok.append(r)
    return ok, skipped


def check_run_options(*, workers: int | None, backend: str, resume: bool = False, force: bool = False) -> None:
    """How a sweep is run, checked before anything runs (`run_comparison` and a dry run alike): ConfigError."""
    if backend not in ("local", "ray"):
        raise ConfigError(f"backend must be 'local' or 'ray', got {backend!r}")
    if workers is not None and workers < 0:
        raise ConfigError(f"workers must be >= 0 (0: in this process), got {workers}")
    if force and not resume:
        raise ConfigError(
            "--force goes with --resume (it accepts a changed config); to start over, choose another --out"
        )


def plan_comparison(spec: CompareSpec | str | Path, *, overrides: Iterable[str] = ()) -> DryRun:
    """Check a comparison as `run_comparison` would before its first run (every planner block validated
    and built once, every scenario config loaded, the first query of each random scenario drawn) and
    count its runs. Runs nothing and writes nothing; raises ConfigError / DependencyMissing."""
    spec = _load(spec, overrides)
    check_spec(spec)
    runs = expand_runs(spec)
    runs, skipped = _runnable(runs)
    return DryRun(spec=spec, runs=runs, skipped=skipped)


def _earlier_rows(
    spec: CompareSpec, runs: Sequence[RunTask], defs: dict[str, Any], out: Path, *, resume: bool, force: bool
) -> list[dict[str, Any]]:
    """The latest rows of the sweep in `out` that a resume continues (none without `resume`). ConfigError
    when results exist without `resume`, or when the config changed runs that have rows, unless `force`."""
    results = out / RESULTS_FILE
    if not resume:
        if results.is_file() and results.stat().st_size > 0:
            raise ConfigError(
                f"{results} already holds results; pass --resume to continue that sweep, or choose another --out"
            )
        return []
    wanted = {r.run_id for r in runs}
    existing = latest_rows(read_results(results, repair=False))
    have = {row["run_id"] for row in existing}
    by_key = {r.key: r for r in runs if r.run_id not in have}
    changed = [row for row in existing if row["run_id"] not in wanted and _row_key(row) in by_key]
    if changed and not force:
        previous = _previous_definitions(out / SPEC_FILE)
        what = describe_changes(previous, defs) if previous is not None else []
        if not what:
            what = [f"{len(changed)} runs (e.g. {_row_key(changed[0])!r}) were made with a different definition"]
        raise ConfigError(
            f"{out}: the comparison config changed since this sweep started: {'; '.join(what)}. "
            f"Pass --force to run the changed runs anew (their old rows stay in {RESULTS_FILE} and leave "
            "the summary), or choose another --out"
        )
    return existing


def _open_out_dir(out: Path, spec: CompareSpec, defs: dict[str, Any], *, resume: bool) -> dict[str, Any]:
    """Create `out`, mend a results file a crash cut short (on resume), write the spec file with where
    this sweep runs (twin, Python, backends, machine: the gate names what changed since its baseline);
    returns that environment."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"cannot create the output folder {out}: {e.strerror}") from None
    if resume:
        read_results(out / RESULTS_FILE, repair=True)  # a line cut short by a crash goes before anything is appended
    env = environment()
    (out / SPEC_FILE).write_text(
        json.dumps({"spec": spec.model_dump(mode="json"), "definitions": defs, "environment": env}, indent=1)
    )
    return env


def _run_all(
    todo: Sequence[RunTask],
    results: Path,
    *,
    backend: Backend,
    n_workers: int,
    workers: int | None,
    ray_address: str | None,
    on_row: Callable[[dict[str, Any], int, int], None] | None,
) -> list[dict[str, Any]]:
    """Run `todo` on the backend, appending each row to `results` as it finishes; the new rows."""
    new_rows: list[dict[str, Any]] = []
    if not todo:
        return new_rows
    if backend == "ray":
        stream = _run_ray(todo, max(1, n_workers), ray_address)
    elif n_workers == 0 or workers == 0:
        stream = _run_inline(todo)
    else:
        stream = _run_local(todo, n_workers)
    writer = _Appender(results)
    try:
        for row in stream:
            writer.write(row)
            new_rows.append(row)
            if on_row is not None:
                on_row(row, len(new_rows), len(todo))
    finally:
        writer.close()
        close = getattr(stream, "close", None)
        if close is not None:
            close()
    return new_rows


def _write_reports(
    spec: CompareSpec,
    rows: list[dict[str, Any]],
    runs: Sequence[RunTask],
    skipped: list[tuple[str, str]],
    out: Path,
    *,
    started: datetime,
    env: dict[str, Any],
    plots: bool,
) -> tuple[Summary, list[Path]]:
    """Summarize the rows and write the summary files, the plots (when asked and plotting is installed)
    and the HTML report; the summary and the files written after results.jsonl."""
    skipped_ids = {rid for rid, _ in skipped}
    skipped_pairs = Counter((r.planner_id, r.scenario) for r in runs if r.run_id in skipped_ids)
    summary = summarize(
        rows,
        planners=[p.id for p in spec.planners],
        skipped=skipped,
        reference=spec.reference,
        skipped_pairs=dict(skipped_pairs),
        provenance=Provenance(spec.name, spec.source if spec.source != "<dict>" else None, started, env),
    )
    files = list(write_summary(summary, out))
    pictures: list[Path] = []
    if plots:
        try:
            pictures = write_plots(rows, out, planners=[p.id for p in spec.planners], summary=summary)
        except DependencyMissing as e:
            log.warning("no plots: %s", e)
    files += [write_html(summary, out, plots=pictures, title=spec.name or "planner comparison"), *pictures]
    return summary, files


def run_comparison(
    spec: CompareSpec | str | Path,
    *,
    out_dir: str | Path | None = None,
    workers: int | None = None,
    backend: Backend = "local",
    resume: bool = False,
    force: bool = False,
    overrides: Iterable[str] = (),
    ray_address: str | None = None,
    plots: bool = True,
    on_row: Callable[[dict[str, Any], int, int], None] | None = None,
) -> CompareResult:
    """Run a comparison (a CompareSpec or the path of its YAML) and write results, summary and plots.

    `out_dir`: default `out/<spec name>`. `workers`: parallel runs (default: the CPUs this process
    may use; 0 runs in this process). `backend`: "local" (process pool) or "ray" (`ray.init()` locally
    unless `ray_address` or RAY_ADDRESS names a cluster; the extra `twin[ray]`). `resume`: continue the
    sweep in out_dir, skipping finished run ids and rerunning those whose row ended in 'error'; without
    it an existing non-empty results.jsonl is a ConfigError. A resume whose config changed a planner
    block or scenario that already has rows is a ConfigError naming the change, unless `force`.
    `on_row(row, done, total)` is called as each run finishes (the CLI prints progress).
    """
    t_start = time.perf_counter()
    started = datetime.now().astimezone()  # summary.md says when the sweep ran (with its time zone)
    spec = _load(spec, overrides)
    check_run_options(workers=workers, backend=backend, resume=resume, force=force)
    check_spec(spec)
    out = Path(out_dir) if out_dir is not None else Path("out") / spec.name
    results = out / RESULTS_FILE
    defs = definitions(spec)
    runs = expand_runs(spec, defs)
    wanted = {r.run_id for r in runs}
    existing = _earlier_rows(spec, runs, defs, out, resume=resume, force=force)
    env = _open_out_dir(out, spec, defs, resume=resume)

    finished = {row["run_id"]: row for row in existing if row["run_id"] in wanted and row.get("status") != "error"}
    retried = sum(1 for row in existing if row["run_id"] in wanted and row.get("status") == "error")
    todo, skipped = _runnable([r for r in runs if r.run_id not in finished])
    if skipped:
        log.info("%d runs skipped, e.g. %s", len(skipped), skipped[0][1])
    n_workers = _default_workers() if workers is None else workers
    n_workers = min(n_workers, len(todo)) if todo else 0
    log.info(
        "compare %s: %d runs, %d finished before (%d errors to rerun), %d to run on %s with %d workers",
        spec.name,
        len(runs),
        len(finished),
        retried,
        len(todo),
        backend,
        n_workers,
    )
    new_rows = _run_all(
        todo, results, backend=backend, n_workers=n_workers, workers=workers, ray_address=ray_address, on_row=on_row
    )

    order = {r.run_id: i for i, r in enumerate(runs)}
    latest = dict(finished)
    latest.update({row["run_id"]: row for row in new_rows})  # a rerun replaces its 'error' row
    rows = sorted(latest.values(), key=lambda r: order[r["run_id"]])
    summary, files = _write_reports(spec, rows, runs, skipped, out, started=started, env=env, plots=plots)
    return CompareResult(
        out_dir=out,
        rows=rows,
        ran=len(new_rows),
        resumed=len(finished),
        skipped=skipped,
        summary=summary,
        files=[results, *files],
        wall_time_s=time.perf_counter() - t_start,
        retried=retried,
        spec_name=spec.name,
    )
