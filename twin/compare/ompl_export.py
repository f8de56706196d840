"""`twin compare` results as OMPL benchmark logs and a Planner Arena database.

Why: OMPL's benchmarking tools are the common ground of motion-planning comparisons. Its script
`ompl_benchmark_statistics` turns benchmark logs into an SQLite database, and Planner Arena
(plannerarena.org, or `plannerarena` locally) plots such a database per experiment and planner. So
twin writes the same two things:

- `write_ompl_logs`: one log per scenario, in the grammar of OMPL's `Benchmark::saveResultsToStream`,
  which `ompl_benchmark_statistics` reads (`readBenchmarkLog`): header (version, experiment, host,
  start date, setup block, random seed, time and memory limit, runs per planner, total time), enum
  types, then per planner its name, common properties, run properties with their types, one line of
  "; "-terminated values per run and a closing ".". An empty value is NULL in the database, for every
  type, so a metric a run does not have (None) is simply left empty.
- `write_planner_arena_db`: the database the script would make from those logs (same tables, columns,
  types, rows and views), built directly from the rows, so it needs no OMPL (an optional extra).

One OMPL experiment per scenario (`<name>.<scenario>`): a scenario is one kind of problem, which is what
an OMPL experiment is, and its cases and seeds are the experiment's runs (`twin_case`, `twin_seed`).
Each run is one twin row (skipped rows are left out; of a repeated run id the last row counts). The
experiments are in file-name order, the order a shell glob (`ompl_benchmark_statistics *.log`) passes
the logs in, so both databases number experiments alike.

Where the runs ran comes from one record, `twin.environment` (the one `twin compare` keeps in compare.json
beside the rows): the host ('Running on', `hostname`), the OMPL version ('OMPL version', `version`), the
machine (CPU, cores, SIMD, BLAS, OS) as the optional cpuinfo block after the setup block that OMPL's
script stores as `cpuinfo`, and twin's commit, Python and the backends' versions as setup lines.

The run properties (`RUN_PROPERTIES`) are OMPL's standard ones where twin measures the same thing
(`time`, `solved`, `status`, `solution length` in joint space, `solution clearance`, `solution
smoothness`) and twin's own, prefixed `twin_` so they never clash with OMPL's. OMPL's `status` enum
(ompl::base::PlannerStatus, values 0-9 as there) is derived from twin's failure reason
(`twin.compare.metrics.FAILURES`; `twin_failure` keeps it exactly):

    success                          -> Exact solution
    start_in_collision               -> Invalid start
    goal_in_collision, ik_failure    -> Invalid goal
    timeout                          -> Timeout
    error (raised, crashed, stopped) -> Crash
    every other failure              -> Unknown status

An ENUM's values are listed in the log under the name of its column, as OMPL does for `status`, because
Planner Arena and OMPL's plotting look them up by column name; the script keeps the first definition of
each name, so every log of one export lists the same values (`twin_case`: every case of the export).
"""

from __future__ import annotations

import logging
import math
import re
import sqlite3
from collections.abc import Callable, Iterable, Mapping, Sequence
from contextlib import closing
from dataclasses import dataclass
from datetime import datetime
from pathlib import Path
from typing import Any, Literal

from twin.compare.metrics import FAILURES, failure_of_row
from twin.compare.runner import latest_rows
from twin.environment import environment as this_environment
from twin.environment import machine_lines, software_lines
from twin.errors import ConfigError

__all__ = [
    "FAILURE_NONE",
    "OMPL_STATUSES",
    "RUN_PROPERTIES",
    "RunProperty",
    "export_planner_arena",
    "ompl_status",
    "write_ompl_logs",
    "write_planner_arena_db",
]

log = logging.getLogger("twin")

Row = dict[str, Any]  # a result row (twin.compare.worker)
OmplType = Literal["REAL", "INTEGER", "BOOLEAN", "ENUM"]

# ompl::base::PlannerStatus::StatusType in its order (the enum values 0..9 OMPL's own logs list)
OMPL_STATUSES: tuple[str, ...] = (
    "Unknown status",
    "Invalid start",
    "Invalid goal",
    "Unrecognized goal type",
    "Timeout",
    "Approximate solution",
    "Exact solution",
    "Crash",
    "Abort",
    "Infeasible",
)
_OMPL_STATUS_OF_FAILURE: dict[str, str] = {
    "start_in_collision": "Invalid start",
    "goal_in_collision": "Invalid goal",
    "ik_failure": "Invalid goal",
    "timeout": "Timeout",
    "error": "Crash",
}
FAILURE_NONE = "none"  # twin_failure of a successful run

