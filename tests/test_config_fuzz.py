"""Malformed configs, fuzzed (issue 12): whatever a config file holds, loading it, building its planning
scene, its planners and its world either works or fails with a TwinError whose message is ONE line.

Any other exception (a traceback for the user) or a message over several lines is a bug in twin, not in the
config. The cases are mutations of configs/robocup.yaml and configs/warehouse.yaml (dropped keys, wrong
types, negative / zero / NaN / huge numbers, unknown keys, bad planner names and parameters, bad fixture
URDF paths, bad object lists, deep nesting) and damaged files (random bytes, truncation, other encodings).
Hypothesis runs derandomized, so every CI run tries the same cases. `bench/bench_config_fuzz.py` runs
the same generator over more cases and counts the outcomes.
"""

from __future__ import annotations

import copy
import math
import tempfile
import traceback
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from twin.config import Settings
from twin.errors import TwinError

ROOT = Path(__file__).resolve().parent.parent
SCENES = ("robocup", "warehouse")

__all__ = ["BASES", "Outcome", "config_files", "run_config"]


# ---- what happens to one config file -----------------------------------------------------------------
@dataclass(frozen=True)
class Outcome:
    """accepted (every stage worked), rejected (a TwinError with a one-line message) or failed (a bug)."""

    kind: str
    stage: str = ""
    message: str = ""


def _stage(name: str, fn: Callable[[], Any]) -> tuple[Any, Outcome | None]:
    try:
        return fn(), None
    except TwinError as e:
        msg = str(e)
        if len(msg.splitlines()) != 1 or "\n" in msg or "\r" in msg:
            return None, Outcome("failed", name, f"{type(e).__name__} over several lines (or empty): {msg!r}")
        return None, Outcome("rejected", name, f"{type(e).__name__}: {msg}")
    except Exception as e:  # noqa: BLE001 - any other exception is what this test looks for
        return None, Outcome("failed", name, "".join(traceback.format_exception(e)).strip())


def run_config(path: Path, *, world: bool = True) -> Outcome:
    """Load `path`, then build the planning scene, every planner (config blocks and the default stage
    planners) and, with `world`, the PyBullet world; the first failure, else the first rejection."""
    from twin.collision import PlanningScene
    from twin.config import STAGE_GROUPS, load_config
    from twin.planning import make_context, make_planner
    from twin.world import World

    loaded, out = _stage("load", lambda: load_config(path))
    if out is not None:
        return out
    s: Settings = loaded
    outcomes: list[Outcome | None] = [_stage("scene", lambda: PlanningScene.from_settings(s))[1]]
    context, out = _stage("context", lambda: make_context(s))
    outcomes.append(out)
    if context is not None:
        blocks = {g: s.planners.block(g) for g in sorted(set(STAGE_GROUPS.values()))}
        blocks.update(s.planners.given())
        for group, block in sorted(blocks.items()):
            outcomes.append(_stage(f"planner {group}", lambda b=block: make_planner(b, context))[1])
    if world:

        def build() -> None:
            with World(s, s.seed, renderer="tiny"):
                pass

        outcomes.append(_stage("world", build)[1])
    found = [o for o in outcomes if o is not None]
    for kind in ("failed", "rejected"):
        for o in found:
            if o.kind == kind:
                return o
    return Outcome("accepted")


# ---- the generator -----------------------------------------------------------------------------------------
def _full(name: str) -> dict[str, Any]:
    """The shipped config with every default spelled out, so that mutations reach every key."""
    from twin.config import load_config

    return load_config(ROOT / "configs" / f"{name}.yaml").model_dump(mode="json", by_alias=True)


BASES: dict[str, dict[str, Any]] = {name: _full(name) for name in SCENES}
SHIPPED: dict[str, dict[str, Any]] = {
    name: yaml.safe_load((ROOT / "configs" / f"{name}.yaml").read_text()) for name in SCENES
}


def _paths(node: Any, max_depth: int = 12) -> list[tuple[Any, ...]]:
    """Every key path of `node` (dict keys and list indices), down to `max_depth` levels."""
    out: list[tuple[Any, ...]] = []
    stack: list[tuple[Any, tuple[Any, ...]]] = [(node, ())]
    while stack:
        cur, prefix = stack.pop()
        if len(prefix) >= max_depth:
            continue
        items = cur.items() if isinstance(cur, dict) else enumerate(cur) if isinstance(cur, list) else ()
        for k, v in items:
            out.append(prefix + (k,))
            stack.append((v, prefix + (k,)))
    return sorted(out, key=repr)


