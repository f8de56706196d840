"""The comparison config: which planners, on which scenarios, with which seeds.

A comparison file is YAML loaded straight into `CompareSpec` (unknown keys rejected with their dotted
path, `extends: other.yaml` and `--set a.b=value` work as for scene configs)::

    name: smoke
    seeds: [0, 1]
    planners:
      - ruckig.movej                                  # a bare registered name ...
      - {name: toppra.movel, params: {...}}           # ... or a planner block
      - {name: ompl.rrtconnect, retimer: toppra, label: rrtconnect+toppra}
    scenarios:
      - name: warehouse-blocked                       # motion queries in a scene config
        scene: warehouse.yaml                         # relative to this file, else a shipped config
        random: {count: 3, goal: joint, straight: blocked}   # only queries a straight line cannot solve
      - name: robocup-fixed
        scene: robocup.yaml
        queries:
          - {start: [0, -1.6, 1.5, -1.5, -1.57, 0], goal: [0.3, -1.4, 1.2, -1.4, -1.57, 0.2]}
          - {start: [0, -1.6, 1.5, -1.5, -1.57, 0], goal_pose: [-0.5, 0.1, 0.2, 3.1416, 0, 0]}
      - name: exported                                # a problem-set file (`twin problems export`,
        problems: warehouse-blocked.json              #   MoveIt import): its world, each problem with its seed
      - name: warehouse-task                          # a full task run (`twin run`)
        task: warehouse.yaml
        seeds: [0, 1]                                 # this scenario's own seeds
      - name: robocup-faults                          # a sweep: any config key as a scenario axis
        task: robocup.yaml
        sweep:
          camera.noise.scale: [1, 2, 3, 4]            # the first value of each key is its nominal level
          camera.extrinsic_error.translation_m: [0, 0.005, 0.01]

Why the cross product is expanded here: every run gets its `run_id` from (planner, case, seed), where a
case is one query of a query scenario (`name#i`) or a task scenario (`name`), plus a hash of everything
that defines the run (the whole planner block and label, the scenario's settings and its loaded config,
the seed), e.g. `rrtconnect|robocup-blocked#3|seed=1|a1b2c3d4`. So run ids are stable across reruns,
resumes and backends, and a run whose definition changed is a different run, never a stale row.

Why a sweep is one factor at a time: each swept key is an axis, varied with every other swept key at its
first (nominal) value, so the example runs the nominal point (noise 1, translation 0) once, then 3 noise
levels and 2 translations: 1 + 3 + 2 = 6 levels, where the full grid would be 4 x 3 = 12; with three or
four keys a grid explodes, while the question asked ("how does success fall off along this fault?") needs
only the axes. `sweep_mode: grid` runs the cross product instead (for interactions; the report still
draws the axes through the nominal point).

Each level is a case of the scenario, named `robocup-faults@camera.noise.scale=3` (`@nominal` for the
shared point, which runs once and belongs to every axis; a grid point off the axes joins its keys with
';'; a query scenario's query index follows: `...@camera.noise.scale=3#2`). Its config gets `key=value`
for every swept key appended to the scenario's `overrides`, in `sweep` order. Its run id hashes the whole
point, so a changed level or nominal value is a different run, and an added level leaves the others their
ids. Rows carry the point (`sweep`: {key: value} of every swept key; None without a sweep) and the axes it
lies on (`sweep_axes`: every key for the nominal point), so results group by level without parsing names.
Every value and level is loaded into the scenario's config when the comparison is: an unknown key or a
value the config rejects is a ConfigError naming the scenario, the key and what is allowed.
"""

from __future__ import annotations

import difflib
import itertools
import json
import math
import re
import zlib
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Literal, NamedTuple

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Discriminator,
    Field,
    PrivateAttr,
    Tag,
    ValidationError,
    field_validator,
    model_validator,
)

from twin.assets import digest
from twin.config import PlannerBlock, apply_override, find_config, load_config, read_yaml
from twin.config.loader import unknown_key_hint
from twin.errors import ConfigError
from twin.problems.mbm import mbm_problem_set
from twin.problems.problem_set import ProblemSet, load_problem_set
from twin.problems.queries import query_of_problem
from twin.problems.sampling import RandomQueries

__all__ = [
    "NOMINAL",
    "Case",
    "ComparePlanner",
    "CompareSpec",
    "QueryScenario",
    "QuerySpec",
    "RandomQueries",
    "RunTask",
    "SweepLevel",
    "TaskScenario",
    "case_name",
    "compare_spec_from_dict",
    "definitions",
    "describe_changes",
    "digest",
    "expand_runs",
    "load_compare_config",
    "run_id",
    "run_key",
]