_PREFIX = "twin"
_MEMORY_LIMIT_MB = 0.0  # twin sets no memory limit
_NO_VERSION = "twin-export"  # the version written when the record has no OMPL
_NO_HOST = "UNKNOWN"  # OMPL's own host of a log that names none


def ompl_status(row: Row) -> str:
    """OMPL's status of a row (one of OMPL_STATUSES): see the mapping in the module docstring."""
    if row.get("success"):
        return "Exact solution"
    return _OMPL_STATUS_OF_FAILURE.get(failure_of_row(row) or "", "Unknown status")


def _twin_failure(row: Row) -> str | None:
    return FAILURE_NONE if row.get("success") else failure_of_row(row)


def _metric(key: str) -> Callable[[Row], Any]:
    return lambda row: (row.get("metrics") or {}).get(key)


def _timing(key: str) -> Callable[[Row], Any]:
    return lambda row: (row.get("timing") or {}).get(key)


@dataclass(frozen=True)
class RunProperty:
    """One run property of the logs and column of the `runs` table. The log's property line, the column,
    a row's value and an ENUM's values all come from this one definition, so logs and database agree."""

    name: str  # words, as the log spells it; the column is the words joined by "_"
    type: OmplType
    value: Callable[[Row], Any]  # the row's value; None is an empty field (NULL)
    labels: tuple[str, ...] | None = None  # ENUM: its values in order; None: the sorted values of the rows

    @property
    def column(self) -> str:
        return "_".join(self.name.split())

    @property
    def line(self) -> str:
        """The property line of the log, 'words TYPE'."""
        return f"{self.name} {self.type}"


_TWIN_METRICS: tuple[tuple[str, OmplType], ...] = (
    ("duration_s", "REAL"),
    ("max_jerk", "REAL"),
    ("tcp_path_length_m", "REAL"),
    ("contacts", "INTEGER"),
    ("goal_error_m", "REAL"),
)

RUN_PROPERTIES: tuple[RunProperty, ...] = (
    # OMPL's own names, where twin measures the same thing
    RunProperty("time", "REAL", _timing("planning_time_s")),
    RunProperty("solved", "BOOLEAN", lambda row: bool(row.get("success"))),
    RunProperty("status", "ENUM", ompl_status, OMPL_STATUSES),
    RunProperty("solution length", "REAL", _metric("joint_path_length_rad")),
    RunProperty("solution clearance", "REAL", _metric("min_clearance_m")),
    RunProperty("solution smoothness", "REAL", _metric("smoothness")),
    # twin's, the column named after the metric key
    *(RunProperty(f"{_PREFIX} {key.replace('_', ' ')}", t, _metric(key)) for key, t in _TWIN_METRICS),
    RunProperty(f"{_PREFIX} wall time s", "REAL", _timing("wall_time_s")),
    RunProperty(f"{_PREFIX} seed", "INTEGER", lambda row: row.get("seed")),
    RunProperty(f"{_PREFIX} case", "ENUM", lambda row: row.get("case")),
    RunProperty(f"{_PREFIX} failure", "ENUM", _twin_failure, (FAILURE_NONE, *FAILURES)),
)


# ---- the logs as data -----------------------------------------------------------------------------
@dataclass(frozen=True)
class _PlannerLog:
    name: str
    settings: tuple[str, ...]  # the common property lines
    runs: tuple[tuple[str, ...], ...]  # per run, the fields of RUN_PROPERTIES ("" for none)