def _get(node: Any, path: tuple[Any, ...]) -> Any:
    for p in path:
        node = node[p]
    return node


def _set(node: Any, path: tuple[Any, ...], value: Any) -> None:
    _get(node, path[:-1])[path[-1]] = value


def _drop(node: Any, path: tuple[Any, ...]) -> None:
    parent = _get(node, path[:-1])
    del parent[path[-1]]


def _nested(depth: int, as_list: bool) -> Any:
    v: Any = 1.0
    for _ in range(depth):
        v = [v] if as_list else {"a": v}
    return v


EDGES = [-1, 0, -0.5, 0.5, 1, 2, 1e-300, 1e300, 2**31, 2**63 - 1, -(2**63 - 1), 1e6]
NUMBERS = [
    0,
    -1,
    -0.0,
    1e-300,
    -1e9,
    1e9,
    1e308,
    -1e308,
    2**63,
    -(2**63),
    2**64 + 1,
    10**30,
    math.nan,
    math.inf,
    -math.inf,
    0.5,
    3,
]
ODD = [
    None,
    "",
    " ",
    "x",
    "a\nb",
    "\x85\u2028",
    "1,2,3",
    "nan",
    "-inf",
    True,
    False,
    [],
    {},
    [1, 2],
    [1, 2, 3, 4, 5, 6, 7],
    {"a": 1},
    [[1, 2], [3]],
    "🤖",
    "../../../../etc/passwd",
    "\u0000",
]
URDFS = [
    "",
    "nope.urdf",
    "urdf",
    "urdf/",
    "/",
    ".",
    "configs/robocup.yaml",
    "README.md",
    "urdf/table.urdf ",
    "/dev/null",
    "/dev/zero",
    "/proc/self/status",
    "urdf/objects",
    "urdf/ur5e.urdf",
    "urdf/bin_blue.urdf",
    "a" * 300,
    "x/" * 200,
    "urdf/table.urdf\u0000",
    "C:\\table.urdf",
    "~/table.urdf",
    3,
    None,
    ["urdf/table.urdf"],
]
CLASSES = ["bottle", "can", "spam", "cube", "marker", "warehouse_cube", "obstacle", "Bottle", "", "robot", 1, None]
COLORS = ["red", "blue", "green", "black", "yellow", "purple", "", "#ff0000", None, 3, "RED"]
COUNTS = [-1, 0, 1, 2, 5, 50, 51, 1000, "3", 2.5, None, True, math.nan]
GROUPS = ["movej", "movel", "transfer", "extra", "", "a.b"]
# mutation operators, weighted: plausible changes (numbers within a few times their value, planner blocks)
# reach the scene, planner and world stages; the rest mostly stop at validation
OPS = (
    ["plausible"] * 4
    + ["edge"] * 3
    + ["planner"] * 3
    + ["fixture", "objects", "region"] * 2
    + ["drop", "set", "numeric", "retype", "unknown", "deep"]
)


def _registered() -> list[str]:
    from twin.registry import default_registry

    return default_registry().names()


def _params_of(name: str) -> list[str]:
    from twin.registry import default_registry

    try:
        cls = default_registry().entry(name).load()
    except TwinError:
        return []
    model = getattr(cls, "Params", None)
    return list(model.model_fields) if model is not None else []


NAMES = _registered()
PLANNER_NAMES = NAMES + ["ompl.rrtconect", "ruckig", "nope", "", "OMPL.RRTCONNECT", "ompl.", "a\nb", 7, None]
RETIMERS = ["toppra", "ruckig", "toppr", "ruckig.movej", "", None, 1]


def scalars() -> st.SearchStrategy[Any]:
    return st.one_of(
        st.sampled_from(NUMBERS),
        st.sampled_from(ODD),
        st.integers(min_value=-(2**70), max_value=2**70),
        st.floats(allow_nan=True, allow_infinity=True),
        st.text(max_size=12),
        st.booleans(),
    )


def values() -> st.SearchStrategy[Any]:
    return st.recursive(
        scalars(),
        lambda inner: st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=6), inner, max_size=3)),
        max_leaves=8,
    )