_NAME_PATTERN = r"^[A-Za-z0-9_.+\-]+$"  # no '|', '#', '@' or spaces: they delimit run ids and case names
_KEY_PATTERN = r"^[A-Za-z0-9_]+(\.[A-Za-z0-9_]+)*$"  # a dotted config key, as `--set` takes it
NOMINAL = "nominal"  # the case label of a sweep's shared point (every swept key at its first value)
_LABEL_FORBIDDEN = set("|#@;") | {" ", "\t", "\n", "\r"}

Q6 = tuple[float, float, float, float, float, float]


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True)


class ComparePlanner(PlannerBlock):
    """A planner block plus a `label` that names it in results (default: its registered name).

    Labels let one planner appear twice with different params (`rrtconnect-fast`, `rrtconnect-slow`).
    """

    label: str | None = Field(None, pattern=_NAME_PATTERN)

    @property
    def id(self) -> str:
        return self.label or self.name

    def block(self) -> PlannerBlock:
        """The plain planner block (what `make_planner` takes)."""
        return PlannerBlock(
            name=self.name, params=self.params, retimer=self.retimer, retimer_params=self.retimer_params
        )


class QuerySpec(_Model):
    """One explicit motion query: start (6,) rad and either a joint goal (6,) rad or a TCP pose goal
    `goal_pose` = x, y, z, roll, pitch, yaw (m, rad; base frame) of `frame`.

    A pose goal is reached exactly (twin.types' default tolerances) unless `orientation_free` makes it a
    position goal, reached within `position_tolerance_m` (default 3 cm, as the warehouse transfer asks)."""

    start: Q6
    goal: Q6 | None = None
    goal_pose: tuple[float, float, float, float, float, float] | None = None
    frame: Literal["tcp", "flange"] = "tcp"
    orientation_free: bool = False
    position_tolerance_m: float | None = Field(None, gt=0, le=0.1)

    @property
    def goal_kind(self) -> str:
        """'joint', 'pose' or 'position' (see `twin.planning.GOAL_KINDS`)."""
        return "joint" if self.goal is not None else "position" if self.orientation_free else "pose"

    @model_validator(mode="after")
    def _one_goal(self) -> QuerySpec:
        if (self.goal is None) == (self.goal_pose is None):
            raise ValueError("give exactly one of `goal` (joint angles) or `goal_pose` (x, y, z, roll, pitch, yaw)")
        if self.goal is not None and (self.orientation_free or self.position_tolerance_m is not None):
            raise ValueError("`orientation_free` and `position_tolerance_m` apply to `goal_pose` only")
        vals = list(self.start) + list(self.goal or ()) + list(self.goal_pose or ())
        if not all(math.isfinite(v) for v in vals):
            raise ValueError("start and goal must be finite numbers")
        return self


def _yaml_text(v: Any) -> str:
    """`v` as the YAML flow text an override carries (`apply_override` reads it back to `v`)."""
    return str(yaml.safe_dump([v], default_flow_style=True, width=1_000_000)).strip()[1:-1]


def _label_text(v: Any) -> str:
    """`v` as a case name shows it: a string as it is, anything else as compact JSON ('0.005', '[0.5,1.5]')."""
    return v if isinstance(v, str) else json.dumps(v, separators=(",", ":"))


@dataclass(frozen=True)
class SweepLevel:
    """One point of a scenario's sweep: the value of every swept key (`point`, in `sweep` order), its label
    in case names ('nominal', 'camera.noise.scale=3'; '' for a scenario without a sweep) and the swept keys
    whose axis it lies on (every other key at its first value: all of them for the nominal point)."""

    point: dict[str, Any]
    label: str
    axes: tuple[str, ...]

    def overrides(self) -> tuple[str, ...]:
        """'key=value' for every swept key, in `sweep` order: what the level appends to the scenario's overrides."""
        return tuple(f"{k}={_yaml_text(v)}" for k, v in self.point.items())


UNSWEPT = SweepLevel({}, "", ())