@dataclass(frozen=True)
class _ExperimentLog:
    """One log file, field by field: the logs are its text, the database is what the script reads from it."""

    name: str
    version: str
    host: str
    date: str
    setup: tuple[str, ...]
    cpuinfo: tuple[str, ...]  # the machine (twin.environment.machine_lines); () writes no block
    seed: str
    time_limit_s: float
    memory_limit_mb: float
    run_count: int
    total_time_s: float
    enums: tuple[tuple[str, tuple[str, ...]], ...]
    planners: tuple[_PlannerLog, ...]

    @property
    def setup_text(self) -> str:
        return "".join(f"{line}\n" for line in self.setup)

    @property
    def cpuinfo_text(self) -> str | None:
        """The cpuinfo block as the script stores it (None when the log has none)."""
        return "".join(f"{line}\n" for line in self.cpuinfo) if self.cpuinfo else None

    @property
    def version_text(self) -> str:
        """The version as the script stores it ('<library> <version>' from the first line)."""
        return f"OMPL {self.version}"

    def text(self) -> str:
        out = [
            f"OMPL version {self.version}",
            f"Experiment {self.name}",
            "0 experiment properties",
            f"Running on {self.host}",
            f"Starting at {self.date}",
            "<<<|",
            *self.setup,
            "|>>>",
            *(["<<<|", *self.cpuinfo, "|>>>"] if self.cpuinfo else []),
            f"{self.seed} is the random seed",
            f"{self.time_limit_s!r} seconds per run",
            f"{self.memory_limit_mb!r} MB per run",
            f"{self.run_count} runs per planner",
            f"{self.total_time_s!r} seconds spent to collect the data",
            f"{len(self.enums)} enum types",
            *("|".join((name, *labels)) for name, labels in self.enums),
            f"{len(self.planners)} planners",
        ]
        for p in self.planners:
            out += [p.name, f"{len(p.settings)} common properties", *p.settings]
            out += [f"{len(RUN_PROPERTIES)} properties for each run", *(q.line for q in RUN_PROPERTIES)]
            out += [f"{len(p.runs)} runs", *("".join(f"{x}; " for x in run) for run in p.runs), "."]
        return "\n".join(out) + "\n"


def _token(text: str) -> str:
    """`text` as one token of a log line (and a file name): whitespace and path separators as '_'."""
    return re.sub(r"[\s/\\]+", "_", text.strip()) or "_"


def _field(prop: RunProperty, value: Any, labels: tuple[str, ...]) -> str:
    """A value as the log writes it; "" (NULL) for None, non-finite numbers and unknown enum values."""
    if value is None:
        return ""
    if prop.type == "REAL":
        v = float(value)
        return repr(v) if math.isfinite(v) else ""
    if prop.type == "INTEGER":
        return str(int(value))
    if prop.type == "BOOLEAN":
        return "1" if value else "0"
    label = _enum_label(value)
    return str(labels.index(label)) if label in labels else ""


def _enum_label(value: Any) -> str:
    return " ".join(str(value).replace("|", "/").split())


def _ompl_version(env: Mapping[str, Any]) -> str:
    packages = env.get("packages")
    version = packages.get("ompl") if isinstance(packages, Mapping) else None
    return _token(str(version)) if version else _NO_VERSION


def _block_line(text: str) -> str:
    """A line of a <<<| ... |>>> block: one that began with a block marker would end the block early."""
    return f" {text}" if text.startswith(("<<<|", "|>>>")) else text


def _seed_token(seeds: Iterable[Any]) -> str:
    """The experiment's seeds as one token short enough for the column (VARCHAR(24))."""
    s = sorted({int(x) for x in seeds if x is not None})
    text = ",".join(map(str, s))
    return text if len(text) <= 24 else f"{s[0]}..{s[-1]}"


def _time_limit(scenario: str, rows: Sequence[Row], given: float | Mapping[str, float] | None) -> float | None:
    if isinstance(given, Mapping):
        given = given.get(scenario)
    if given is not None:
        return float(given)
    limits = [float(r["time_limit_s"]) for r in rows if r.get("time_limit_s") is not None]
    return max(limits) if limits else None