@st.composite
def planner_blocks(draw: st.DrawFn) -> Any:
    name = draw(
        st.sampled_from(
            PLANNER_NAMES + [n for n in NAMES if n.startswith(("ompl.", "ruckig", "toppra", "nmpc", "seed."))]
        )
    )
    keys = _params_of(name) if isinstance(name, str) else []
    params: dict[Any, Any] = {}
    for _ in range(draw(st.integers(0, 3))):
        key = draw(st.sampled_from(keys + ["nope", "Range", ""])) if keys else draw(st.sampled_from(["range", "x"]))
        params[key] = draw(
            st.one_of(
                st.sampled_from([0.1, 0.5, 1, 2, 10, 50, True, False, "full", "compact", "toppra", "ruckig"]),
                scalars(),
                values(),
            )
        )
    block: dict[str, Any] = {"name": name}
    if params or draw(st.booleans()):
        block["params"] = draw(st.sampled_from([params, params, params, [1], "x", None]))
    if draw(st.integers(0, 4)) == 0:
        block["retimer"] = draw(st.sampled_from(RETIMERS))
        if draw(st.booleans()):
            block["retimer_params"] = draw(
                st.one_of(
                    st.just({}),
                    st.dictionaries(st.sampled_from(["x", "grid_points", "gridpoints"]), scalars(), max_size=2),
                )
            )
    if draw(st.integers(0, 6)) == 0:
        block[draw(st.sampled_from(["nme", "param", "extra"]))] = 1
    return draw(st.sampled_from([block, block, block, block, name, [block], None]))


@st.composite
def object_items(draw: st.DrawFn) -> Any:
    n = draw(st.sampled_from([0, 1, 2, 4, 8, 60]))
    items = []
    for _ in range(n):
        item: dict[str, Any] = {"class": draw(st.sampled_from(CLASSES))}
        if draw(st.booleans()):
            item["color"] = draw(st.sampled_from(COLORS))
        if draw(st.booleans()):
            item["count"] = draw(st.sampled_from(COUNTS))
        if draw(st.integers(0, 8)) == 0:
            item[draw(st.sampled_from(["size", "cls", "colour"]))] = draw(scalars())
        items.append(item)
    return draw(st.sampled_from([items] * 6 + [{"class": "can"}, "can", None]))


@st.composite
def mutated(draw: st.DrawFn) -> dict[str, Any]:
    """A config mapping: a shipped config (as written, or with every default spelled out) after 1-4 mutations."""
    scene = draw(st.sampled_from(SCENES))
    data = copy.deepcopy(draw(st.sampled_from([BASES[scene], SHIPPED[scene]])))
    for _ in range(draw(st.sampled_from([1, 1, 1, 2, 2, 3, 4]))):
        paths = _paths(data)
        op = draw(st.sampled_from(OPS))
        if op == "edge":  # one number at a boundary, everything else valid: reaches the later stages
            numeric = [
                p for p in paths if isinstance(_get(data, p), (int, float)) and not isinstance(_get(data, p), bool)
            ]
            if numeric:
                _set(data, draw(st.sampled_from(numeric)), draw(st.sampled_from(EDGES)))
        elif op == "plausible":  # a finite number scaled near its value (an earlier op may have left a nan)
            numeric = [
                p
                for p in paths
                if isinstance(_get(data, p), (int, float))
                and not isinstance(_get(data, p), bool)
                and math.isfinite(_get(data, p))
            ]
            if numeric:
                path = draw(st.sampled_from(numeric))
                old = _get(data, path)
                sign = -1.0 if old < 0 else 1.0 if old > 0 else draw(st.sampled_from([-1.0, 1.0]))
                new = sign * draw(st.floats(0.0, max(abs(float(old)), 0.1) * 3))
                _set(data, path, int(new) if isinstance(old, int) else new)
        elif op in ("drop", "set", "retype", "numeric") and paths:
            path = draw(st.sampled_from(paths))
            if op == "drop":
                _drop(data, path)
            elif op == "set":
                _set(data, path, draw(values()))
            elif op == "numeric":
                old = _get(data, path)
                base = old if isinstance(old, (int, float)) and not isinstance(old, bool) else 1.0
                _set(data, path, draw(st.sampled_from(NUMBERS + [-base, base * 1e6, base + 1e-9, base * 1e-9])))
            else:
                old = _get(data, path)
                text = str(old) if not isinstance(old, (dict, list)) else type(old).__name__
                _set(data, path, draw(st.sampled_from([text, [old], {"value": old}, None, old is None])))
        elif op == "unknown":
            sections = [()] + [p for p in paths if isinstance(_get(data, p), dict)]
            where = _get(data, draw(st.sampled_from(sections)))
            where[draw(st.sampled_from(["typo", "nmae", "Name", "", "a.b", "a\nb", 1, 2.5, True]))] = draw(values())
        elif op == "planner":
            planners = data.setdefault("planners", {})
            if not isinstance(planners, dict):
                data["planners"] = planners = {}
            planners[draw(st.sampled_from(GROUPS))] = draw(planner_blocks())
        elif op == "fixture":
            world = data.setdefault("world", {})
            if not isinstance(world, dict):
                continue
            fixtures = world.get("fixtures")
            if not isinstance(fixtures, list) or not fixtures or draw(st.integers(0, 3)) == 0:
                world["fixtures"] = fixtures = [{"name": "table", "urdf": "urdf/table.urdf"}]
            i = draw(st.integers(0, len(fixtures)))
            fx = {
                "name": draw(st.sampled_from(["table", "bin_x", "aruco_plate", "", "robot"])),
                "urdf": "urdf/table.urdf",
            }
            if i == len(fixtures):
                fixtures.append(fx)
            elif not isinstance(fixtures[i], dict):
                fixtures[i] = fx
            field = draw(st.sampled_from(["urdf", "urdf", "urdf", "position", "rpy", "name", "known"]))
            value = (
                draw(st.sampled_from(URDFS))
                if field == "urdf"
                else draw(st.one_of(scalars(), st.lists(scalars(), max_size=4)))
            )
            fixtures[min(i, len(fixtures) - 1)][field] = value
        elif op == "objects":
            world = data.setdefault("world", {})
            if not isinstance(world, dict):
                continue
            objects = world.setdefault("objects", {})
            if isinstance(objects, dict):
                objects["items"] = draw(object_items())
        elif op == "deep":
            depth = draw(st.sampled_from([5, 20, 40, 200, 2000]))
            target = draw(st.sampled_from(paths)) if paths else ("deep",)
            _set(data, target, _nested(depth, draw(st.booleans())))
        elif op == "region":
            world = data.setdefault("world", {})
            if not isinstance(world, dict):
                continue
            objects = world.setdefault("objects", {})
            if isinstance(objects, dict):
                key = draw(st.sampled_from(["region_x", "region_y"]))
                objects[key] = draw(
                    st.sampled_from(
                        [
                            [0.0, 0.0],
                            [1.0, -1.0],
                            [-0.5, -0.499],
                            [-1e9, 1e9],
                            [-100.0, 100.0],
                            [0.2],
                            [-0.6, -0.3, 0.1],
                        ]
                    )
                )
                if draw(st.booleans()):
                    objects["min_gap_m"] = draw(st.sampled_from([0.0, 0.5, 10.0, 1e6]))
    return data