class _Swept(_Model):
    """The sweep of a scenario (see the module docstring): `sweep` maps dotted config keys to their levels,
    the first one nominal; `sweep_mode` is `one_at_a_time` (default: the axes through the nominal point)
    or `grid` (every combination)."""

    sweep: dict[str, list[Any]] = Field(default_factory=dict)
    sweep_mode: Literal["one_at_a_time", "grid"] = "one_at_a_time"

    @model_validator(mode="after")
    def _check_sweep(self) -> _Swept:
        name = getattr(self, "name", "?")
        for key, values in self.sweep.items():
            where = f"scenario {name!r}: sweep {key!r}"
            if not re.match(_KEY_PATTERN, key):
                raise ValueError(f"{where}: a sweep key is a dotted config key such as camera.noise.scale")
            if not values:
                raise ValueError(f"{where}: the list of values is empty; give at least one (the first is nominal)")
            for i, v in enumerate(values):
                try:
                    json.dumps(v, allow_nan=False)
                except (TypeError, ValueError):
                    raise ValueError(f"{where}: value {v!r} is not a plain YAML value (number, string, list)") from None
                try:
                    back = yaml.safe_load(_yaml_text(v))
                except yaml.YAMLError:
                    back = None
                if back != v:
                    raise ValueError(f"{where}: value {v!r} does not survive a --set override; write it plainly")
                text = _label_text(v)
                if not text or _LABEL_FORBIDDEN & set(text):
                    raise ValueError(
                        f"{where}: value {text!r} names a case: no spaces, '|', '#', '@' or ';', and not empty"
                    )
                if any(_same(v, w) for w in values[:i]):
                    raise ValueError(f"{where}: value {text} is listed twice; each level once")
        if self.sweep_mode == "grid" and self.level_count() > 10_000:
            raise ValueError(f"scenario {name!r}: a sweep grid of {self.level_count()} levels; use one_at_a_time")
        return self

    def level_count(self) -> int:
        """How many levels the sweep has (1 without a sweep; the nominal point counts once)."""
        if self.sweep_mode == "grid":
            return math.prod(len(v) for v in self.sweep.values())
        return 1 + sum(len(v) - 1 for v in self.sweep.values())

    def levels(self) -> list[SweepLevel]:
        """The sweep's levels in run order, the nominal point first: then each key's other values in
        `sweep` order (one_at_a_time), or the cross product in `sweep` order (grid). Without a sweep, one
        level with an empty point and label."""
        if not self.sweep:
            return [UNSWEPT]
        keys = list(self.sweep)
        nominal = {k: v[0] for k, v in self.sweep.items()}
        if self.sweep_mode == "grid":
            points = [dict(zip(keys, combo, strict=True)) for combo in itertools.product(*self.sweep.values())]
        else:
            points = [nominal] + [dict(nominal, **{k: v}) for k in keys for v in self.sweep[k][1:]]
        out = []
        for point in points:
            off = [k for k in keys if not _same(point[k], nominal[k])]
            label = ";".join(f"{k}={_label_text(point[k])}" for k in off) or NOMINAL
            axes = tuple(keys) if not off else tuple(off) if len(off) == 1 else ()
            out.append(SweepLevel(point, label, axes))
        return out

    def query_count(self) -> int:
        """Queries (or problems) per seed of a query scenario; 1 for a task run."""
        return 1

    def case_count(self) -> int:
        """Cases per seed: queries (1 for a task run) x sweep levels."""
        return self.query_count() * self.level_count()


def _same(a: Any, b: Any) -> bool:
    """Two sweep values are one level when they are equal as data (1 and 1.0 are; True and 1 are not)."""
    return json.dumps(a, sort_keys=True) == json.dumps(b, sort_keys=True) or (
        type(a) in (int, float) and type(b) in (int, float) and a == b
    )