def _experiments(
    rows: Iterable[Row],
    *,
    name: str,
    planners: Sequence[str] | None,
    host: str | None,
    started: datetime | None,
    time_limit_s: float | Mapping[str, float] | None,
    environment: Mapping[str, Any] | None,
) -> list[_ExperimentLog]:
    """The rows as one experiment per scenario, sorted by name. ConfigError when no row is left.
    `environment`: where the rows ran (None: this process, `twin.environment.environment()`; {}: unknown)."""
    all_rows = latest_rows(rows)
    kept = [r for r in all_rows if r.get("status") != "skipped"]
    if not kept:
        raise ConfigError(
            f"no result rows to export ({len(all_rows)} rows, all skipped)" if all_rows else "no result rows to export"
        )
    labels = {
        p.column: p.labels or tuple(sorted({_enum_label(v) for r in kept if (v := p.value(r)) is not None}))
        for p in RUN_PROPERTIES
        if p.type == "ENUM"
    }
    enums = tuple(labels.items())
    env = this_environment() if environment is None else environment
    version = _ompl_version(env)
    host = _token(host or str(env.get("hostname") or _NO_HOST))
    cpuinfo = tuple(_block_line(line) for line in machine_lines(env))
    software = tuple(_block_line(line) for line in software_lines(env))
    date = (started or datetime.now()).strftime("%Y-%m-%d %H:%M:%S")
    order = {p: i for i, p in enumerate(planners or ())}

    by_scenario: dict[str, list[Row]] = {}
    for r in kept:
        by_scenario.setdefault(str(r.get("scenario")), []).append(r)
    out: dict[str, _ExperimentLog] = {}
    scenario_of: dict[str, str] = {}
    for scenario, srows in by_scenario.items():
        exp_name = f"{_token(name)}.{_token(scenario)}"
        if exp_name in out:
            raise ConfigError(
                f"scenarios {scenario_of[exp_name]!r} and {scenario!r} both export as {exp_name!r}; rename one"
            )
        scenario_of[exp_name] = scenario
        by_planner: dict[str, list[Row]] = {}
        for r in srows:
            by_planner.setdefault(str(r.get("planner")), []).append(r)
        ranked = sorted(by_planner, key=lambda p: order.get(p, len(order)))  # stable: others as they came
        plogs = tuple(
            _PlannerLog(
                name=_token(p),
                settings=(f"planner STRING = {_token(str(by_planner[p][0].get('planner_name') or p))}",),
                runs=tuple(
                    tuple(_field(q, q.value(r), labels.get(q.column, ())) for q in RUN_PROPERTIES)
                    for r in by_planner[p]
                ),
            )
            for p in ranked
        )
        limit = _time_limit(scenario, srows, time_limit_s)
        cases = sorted({str(r.get("case")) for r in srows})
        seeds = [r.get("seed") for r in srows]
        setup = (
            f"twin compare {name}, scenario {scenario} ({srows[0].get('kind', 'query')} runs)",
            f"cases: {', '.join(cases)}",
            f"seeds: {_seed_token(seeds) or '-'}",
            f"planners: {', '.join(ranked)}",
            f"runs: {len(srows)}",
            f"time limit per run: {'not recorded in the rows' if limit is None else f'{limit:g} s'}",
            *software,
            "exported from twin result rows by twin.compare.ompl_export",
        )
        out[exp_name] = _ExperimentLog(
            name=exp_name,
            version=version,
            host=host,
            date=date,
            setup=setup,
            cpuinfo=cpuinfo,
            seed=_seed_token(seeds) or "0",
            time_limit_s=0.0 if limit is None else limit,
            memory_limit_mb=_MEMORY_LIMIT_MB,
            run_count=max(len(v) for v in by_planner.values()),
            total_time_s=float(sum(_timing("wall_time_s")(r) or 0.0 for r in srows)),
            enums=enums,
            planners=plogs,
        )
    return [out[k] for k in sorted(out)]


# ---- writing --------------------------------------------------------------------------------------
def _write_logs(experiments: Sequence[_ExperimentLog], out_dir: str | Path) -> list[Path]:
    out = Path(out_dir)
    paths = [out / f"{e.name}.log" for e in experiments]
    try:
        out.mkdir(parents=True, exist_ok=True)
        for e, path in zip(experiments, paths, strict=True):
            path.write_text(e.text(), encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"cannot write the OMPL logs to {out}: {err.strerror or err}") from None
    return paths


