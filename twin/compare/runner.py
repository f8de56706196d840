"""The comparison runner: planners x scenarios x seeds, one row per finished run, resumable.

Why it looks like this:
* every run is one call of `twin.compare.worker.execute_run(RunTask) -> row`, the same function in a
  local process pool (default), in-process (`workers=0`, for debugging) and on Ray (`backend="ray"`);
* the main process alone writes `DIR/results.jsonl`: one JSON line per finished run, flushed and
  fsync'd as it arrives, so a crash loses nothing finished;
* `resume=True` reads the file (dropping a line cut short by a crash), skips the run ids it holds and
  appends the rest, so each run ends up in the file exactly once;
* everything a user can get wrong (an unknown planner name, bad params, a missing scene file) is a
  ConfigError before the first run starts.
"""

from __future__ import annotations

import json
import logging
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal

from twin.compare.spec import CompareSpec, RunTask, TaskScenario, expand_runs, load_compare_config
from twin.compare.worker import TASKS_UNAVAILABLE, execute_run, quiet_imports, worker_init
from twin.errors import ConfigError, DependencyMissing, TwinError, UnknownNameError

__all__ = ["CompareResult", "run_comparison", "check_spec", "read_results", "tasks_available", "RESULTS_FILE"]

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
    summary: Any  # twin.compare.report.Summary
    files: list[Path] = field(default_factory=list)
    wall_time_s: float = 0.0

    @property
    def results_path(self) -> Path:
        return self.out_dir / RESULTS_FILE


# ---- checks before anything runs ----------------------------------------------------------------
def tasks_available() -> bool:
    """True when `twin.tasks.run_task` can be imported (task scenarios run); else they are skipped."""
    try:
        from twin.tasks import run_task  # noqa: F401
    except ImportError:
        return False
    return True


def check_spec(spec: CompareSpec, *, instantiate: bool = True) -> None:
    """Raise ConfigError for an unknown planner or retimer name, bad planner params, or a scenario
    config that does not load, before anything runs. With `instantiate`, each planner is also built
    once here, so a missing backend (DependencyMissing, naming the extra) stops the sweep now rather
    than turning every one of its runs into an error row."""
    from twin.config import load_config
    from twin.planning import make_context, make_planner
    from twin.registry import Kind, default_registry, validate_params

    source = spec.source or "<compare config>"
    settings = []
    for i, sc in enumerate(spec.scenarios):
        path = sc.task if isinstance(sc, TaskScenario) else sc.scene
        try:
            settings.append(load_config(path, sc.overrides))
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
                if not hasattr(cls, "set_retimer"):
                    raise ConfigError(f"planner {p.name!r} produces trajectories itself and takes no retimer")
                try:
                    rentry = registry.entry(p.retimer, (Kind.RETIMER,))
                except UnknownNameError as e:
                    raise ConfigError(str(e)) from None
                validate_params(rentry, rentry.load(), p.retimer_params)
            if instantiate:
                make_planner(p.block(), make_context(settings[0], registry))
        except (ConfigError, DependencyMissing) as e:
            raise type(e)(f"{source}: planners.{i} ({p.id}): {e}") from None


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


class _Appender:
    """Appends one JSON line per row and makes it durable before the next one (flush + fsync)."""

    def __init__(self, path: Path) -> None:
        self._f = open(path, "a", encoding="utf-8")

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
    quiet_imports()
    for t in todo:
        yield execute_run(t)


def _run_local(todo: Sequence[RunTask], workers: int) -> Iterator[dict[str, Any]]:
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    pool = ProcessPoolExecutor(max_workers=workers, mp_context=_mp_context(), initializer=worker_init)
    try:
        pending = {pool.submit(execute_run, t) for t in todo}
        while pending:
            done, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in done:
                try:
                    yield fut.result()
                except BrokenProcessPool as e:
                    raise TwinError(
                        f"a worker process died ({e}); finished runs are saved, rerun with --resume"
                    ) from None
    finally:
        pool.shutdown(wait=True, cancel_futures=True)


def _run_ray(todo: Sequence[RunTask], workers: int, address: str | None) -> Iterator[dict[str, Any]]:
    try:
        import ray
    except ImportError as e:
        raise DependencyMissing(
            f"the ray backend needs ray ({e.name or 'ray'} is not installed); install it with `pip install 'twin[ray]'`"
        ) from e
    started = False
    if not ray.is_initialized():
        kw: dict[str, Any] = dict(include_dashboard=False, log_to_driver=False, logging_level=logging.ERROR)
        address = address or os.environ.get("RAY_ADDRESS")
        if address:
            ray.init(address=address, **kw)
        else:  # a local cluster of `workers` CPUs, started for this sweep and stopped after it
            ray.init(num_cpus=workers, **kw)
        started = True
    try:
        remote = ray.remote(num_cpus=1, max_retries=0)(execute_run)
        pending = [remote.remote(t) for t in todo]
        while pending:
            done, pending = ray.wait(pending, num_returns=1)
            for ref in done:
                yield ray.get(ref)
    finally:
        if started:
            ray.shutdown()