class QueryScenario(_Swept):
    """Motion queries planned in the static cell of a scene config, then executed in PyBullet.

    The queries are listed (`queries`), drawn at random (`random`), or read from a problem-set file
    (`problems`, relative to the comparison file): then the cell's fixtures are the file's primitives,
    in the robot cell of `scene` (default: the config the file names in `source.config`), and each
    problem runs once with its own seed and time limit unless `seeds` / `time_limit_s` are given.

    Loose objects are left out of both the planning scene and the physics, so the two agree. Fixtures
    marked `known: false` (obstacles a task must perceive first) are, with `unknown_fixtures: box`,
    added to the planning scene as the axis-aligned box a perfect detector would report (a motion query
    has no perception step; box-based planners such as NMPC see them too); with `ignore` the planners
    do not see them and the physics shows what the robot hits.
    """

    name: str = Field(pattern=_NAME_PATTERN)
    scene: str | None = None
    overrides: list[str] = Field(default_factory=list)
    queries: list[QuerySpec] = Field(default_factory=list)
    random: RandomQueries | None = None
    problems: str | None = None
    seeds: list[int] | None = None
    time_limit_s: float | None = Field(None, gt=0)
    unknown_fixtures: Literal["box", "ignore"] = "box"
    _problem_set: ProblemSet | None = PrivateAttr(None)

    @model_validator(mode="after")
    def _one_source(self) -> QueryScenario:
        if bool(self.queries) + (self.random is not None) + (self.problems is not None) != 1:
            raise ValueError(
                "give exactly one of `queries` (a list), `random` ({count: N, ...}) or `problems` (a problem-set file)"
            )
        if self.scene is None and self.problems is None:
            raise ValueError("`scene` (the scene config the queries are planned in) is missing")
        return self

    @property
    def kind(self) -> str:
        return "query"

    @property
    def problem_set(self) -> ProblemSet:
        """The loaded problem set of a `problems:` scenario (loaded when the spec is)."""
        if self._problem_set is None:
            raise ConfigError(f"scenario {self.name!r}: its problem set is not loaded (load the spec from a file)")
        return self._problem_set

    def query_count(self) -> int:
        if self.problems is not None:
            return len(self.problem_set.problems)
        return len(self.queries) if self.queries else self.random.count  # type: ignore[union-attr]


class TaskScenario(_Swept):
    """A full task run (`twin run`) of a scene/task config with each planner."""

    name: str = Field(pattern=_NAME_PATTERN)
    task: str
    overrides: list[str] = Field(default_factory=list)
    seeds: list[int] | None = None

    @property
    def kind(self) -> str:
        return "task"


def _scenario_kind(v: Any) -> str:
    if isinstance(v, dict):
        return "task" if "task" in v else "query"
    return "task" if isinstance(v, TaskScenario) else "query"


Scenario = Annotated[
    Annotated[QueryScenario, Tag("query")] | Annotated[TaskScenario, Tag("task")],
    Discriminator(_scenario_kind),
]


class CompareSpec(_Model):
    """A whole comparison: planners x scenarios x seeds, and how each run is measured.

    `execute`: run each trajectory in PyBullet (contacts, goal error after `settle_s`).
    `jerk_dt_s`: the resampling step for max |jerk| (finite differences of qdd).
    `run_timeout_s`: a run that has not returned after this long (a planner that ignores its time limit)
    is stopped and recorded as an error row (local backend); default `default_run_timeout`.
    `reference`: the planner the summary pairs every other one against on the same problems (wins, ties,
    losses, Wilcoxon signed-rank p); default the first planner.
    """

    name: str = Field("compare", pattern=_NAME_PATTERN)
    planners: list[ComparePlanner] = Field(min_length=1)
    scenarios: list[Scenario] = Field(min_length=1)
    seeds: list[int] = Field(default_factory=lambda: [0], min_length=1)
    time_limit_s: float = Field(1.0, gt=0)
    execute: bool = True
    settle_s: float = Field(0.5, ge=0, le=10)
    jerk_dt_s: float = Field(1e-3, gt=0, le=0.01)
    run_timeout_s: float | None = Field(None, gt=0)
    reference: str | None = None  # the planner label every other planner is paired against (default: the first)
    _source: str | None = PrivateAttr(None)

    @property
    def source(self) -> str | None:
        """The file (or '<dict>') it was loaded from, for error messages."""
        return self._source

    @field_validator("planners", mode="before")
    @classmethod
    def _bare_names(cls, v: Any) -> Any:
        if isinstance(v, list):
            return [{"name": p} if isinstance(p, str) else p for p in v]
        return v

    @field_validator("seeds")
    @classmethod
    def _unique_seeds(cls, v: list[int]) -> list[int]:
        if len(set(v)) != len(v):
            raise ValueError(f"seeds must be unique, got {v}")
        return v

    @model_validator(mode="after")
    def _unique_names(self) -> CompareSpec:
        ids = [p.id for p in self.planners]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"planner labels must be unique, repeated: {dup} (give each a `label`)")
        if self.reference is not None and self.reference not in ids:
            raise ValueError(f"reference {self.reference!r} is not a planner label of this comparison; labels: {ids}")
        names = [s.name for s in self.scenarios]
        dup = sorted({n for n in names if names.count(n) > 1})
        if dup:
            raise ValueError(f"scenario names must be unique, repeated: {dup}")
        for s in self.scenarios:
            if s.seeds is not None and (not s.seeds or len(set(s.seeds)) != len(s.seeds)):
                raise ValueError(f"scenario {s.name!r}: seeds must be a non-empty list of unique integers")
        return self

    def seeds_for(self, scenario: QueryScenario | TaskScenario) -> list[int]:
        """The seeds a scenario runs with; a problem set's problems without `seeds:` run once each, with
        the seed the file gives them."""
        if scenario.seeds is not None:
            return list(scenario.seeds)
        if isinstance(scenario, QueryScenario) and scenario.problems is not None:
            return sorted({p.seed for p in scenario.problem_set.problems})
        return list(self.seeds)

    def cases(self, scenario: QueryScenario | TaskScenario) -> list[Case]:
        """(query index or None for a task, seed, sweep level) of every run a planner makes in `scenario`,
        in run order: by seed, then query, then level (so the first seed has seen every level early)."""
        levels = scenario.levels()
        if isinstance(scenario, TaskScenario):
            pairs: list[tuple[int | None, int]] = [(None, seed) for seed in self.seeds_for(scenario)]
        elif scenario.problems is not None and scenario.seeds is None:
            pairs = [(i, p.seed) for i, p in enumerate(scenario.problem_set.problems)]
        else:
            pairs = [(i, seed) for seed in self.seeds_for(scenario) for i in range(scenario.query_count())]
        return [Case(i, seed, level) for i, seed in pairs for level in levels]