def _dump(data: Any, **kw: Any) -> str:
    try:
        return yaml.safe_dump(data, allow_unicode=True, sort_keys=False, **kw)
    except RecursionError:
        return yaml.safe_dump({"deep": "too deep to write"})


@st.composite
def config_files(draw: st.DrawFn) -> bytes:
    """The bytes of a config file: a mutated mapping written as YAML, maybe damaged afterwards."""
    data = draw(mutated())
    text = _dump(data)
    how = draw(
        st.sampled_from(
            ["as-is"] * 12 + ["truncate", "insert", "latin-1", "utf-16", "bom", "binary", "empty", "tabs", "flow"]
        )
    )
    raw = text.encode()
    if how == "truncate":
        return raw[: draw(st.integers(0, len(raw)))]
    if how == "insert":
        at = draw(st.integers(0, len(raw)))
        return raw[:at] + draw(st.binary(min_size=1, max_size=8)) + raw[at:]
    if how == "latin-1":
        return (
            text.replace("name: ", "name: caf\u00e9", 1) if "name: " in text else text + "name: caf\u00e9\n"
        ).encode("latin-1", "replace")
    if how == "utf-16":
        return text.encode("utf-16")
    if how == "bom":
        return b"\xef\xbb\xbf" + raw
    if how == "binary":
        return draw(st.binary(max_size=200))
    if how == "empty":
        return draw(st.sampled_from([b"", b"\n", b"# comment\n", b"---\n", b"~\n", b"null\n", b"   \n"]))
    if how == "tabs":
        return raw.replace(b"  ", b"\t", 3)
    if how == "flow":
        return _dump(data, default_flow_style=True, width=10_000).encode()
    return raw


# ---- the tests ---------------------------------------------------------------------------------------------
FUZZ = settings(
    max_examples=400,
    derandomize=True,
    deadline=None,
    database=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
)


def _check(content: bytes, *, world: bool = True) -> Outcome:
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.yaml"
        path.write_bytes(content)
        out = run_config(path, world=world)
    assert out.kind != "failed", f"stage {out.stage}: {out.message}\n--- config ---\n{content[:3000]!r}"
    return out