# The schema `ompl_benchmark_statistics` creates (readBenchmarkLog), before it adds a column per property
_SCHEMA = """
CREATE TABLE IF NOT EXISTS experiments
    (id INTEGER PRIMARY KEY AUTOINCREMENT, name VARCHAR(512),
    totaltime REAL, timelimit REAL, memorylimit REAL, runcount INTEGER,
    version VARCHAR(128), hostname VARCHAR(1024), cpuinfo TEXT,
    date DATETIME, seed VARCHAR(24), setup TEXT);
CREATE TABLE IF NOT EXISTS plannerConfigs
    (id INTEGER PRIMARY KEY AUTOINCREMENT,
    name VARCHAR(512) NOT NULL, settings TEXT);
CREATE TABLE IF NOT EXISTS enums
    (name VARCHAR(512), value INTEGER, description TEXT,
    PRIMARY KEY (name, value));
CREATE TABLE IF NOT EXISTS runs
    (id INTEGER PRIMARY KEY AUTOINCREMENT, experimentid INTEGER, plannerid INTEGER,
    FOREIGN KEY (experimentid) REFERENCES experiments(id) ON DELETE CASCADE,
    FOREIGN KEY (plannerid) REFERENCES plannerConfigs(id) ON DELETE CASCADE);
CREATE TABLE IF NOT EXISTS progress
    (runid INTEGER, time REAL, PRIMARY KEY (runid, time),
    FOREIGN KEY (runid) REFERENCES runs(id) ON DELETE CASCADE);
"""

# The views its command line adds (computeViews): the best configuration of each planner, per
# experiment and overall, by success rate and then mean time
_RUN_TIMES = """SELECT plannerid, plannerConfigs.name AS plannerName, experimentid, solved, time AS total_time
    FROM plannerConfigs INNER JOIN experiments INNER JOIN runs
    ON plannerConfigs.id=runs.plannerid AND experiments.id=runs.experimentid"""
_VIEWS = f"""
CREATE VIEW bestPlannerConfigsPerExperiment AS
    SELECT plannerid, experimentid, MIN(avg_solved) AS avg_solved, avg_total_time
    FROM (SELECT plannerid, plannerName, experimentid, AVG(solved) AS avg_solved,
        AVG(total_time) AS avg_total_time FROM ({_RUN_TIMES}) GROUP BY plannerid, experimentid)
    GROUP BY plannerName, experimentid ORDER BY avg_solved DESC, avg_total_time ASC;
CREATE VIEW bestPlannerConfigs AS
    SELECT plannerid, MIN(avg_solved) AS avg_solved, avg_total_time
    FROM (SELECT plannerid, plannerName, AVG(solved) AS avg_solved,
        AVG(total_time) AS avg_total_time FROM ({_RUN_TIMES}) GROUP BY plannerid)
    GROUP BY plannerName ORDER BY avg_solved DESC, avg_total_time ASC;
"""


def _insert_experiment(c: sqlite3.Cursor, e: _ExperimentLog) -> None:
    """What readBenchmarkLog stores of one log: its enums (the first definition of a name wins), the
    experiment, each planner configuration (shared by name and settings) and the runs, each field as
    the text the log holds (an empty one NULL), so SQLite converts it by the column's type alike."""
    for enum_name, labels in e.enums:
        if c.execute("SELECT 1 FROM enums WHERE name = ?", (enum_name,)).fetchone() is None:
            c.executemany("INSERT INTO enums VALUES (?, ?, ?)", [(enum_name, j, d) for j, d in enumerate(labels)])
    c.execute(
        "INSERT INTO experiments (name, totaltime, timelimit, memorylimit, runcount, version, hostname, cpuinfo, "
        "date, seed, setup) VALUES (?, ?, ?, ?, ?, ?, ?, ?, ?, ?, ?)",
        (
            e.name,
            e.total_time_s,
            e.time_limit_s,
            e.memory_limit_mb,
            e.run_count,
            e.version_text,
            e.host,
            e.cpuinfo_text,
            e.date,
            e.seed,
            e.setup_text,
        ),
    )
    experiment_id = c.lastrowid
    columns = ", ".join(["experimentid", "plannerid", *(p.column for p in RUN_PROPERTIES)])
    insert_run = f"INSERT INTO runs ({columns}) VALUES ({', '.join('?' * (len(RUN_PROPERTIES) + 2))})"
    for p in e.planners:
        settings = "".join(f"{line}\n;" for line in p.settings)
        found = c.execute("SELECT id FROM plannerConfigs WHERE (name=? AND settings=?)", (p.name, settings)).fetchone()
        if found is None:
            c.execute("INSERT INTO plannerConfigs VALUES (?, ?, ?)", (None, p.name, settings))
            planner_id = c.lastrowid
        else:
            planner_id = found[0]
        c.executemany(insert_run, [(experiment_id, planner_id, *(x or None for x in run)) for run in p.runs])