class Case(NamedTuple):
    """One case of a scenario: the query index (None for a task run), the seed and the sweep level."""

    query_index: int | None
    seed: int
    level: SweepLevel


# ---- runs ----------------------------------------------------------------------------------------
def config_digest(path: str | Path, overrides: Iterable[str] = ()) -> str:
    """Hash of a scene/task config as loaded (after `extends` and overrides), so an edit to the file that
    changes what a run does changes the run ids, and a comment or a moved checkout does not."""
    return digest(load_config(path, list(overrides)).model_dump(mode="json"), 16)


def planner_definition(p: ComparePlanner) -> dict[str, Any]:
    """What defines a planner's runs: the whole block and its label."""
    return p.model_dump(mode="json")


def scenario_definitions(spec: CompareSpec) -> dict[str, dict[str, Any]]:
    """What defines each scenario's runs (name -> dict): its settings as written (minus the seeds and the
    config's path), the loaded config's hash, and the comparison settings its runs use."""
    out: dict[str, dict[str, Any]] = {}
    for sc in spec.scenarios:
        path = sc.task if isinstance(sc, TaskScenario) else sc.scene
        assert path is not None  # resolved on load
        d = sc.model_dump(mode="json", exclude={"seeds", "scene", "task", "problems", "sweep", "sweep_mode"})
        if sc.sweep:  # only then, so the runs of a scenario without a sweep keep the ids they had
            d["sweep"] = sc.sweep
            if sc.sweep_mode != "one_at_a_time":
                d["sweep_mode"] = sc.sweep_mode
        d["kind"] = sc.kind
        d["config"] = {"file": Path(path).name, "sha256": config_digest(path, sc.overrides)}
        if isinstance(sc, QueryScenario) and sc.problems is not None:
            ps = sc.problem_set
            d["problems"] = {
                "file": Path(sc.problems).name,
                "world": digest(ps.model_dump(mode="json", include={"robot", "world"}), 16),
                "list": [p.model_dump(mode="json") for p in ps.problems],
            }
        if isinstance(sc, QueryScenario):
            d["time_limit_s"] = sc.time_limit_s or spec.time_limit_s
            d.update(execute=spec.execute, settle_s=spec.settle_s, jerk_dt_s=spec.jerk_dt_s)
        out[sc.name] = d
    return out


def definitions(spec: CompareSpec) -> dict[str, Any]:
    """Planner and scenario definitions of a spec, as `compare.json` stores them for `--resume` to diff."""
    return {
        "planners": {p.id: planner_definition(p) for p in spec.planners},
        "scenarios": scenario_definitions(spec),
    }


def _case_definition(scenario: dict[str, Any], index: int | None, level: SweepLevel = UNSWEPT) -> dict[str, Any]:
    """A scenario's definition narrowed to one case: adding queries, raising `count` or adding sweep levels
    leaves the runs that were there before with their ids (a level's point is its whole sweep)."""
    d = {k: v for k, v in scenario.items() if k not in ("sweep", "sweep_mode")}
    if level.point:
        d["sweep"] = level.point
    if d.get("queries"):
        d["queries"] = [d["queries"][index or 0]]
    if d.get("random"):
        d["random"] = {k: v for k, v in d["random"].items() if k != "count"}
    if d.get("problems"):
        d["problems"] = {k: v for k, v in d["problems"].items() if k != "list"} | {
            "problem": d["problems"]["list"][index or 0]
        }
    d["case_index"] = index
    return d