@FUZZ
@given(config_files())
def test_malformed_configs_are_accepted_or_rejected_in_one_line(content: bytes) -> None:
    _check(content)


@settings(FUZZ, max_examples=120)
@given(
    st.builds(lambda d: _dump(d).encode(), mutated()),
    st.sampled_from(
        [
            "robot.max_joint_vel",
            "seed",
            "world.objects.items",
            "planners.transfer",
            "camera.position",
            "x.y.z",
            "world.fixtures",
        ]
    ),
    values(),
)
def test_overrides_are_accepted_or_rejected_in_one_line(content: bytes, key: str, value: Any) -> None:
    """`--set key=value` on a mutated config: the value is any YAML a user could type."""
    from twin.config import load_config

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "fuzz.yaml"
        path.write_bytes(content)
        text = _dump(value).strip().replace("\n...", "")
        _, out = _stage("load", lambda: load_config(path, [f"{key}={text}"]))
    assert out is None or out.kind == "rejected", f"{out.message}\n--- override --- {key}={text!r}"


def _bomb(levels: int = 9) -> str:
    """A 'billion laughs' YAML: each level's list names the previous one nine times (9**levels values)."""
    lines = ["l0: &l0 [1, 1, 1, 1, 1, 1, 1, 1, 1]"]
    lines += [f"l{i}: &l{i} [{', '.join([f'*l{i - 1}'] * 9)}]" for i in range(1, levels)]
    return "\n".join(lines) + f"\nworld: {{objects: {{items: *l{levels - 1}}}}}\n"


# cases the fuzzing found (or that it reaches too rarely), kept as regressions: (text after `extends`, stage
# that rejects it, words of the message)
EDGE_CASES = [
    ("seed: -1", "load", "seed"),
    ("aruco: {id: 50}", "load", "aruco.id"),
    ("aruco: {id: 2147483648}", "load", "aruco.id"),
    ("world: {fixtures: [{name: table, urdf: .}]}", "load", "world.fixtures.0.urdf"),
    ("world: {fixtures: [{name: table, urdf: /dev/zero}]}", "load", "not a file"),
    ('world: {fixtures: [{name: table, urdf: "urdf/table.urdf\\0"}]}', "load", "world.fixtures.0.urdf"),
    ("robot: {urdf: urdf}", "load", "robot.urdf"),
    ("seed: 100000000000000000000", "load", "too large"),
    ("robot: {max_joint_vel: .inf}", "load", "finite"),
    ("camera: {position: [.nan, 0, 0]}", "load", "camera.position.0"),
    ("planners: {transfer: {name: ompl.rrtconnect, params: {range: .nan}}}", "load", "finite"),
    ("planners: {transfer: {name: ompl.rrtconnect, params: {range: [[[[[[1]]]]]]}}}", "planner transfer", "range"),
    ("planners: {transfer: {name: ompl.lazyprmstar}}", "planner transfer", "ompl.lazyprmstar"),
    ('planners: {transfer: {name: "ompl.rrt\\nconnect"}}', "planner transfer", "not registered"),
    ("world: {objects: {items: [{class: cube, color: mauve}]}}", "world", "mauve"),
    ("perception: {robocup: {grasp: {1: {z_grasp_m: 0.1, w_grip_m: 0.05}}}}", "load", "perception.robocup.grasp"),
    ("task: {robocup: {bins: {null: bin_green}}}", "load", "task.robocup.bins"),
    ("a: &a [*a]", "load", "nested deeper"),
    ("world: " + "[" * 3000 + "]" * 3000, "load", "nested too deeply"),
]


def test_edge_cases_are_rejected_in_one_line_by_the_right_stage(tmp_path: Path) -> None:
    from twin.registry import default_registry

    lazyprm_missing = not default_registry().entry("ompl.lazyprmstar").availability()
    for text, stage, words in EDGE_CASES + [(_bomb(), "load", "more than")]:
        if "lazyprmstar" in text and not lazyprm_missing:
            continue
        cfg = tmp_path / "edge.yaml"
        cfg.write_text(f"extends: {ROOT / 'configs' / 'robocup.yaml'}\n{text}\n")
        out = run_config(cfg)
        assert (out.kind, out.stage) == ("rejected", stage) and words in out.message, (text[:80], out)


def test_the_shipped_configs_are_accepted() -> None:
    for name in SCENES:
        assert run_config(ROOT / "configs" / f"{name}.yaml") == Outcome("accepted")