def _write_db(experiments: Sequence[_ExperimentLog], db_path: str | Path) -> Path:
    path = Path(db_path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.unlink(missing_ok=True)  # as the script without --append: a new database
        with closing(sqlite3.connect(path)) as conn:
            c = conn.cursor()
            c.execute("PRAGMA FOREIGN_KEYS = ON")
            c.executescript(_SCHEMA)
            for p in RUN_PROPERTIES:
                c.execute(f"ALTER TABLE runs ADD {p.column} {p.type}")
            for e in experiments:
                _insert_experiment(c, e)
            conn.commit()
            c.executescript(_VIEWS)
            conn.commit()
    except (OSError, sqlite3.Error) as err:
        raise ConfigError(
            f"cannot write the Planner Arena database {path}: {getattr(err, 'strerror', None) or err}"
        ) from None
    return path


# ---- public ---------------------------------------------------------------------------------------
def write_ompl_logs(
    rows: Iterable[Row],
    out_dir: str | Path,
    *,
    name: str = "compare",
    planners: Sequence[str] | None = None,
    host: str | None = None,
    started: datetime | None = None,
    time_limit_s: float | Mapping[str, float] | None = None,
    environment: Mapping[str, Any] | None = None,
) -> list[Path]:
    """Write one OMPL benchmark log per scenario, `out_dir/<name>.<scenario>.log`, so OMPL's tools
    (`ompl_benchmark_statistics`, Planner Arena) read twin's results like their own.

    `rows`: result rows (results.jsonl). `planners`: labels in the order to list them (others follow as
    they come). `host`, `started`: the 'Running on' and 'Starting at' lines (default: the environment's
    host, now). `time_limit_s`: the limit per run, one for all or per scenario (default: the largest the
    rows record; 0 when none does). `environment`: where the rows ran, a `twin.environment` record (the
    sweep's compare.json has it); None: this process's; {}: unknown (host UNKNOWN, no cpuinfo block).
    Raises ConfigError for no rows or an unwritable folder.
    """
    exps = _experiments(
        rows,
        name=name,
        planners=planners,
        host=host,
        started=started,
        time_limit_s=time_limit_s,
        environment=environment,
    )
    paths = _write_logs(exps, out_dir)
    log.info("wrote %d OMPL benchmark logs to %s", len(paths), out_dir)
    return paths


def write_planner_arena_db(
    rows: Iterable[Row],
    db_path: str | Path,
    *,
    name: str = "compare",
    planners: Sequence[str] | None = None,
    host: str | None = None,
    started: datetime | None = None,
    time_limit_s: float | Mapping[str, float] | None = None,
    environment: Mapping[str, Any] | None = None,
) -> Path:
    """Write the SQLite database `ompl_benchmark_statistics` would make from `write_ompl_logs`' logs (the
    file Planner Arena opens), without OMPL installed. An existing file is replaced. Arguments as there;
    raises ConfigError for no rows or an unwritable path."""
    exps = _experiments(
        rows,
        name=name,
        planners=planners,
        host=host,
        started=started,
        time_limit_s=time_limit_s,
        environment=environment,
    )
    return _write_db(exps, db_path)


def export_planner_arena(
    rows: Iterable[Row],
    out_dir: str | Path,
    *,
    name: str = "compare",
    planners: Sequence[str] | None = None,
    host: str | None = None,
    started: datetime | None = None,
    time_limit_s: float | Mapping[str, float] | None = None,
    environment: Mapping[str, Any] | None = None,
) -> list[Path]:
    """Write both, the logs and `out_dir/<name>.db`, from one reading of the rows (so they agree to the
    date); returns the logs' paths, then the database's. Raises ConfigError as the two do."""
    exps = _experiments(
        rows,
        name=name,
        planners=planners,
        host=host,
        started=started,
        time_limit_s=time_limit_s,
        environment=environment,
    )
    paths = _write_logs(exps, out_dir)
    paths.append(_write_db(exps, Path(out_dir) / f"{_token(name)}.db"))
    log.info("wrote %d OMPL benchmark logs and the Planner Arena database %s", len(paths) - 1, paths[-1])
    return paths