def run_key(planner: str, case: str, seed: int) -> str:
    """The readable part of a run id, 'planner|case|seed=N': which cell of the sweep a run fills."""
    return f"{planner}|{case}|seed={seed}"


def run_id(planner: str, case: str, seed: int, definition: dict[str, Any] | None = None) -> str:
    """The unique, deterministic id of one run: 'planner|case|seed=N|hash', the hash over the full
    definition (planner block and label, scenario case, seed), so a changed block is a different run."""
    key = run_key(planner, case, seed)
    return key if definition is None else f"{key}|{digest(definition)}"


@dataclass(frozen=True)
class RunTask:
    """Everything a worker needs for one run; plain data, so it pickles to processes and Ray."""

    run_id: str
    planner_id: str
    planner: dict[str, Any]  # the PlannerBlock as a dict
    scenario: str
    case: str
    kind: Literal["query", "task"]
    seed: int
    config: str  # absolute path of the scene/task config
    overrides: tuple[str, ...] = ()
    problems: str | None = None  # absolute path of the problem set whose world the cell is
    query_index: int | None = None
    query: dict[str, Any] | None = None  # an explicit QuerySpec as a dict
    random: dict[str, Any] | None = None  # RandomQueries as a dict
    time_limit_s: float = 1.0
    execute: bool = True
    settle_s: float = 0.5
    jerk_dt_s: float = 1e-3
    unknown_fixtures: Literal["box", "ignore"] = "box"
    timeout_s: float = 3600.0  # stop the run (an error row) if it has not returned after this long
    sweep: dict[str, Any] | None = None  # the sweep level's point {key: value}; None without a sweep
    sweep_axes: tuple[str, ...] = ()  # the swept keys whose axis this level lies on

    @property
    def key(self) -> str:
        """'planner|case|seed=N' (the run id without its hash)."""
        return run_key(self.planner_id, self.case, self.seed)

    def random_seed(self) -> list[int]:
        """Seed sequence of a random query: independent per (scenario, seed, index), stable across processes."""
        return [int(self.seed) & 0xFFFFFFFF, zlib.crc32(self.scenario.encode()), int(self.query_index or 0)]


def default_run_timeout(kind: str, time_limit_s: float) -> float:
    """How long a run may take before it is stopped: a motion query plans within its time limit and then
    executes a few seconds of motion (60 s + 10 x the limit leaves room for a loaded machine); a task
    run simulates a whole sorting task (an hour)."""
    return 60.0 + 10.0 * time_limit_s if kind == "query" else 3600.0


def expand_runs(spec: CompareSpec, defs: dict[str, Any] | None = None) -> list[RunTask]:
    """The cross product planners x cases x seeds, in a fixed order (scenario, seed, case, planner; a
    problem set's problems with their own seeds in file order).

    `defs`: `definitions(spec)` when the caller has them already (they load every scenario's config)."""
    defs = definitions(spec) if defs is None else defs
    out: list[RunTask] = []
    for sc in spec.scenarios:
        for i, seed, level in spec.cases(sc):
            out += _case_runs(spec, sc, i, seed, defs, level)
    return out


def case_name(scenario: str, index: int | None, level: SweepLevel = UNSWEPT) -> str:
    """'scenario', 'scenario#3', 'scenario@camera.noise.scale=3', 'scenario@nominal#3'."""
    name = f"{scenario}@{level.label}" if level.label else scenario
    return name if index is None else f"{name}#{index}"