# ---- the sweep ------------------------------------------------------------------------------------
def _default_workers() -> int:
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not on Linux
        return max(1, os.cpu_count() or 1)


def run_comparison(
    spec: CompareSpec | str | Path,
    *,
    out_dir: str | Path | None = None,
    workers: int | None = None,
    backend: Backend = "local",
    resume: bool = False,
    overrides: Iterable[str] = (),
    ray_address: str | None = None,
    plots: bool = True,
    on_row: Callable[[dict[str, Any], int, int], None] | None = None,
) -> CompareResult:
    """Run a comparison (a CompareSpec or the path of its YAML) and write results, summary and plots.

    `out_dir`: default `out/<spec name>`. `workers`: parallel runs (default: the CPUs this process
    may use; 0 runs in this process). `backend`: "local" (process pool) or "ray" (`ray.init()` locally
    unless `ray_address` or RAY_ADDRESS names a cluster; the extra `twin[ray]`). `resume`: continue the
    sweep in out_dir, skipping finished run ids; without it an existing non-empty results.jsonl is a
    ConfigError. `on_row(row, done, total)` is called as each run finishes (the CLI prints progress).
    """
    t_start = time.perf_counter()
    if not isinstance(spec, CompareSpec):
        spec = load_compare_config(spec, overrides)
    elif overrides:
        raise ConfigError("overrides apply to a config file; pass the path, or change the CompareSpec itself")
    if backend not in ("local", "ray"):
        raise ConfigError(f"backend must be 'local' or 'ray', got {backend!r}")
    if workers is not None and workers < 0:
        raise ConfigError(f"workers must be >= 0, got {workers}")
    check_spec(spec)
    out = Path(out_dir) if out_dir is not None else Path("out") / spec.name
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise ConfigError(f"cannot create the output folder {out}: {e.strerror}") from None
    results = out / RESULTS_FILE

    runs = expand_runs(spec)
    spec_json = spec.model_dump(mode="json")
    spec_path = out / SPEC_FILE
    if resume:
        existing = read_results(results, repair=True)
        if spec_path.is_file():
            try:
                if json.loads(spec_path.read_text()) != spec_json:
                    log.warning("%s: resuming with a different comparison config than the one that started it", out)
            except ValueError:
                pass
    else:
        if results.is_file() and results.stat().st_size > 0:
            raise ConfigError(
                f"{results} already holds results; pass --resume to continue that sweep, or choose another --out"
            )
        existing = []
    spec_path.write_text(json.dumps(spec_json, indent=1))

    wanted = {r.run_id for r in runs}
    finished: dict[str, dict[str, Any]] = {}
    for row in existing:
        if row["run_id"] in wanted and row["run_id"] not in finished:
            finished[row["run_id"]] = row
    skipped: list[tuple[str, str]] = []
    have_tasks = tasks_available()
    todo: list[RunTask] = []
    for r in runs:
        if r.run_id in finished:
            continue
        if r.kind == "task" and not have_tasks:
            skipped.append((r.run_id, TASKS_UNAVAILABLE))
            continue
        todo.append(r)
    if skipped:
        log.warning("%d task runs %s", len(skipped), TASKS_UNAVAILABLE)
    n_workers = _default_workers() if workers is None else workers
    n_workers = min(n_workers, len(todo)) if todo else 0
    log.info("compare %s: %d runs, %d finished before, %d to run on %s with %d workers",
             spec.name, len(runs), len(finished), len(todo), backend, n_workers)

    new_rows: list[dict[str, Any]] = []
    if todo:
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

    order = {r.run_id: i for i, r in enumerate(runs)}
    rows = sorted(list(finished.values()) + new_rows, key=lambda r: order[r["run_id"]])
    from twin.compare.report import summarize, write_summary

    summary = summarize(rows, planners=[p.id for p in spec.planners], skipped=skipped)
    files = [results, *write_summary(summary, out)]
    if plots:
        try:
            from twin.compare.plots import write_plots

            files += write_plots(rows, out, planners=[p.id for p in spec.planners])
        except DependencyMissing as e:
            log.warning("no plots: %s", e)
    return CompareResult(
        out_dir=out, rows=rows, ran=len(new_rows), resumed=len(finished), skipped=skipped, summary=summary,
        files=files, wall_time_s=time.perf_counter() - t_start,
    )