def _case_runs(
    spec: CompareSpec,
    sc: QueryScenario | TaskScenario,
    i: int | None,
    seed: int,
    defs: dict[str, Any],
    level: SweepLevel = UNSWEPT,
) -> list[RunTask]:
    """One run per planner of one case: a query (index i) or a task run (i None), with its seed, at one
    level of the scenario's sweep."""
    case = case_name(sc.name, i, level)
    case_def = _case_definition(defs["scenarios"][sc.name], i, level)
    out = []
    for p in spec.planners:
        rid = run_id(p.id, case, seed, {"planner": defs["planners"][p.id], "scenario": case_def, "seed": seed})
        common: dict[str, Any] = {
            "run_id": rid,
            "planner_id": p.id,
            "planner": p.block().model_dump(),
            "scenario": sc.name,
            "case": case,
            "seed": seed,
            "overrides": (*sc.overrides, *level.overrides()),
            "sweep": dict(level.point) if level.point else None,
            "sweep_axes": level.axes,
        }
        if isinstance(sc, TaskScenario):
            timeout = spec.run_timeout_s or default_run_timeout("task", 0.0)
            out.append(RunTask(kind="task", config=sc.task, timeout_s=timeout, **common))
            continue
        assert sc.scene is not None and i is not None
        problem = sc.problem_set.problems[i] if sc.problems is not None else None
        if problem is not None:
            query: dict[str, Any] | None = query_of_problem(problem)
        else:
            query = sc.queries[i].model_dump() if sc.queries else None
        limit = sc.time_limit_s or (problem.time_limit_s if problem is not None else spec.time_limit_s)
        out.append(
            RunTask(
                kind="query",
                config=sc.scene,
                problems=sc.problems,
                query_index=i,
                query=query,
                random=sc.random.model_dump() if sc.random is not None else None,
                time_limit_s=limit,
                execute=spec.execute,
                settle_s=spec.settle_s,
                jerk_dt_s=spec.jerk_dt_s,
                unknown_fixtures=sc.unknown_fixtures,
                timeout_s=spec.run_timeout_s or default_run_timeout("query", limit),
                **common,
            )
        )
    return out


def _flat(d: Any, prefix: str = "") -> dict[str, Any]:
    if isinstance(d, dict) and d:
        out: dict[str, Any] = {}
        for k, v in d.items():
            out.update(_flat(v, f"{prefix}.{k}" if prefix else str(k)))
        return out
    return {prefix: d}


def _short(v: Any, n: int = 60) -> str:
    text = repr(v)
    return text if len(text) <= n else text[: n - 3] + "..."


def describe_changes(old: dict[str, Any], new: dict[str, Any]) -> list[str]:
    """What differs between two `definitions()` for the planners and scenarios both have, one phrase
    each: "planner 'rrtconnect': params.range 1.0 -> 0.5". Added or removed ones are not changes."""
    out: list[str] = []
    for what in ("planners", "scenarios"):
        a, b = old.get(what) or {}, new.get(what) or {}
        for name in [n for n in b if n in a]:
            fa, fb = _flat(a[name]), _flat(b[name])
            keys = sorted(k for k in set(fa) | set(fb) if fa.get(k, "<unset>") != fb.get(k, "<unset>"))
            if keys:
                parts = []
                for k in keys:
                    if k == "config.sha256":
                        parts.append(f"the content of {fb.get('config.file', 'its config')}")
                    else:
                        parts.append(f"{k} {_short(fa.get(k, '<unset>'))} -> {_short(fb.get(k, '<unset>'))}")
                out.append(f"{what[:-1]} {name!r}: " + ", ".join(parts))
    return out


# ---- loading -------------------------------------------------------------------------------------
def _format(source: str, err: ValidationError) -> str:
    e = err.errors()[0]
    # drop the union tags pydantic puts into the location ('scenarios.0.query.x' -> 'scenarios.0.x')
    raw = e["loc"]
    loc = [str(p) for i, p in enumerate(raw) if not (p in ("query", "task") and i > 0 and isinstance(raw[i - 1], int))]
    where = ".".join(loc) or "(top level)"
    more = f" (and {len(err.errors()) - 1} more)" if len(err.errors()) > 1 else ""
    if e["type"] == "extra_forbidden":
        return f"{source}: unknown key {where!r}{more}.{unknown_key_hint(CompareSpec, raw)}".rstrip(".")
    msg = e["msg"].removeprefix("Value error, ")
    return f"{source}: {where}: {msg}{more}"


def _resolve_configs(spec: CompareSpec, base: Path, source: str) -> CompareSpec:
    scenarios = []
    for i, sc in enumerate(spec.scenarios):
        key = "task" if isinstance(sc, TaskScenario) else "scene"
        update: dict[str, Any] = {}
        ps = None
        if isinstance(sc, QueryScenario) and sc.problems is not None:
            ps, update["problems"] = _problem_set(sc.problems, base, f"{source}: scenarios.{i}.problems")
        ref = getattr(sc, key)
        where = base
        if ref is None:  # a problem set planned in the config it was exported from
            assert ps is not None
            ref = ps.source.get("config")
            where = Path(update["problems"]).parent
            if not isinstance(ref, str) or not ref:
                raise ConfigError(
                    f"{source}: scenarios.{i}: the problem set {update['problems']} names no twin config "
                    "(source.config); give `scene:` (the config whose robot, limits and collision settings plan it)"
                )
        try:  # a path relative to the comparison file, or the name of a shipped config
            p = find_config(ref, relative_to=where)
        except ConfigError as e:
            raise ConfigError(f"{source}: scenarios.{i}.{key}: {e}") from None
        update[key] = str(p.resolve())
        new = sc.model_copy(update=update)
        if isinstance(new, QueryScenario):
            new._problem_set = ps
        scenarios.append(new)
    return spec.model_copy(update={"scenarios": scenarios})


def _problem_set(ref: str, base: Path, where: str) -> tuple[ProblemSet, str]:
    """Load a scenario's problem set (a path relative to the comparison file, or `mbm:ur5/<scene>`:
    MotionBenchMaker's, `twin.problems.mbm`); ConfigError naming it."""
    try:
        if ref.startswith("mbm:"):
            path = mbm_problem_set(ref.removeprefix("mbm:"))
        else:
            path = Path(ref) if Path(ref).is_absolute() else base / ref
        return load_problem_set(path), str(path.resolve())
    except ConfigError as e:
        raise ConfigError(f"{where}: {e}") from None


def compare_spec_from_dict(
    data: dict[str, Any], *, source: str = "<dict>", base_dir: str | Path | None = None
) -> CompareSpec:
    """Validate a mapping into a CompareSpec; scene paths are resolved against `base_dir` (default: cwd),
    and a scene that is no file there names a shipped config ('robocup', 'warehouse.yaml').

    Raises ConfigError naming the dotted path of a bad or unknown key.
    """
    try:
        spec = CompareSpec.model_validate(data)
    except ValidationError as err:
        raise ConfigError(_format(source, err)) from None
    spec = _resolve_configs(spec, Path(base_dir) if base_dir is not None else Path.cwd(), source)
    _check_sweeps(spec, source)
    spec._source = source
    return spec


def _check_sweeps(spec: CompareSpec, source: str) -> None:
    """Load every sweep value, and every level, into its scenario's config: an unknown key (with the key
    meant) or a value the config rejects (with what it allows) is a ConfigError naming the scenario."""
    for i, sc in enumerate(spec.scenarios):
        if not sc.sweep:
            continue
        path = sc.task if isinstance(sc, TaskScenario) else sc.scene
        assert path is not None  # resolved on load
        where = f"{source}: scenarios.{i} ({sc.name})"
        try:
            base = load_config(path, sc.overrides)
        except ConfigError as e:
            raise ConfigError(f"{where}: {e}") from None
        keys = _flat(base.model_dump(mode="json"))
        for key, values in sc.sweep.items():
            for v in values:
                try:
                    load_config(path, [*sc.overrides, f"{key}={_yaml_text(v)}"])
                except ConfigError as e:
                    if not _is_config_key(key, keys):
                        close = difflib.get_close_matches(key, list(keys), n=1, cutoff=0.6)
                        hint = (
                            f" Did you mean {close[0]!r}?"
                            if close
                            else " Sweep keys are dotted config keys such as camera.noise.scale."
                        )
                        raise ConfigError(
                            f"{where}: sweep key {key!r} is not a key of {Path(path).name}.{hint}"
                        ) from None
                    raise ConfigError(f"{where}: sweep {key!r} value {_label_text(v)}: {e}") from None
        if len(sc.sweep) > 1:  # each value loads on its own; together they must too
            for level in sc.levels():
                try:
                    load_config(path, [*sc.overrides, *level.overrides()])
                except ConfigError as e:
                    raise ConfigError(f"{where}: sweep level {level.label}: {e}") from None


def _is_config_key(key: str, flat: dict[str, Any]) -> bool:
    """Whether `key` names a value or section of a loaded config (`flat`: its dotted leaves), or lies in a
    free-form mapping of it (a planner's `params`)."""
    if key in flat or any(k.startswith(key + ".") for k in flat):
        return True
    return any(key.startswith(k + ".") and v == {} for k, v in flat.items())


def load_compare_config(path: str | Path, overrides: Iterable[str] = ()) -> CompareSpec:
    """Load a comparison YAML (a path, or the name of a shipped one: 'compare-smoke'), following `extends`,
    apply `a.b=value` overrides, validate, and resolve the scenarios' config paths relative to the file
    (or to the shipped configs). Raises ConfigError."""
    p = find_config(path)
    data = read_yaml(p)
    for o in overrides:
        apply_override(data, o)
    return compare_spec_from_dict(data, source=str(p), base_dir=p.resolve().parent)
