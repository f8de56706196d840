"""Reading configs: YAML files into validated `Settings`, with one-line errors.

A config is named by a path or, for the configs twin ships, by name (`robocup`, `robocup.yaml`:
`find_config`). A file may name another with `extends: other.yaml` (a path relative to the file, or a
shipped config's name); the two are merged key by key, the extending file winning. `--set a.b=value`
overrides (parsed as YAML scalars) apply last. Unknown keys are rejected with the file and the dotted path
of the key. Every mistake is a ConfigError whose message is one line.

The loaded `Settings` remember the directories of the files they came from, so that relative paths in
them (URDFs) are found next to the config first and in twin's shipped data second (`Settings.resolve`).
"""

from __future__ import annotations

import difflib
import math
import re
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import UnionType
from typing import Annotated, Any, Union, get_args, get_origin

import yaml
from pydantic import BaseModel, Tag, ValidationError

from twin.config.schema import PlannerBlock, PlannerGroups, Settings
from twin.errors import ConfigError, UnknownNameError
from twin.messages import one_line, short_repr
from twin.registry import Kind, default_registry
from twin.resources import CONFIG_SUFFIXES, config_names, packaged_config

__all__ = [
    "apply_override",
    "blamed_source",
    "find_config",
    "format_validation",
    "load_config",
    "read_yaml",
    "settings_from_dict",
    "swap_planner",
    "unknown_key_hint",
    "with_planner",
]


def _merge(base: dict[str, Any], over: dict[str, Any]) -> dict[str, Any]:
    out = dict(base)
    for k, v in over.items():
        if isinstance(v, dict) and isinstance(out.get(k), dict):
            out[k] = _merge(out[k], v)
        else:
            out[k] = v
    return out


# A config is a handful of levels deep (perception.robocup.grasp.<key>.z_grasp_m; a detector's exclude boxes)
# and a few hundred values; far beyond that it is a mistake or an attack (YAML aliases can make a small
# file expand to millions of nodes, and pydantic would walk every one)
_MAX_DEPTH = 32
_MAX_NODES = 100_000
_MAX_INT = 2**63 - 1  # beyond int64 a seed or an id breaks numpy, PyBullet or OpenCV instead of failing here


def _dotted(loc: Iterable[object]) -> str:
    """'a.b.0.c' for a path of keys; a key that is not a plain printable word is shown as its repr."""
    parts = []
    for p in loc:
        text = str(p)
        parts.append(text if text and text.isprintable() and not any(c.isspace() for c in text) else short_repr(p, 40))
    return ".".join(parts)


def _check_tree(data: Any, source: str) -> None:
    """Reject what the models would accept but nothing downstream can use: NaN/inf, integers beyond int64,
    keys that are not text (a validator would meet an int where it expects a name), nesting deeper than
    _MAX_DEPTH, more than _MAX_NODES values (aliases counted every time they are used)."""
    nodes = 0
    stack: list[tuple[Any, tuple[object, ...]]] = [(data, ())]
    while stack:
        node, path = stack.pop()
        nodes += 1
        if nodes > _MAX_NODES:
            raise ConfigError(
                f"{source}: the config has more than {_MAX_NODES} values (YAML aliases count each time they are used)"
            )
        if len(path) > _MAX_DEPTH:
            raise ConfigError(f"{source}: {_dotted(path[:_MAX_DEPTH])}...: nested deeper than {_MAX_DEPTH} levels")
        if isinstance(node, bool):
            continue
        if isinstance(node, float) and not math.isfinite(node):
            raise ConfigError(f"{source}: {_dotted(path) or '(top level)'}: must be a finite number, got {node}")
        if isinstance(node, int) and abs(node) > _MAX_INT:
            raise ConfigError(
                f"{source}: {_dotted(path) or '(top level)'}: "
                f"integer {short_repr(node, 30)} is too large (at most 2**63-1)"
            )
        if isinstance(node, dict):
            for k in node:
                if not isinstance(k, str):  # every mapping of a config is keyed by names (YAML allows `1:`, `null:`)
                    raise ConfigError(
                        f"{source}: {_dotted(path) or '(top level)'}: key {short_repr(k, 30)} must be a name (text), "
                        f"got {type(k).__name__}"
                    )
            stack.extend((v, path + (k,)) for k, v in node.items())
        elif isinstance(node, (list, tuple)):
            stack.extend((v, path + (i,)) for i, v in enumerate(node))


def _yaml_error(path: Path, e: yaml.YAMLError, text: str) -> ConfigError:
    """One line for a YAML error: file, line and column, PyYAML's problem (its message spans several lines)."""
    mark = getattr(e, "problem_mark", None) or getattr(e, "context_mark", None)
    line = col = None
    if mark is not None:
        line, col = mark.line + 1, mark.column + 1
    problem = getattr(e, "problem", None)
    if isinstance(e, yaml.reader.ReaderError):  # a control character; no mark, a position in the text
        pos = int(e.position)
        line, col = text.count("\n", 0, pos) + 1, pos - (text.rfind("\n", 0, pos) + 1) + 1
        problem = (
            f"unacceptable character #x{e.character:04x} ({e.reason})" if isinstance(e.character, int) else e.reason
        )
    context = getattr(e, "context", None)
    what = f"{problem} ({context})" if problem and context else problem or context or e
    where = f" at line {line}, column {col}" if line is not None else ""
    return ConfigError(f"{path}: not valid YAML{where}: {one_line(what)}")


def _read_text(path: Path) -> str:
    """The file as text: UTF-8 (a BOM is allowed); a binary or otherwise encoded file is a ConfigError."""
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ConfigError(f"cannot read config {path}: {e.strerror or e}") from None
    if b"\x00" in raw:
        raise ConfigError(f"{path}: a binary file (it contains NUL bytes), not a YAML config")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as e:
        raise ConfigError(
            f"{path}: not UTF-8 text (byte 0x{raw[e.start]:02x} at offset {e.start}); save it as UTF-8"
        ) from None


def _is_config_name(ref: str) -> bool:
    """A bare name ('robocup') or file name ('robocup.yaml'): no directory part, no other suffix."""
    if not ref or "/" in ref or "\\" in ref or ref in (".", ".."):
        return False
    suffix = Path(ref).suffix
    return suffix == "" or suffix in CONFIG_SUFFIXES


def find_config(ref: str | Path, *, relative_to: str | Path | None = None) -> Path:
    """The config file `ref` names: a path (relative ones taken from `relative_to`, default the working
    directory) when that file exists, else the config twin ships under that name ('robocup',
    'robocup.yaml'). A path that exists is returned as given (joined to `relative_to`).

    Raises ConfigError (one line) when it is neither; the message lists the shipped configs' names.
    """
    text = str(ref)
    try:
        p = Path(ref)
        candidate = p if relative_to is None or p.is_absolute() else Path(relative_to) / p
        if candidate.is_file():
            return candidate
        where = candidate.resolve()
    except (OSError, ValueError, RuntimeError) as e:  # a NUL byte, a name too long, a symlink loop
        raise ConfigError(f"config file path {short_repr(text, 200)} is not usable: {one_line(e)}") from None
    if _is_config_name(text):
        shipped = packaged_config(text)
        if shipped is not None:
            return shipped
        names = config_names()
        stem = text[: -len(Path(text).suffix)] if Path(text).suffix else text
        close = difflib.get_close_matches(stem, names, n=1, cutoff=0.6)
        hint = f" Did you mean {close[0]!r}?" if close else ""
        raise ConfigError(
            one_line(
                f"config file not found: {short_repr(text, 100)} is neither a file (looked at {where}) "
                f"nor the name of a config twin ships.{hint} Shipped configs: {', '.join(names) or '(none)'}",
                600,
            )
        )
    raise ConfigError(one_line(f"config file not found: {where}", 600))


def read_yaml(path: str | Path, seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """The mapping of a YAML config (a path or a shipped config's name) with its `extends` chain merged
    in (not validated yet).

    Every problem with the file itself (missing, unreadable, binary, not UTF-8, not YAML, empty, not a
    mapping, an `extends` cycle) is a ConfigError with a one-line message naming the file.
    """
    return _read_chain(path, seen)[0]


def _read_chain(
    ref: str | Path, seen: tuple[Path, ...] = (), relative_to: Path | None = None
) -> tuple[dict[str, Any], tuple[Path, ...]]:
    """`read_yaml`, and the directories of the files read, the named one first, then those it extends."""
    found = find_config(ref, relative_to=relative_to)
    try:
        path = found.resolve()
    except (OSError, ValueError, RuntimeError) as e:
        raise ConfigError(f"config file path {short_repr(str(found), 200)} is not usable: {one_line(e)}") from None
    if path in seen:
        raise ConfigError(f"{path}: `extends` forms a cycle through {' -> '.join(map(str, seen))}")
    text = _read_text(path)
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as e:
        raise _yaml_error(path, e, text) from None
    except RecursionError:
        raise ConfigError(f"{path}: nested too deeply for the YAML parser") from None
    if data is None:
        raise ConfigError(f"{path}: the config is empty")
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: the top level must be a mapping of keys, got {type(data).__name__}")
    _check_tree(data, str(path))
    dirs: tuple[Path, ...] = (path.parent,)
    parent = data.pop("extends", None)
    if parent is not None:
        if not isinstance(parent, str) or not parent:
            raise ConfigError(f"{path}: `extends` must be a file path or a config name, got {short_repr(parent)}")
        try:
            base, base_dirs = _read_chain(parent, seen + (path,), relative_to=path.parent)
        except ConfigError as e:
            if str(e).startswith("config file not found"):
                raise ConfigError(f"{path}: extends: {e}") from None
            raise
        data = _merge(base, data)
        dirs += tuple(d for d in base_dirs if d not in dirs)
    return data, dirs


def swap_planner(
    data: dict[str, Any], group: str, block: PlannerBlock | Mapping[str, Any] | str, overrides: Iterable[str] = ()
) -> None:
    """Make `planners.<group>` of raw config `data` the block `block` (a planner's name, or a whole block with
    its params and retimer), in place: the one way a group's planner is swapped (`load_config(planners=)`
    for `--planner` and a comparison's task rows, `with_planner` for loaded settings). The config's block
    of that group belonged to the planner it named, so its params and retimer go; `overrides` applied
    after (`--set planners.<group>.params.KEY=VALUE`) give the new planner's, validated by its own model
    like any other. An override that names the group's planner too is a ConfigError (two answers to one
    question), as is a group that does not exist (with a did-you-mean)."""
    if group not in PlannerGroups.model_fields:
        close = difflib.get_close_matches(group, list(PlannerGroups.model_fields), n=1)
        hint = f" (did you mean {close[0]!r}?)" if close else ""
        raise ConfigError(f"no planner group {group!r}{hint}; the groups are {', '.join(PlannerGroups.model_fields)}")
    try:
        new = PlannerBlock(name=block) if isinstance(block, str) else PlannerBlock.model_validate(block)
    except ValidationError as err:
        raise ConfigError(format_validation(f"planners.{group}", err, PlannerBlock)) from None
    key = ("planners", group)
    for o in overrides:
        if _override_key(o) in (key, (*key, "name")):
            raise ConfigError(
                f"--planner {new.name} and --set {short_repr(o)} both choose the {group} planner; give one"
            )
    planners = data.get("planners")
    data["planners"] = {**(planners if isinstance(planners, dict) else {}), group: new.model_dump()}


def with_planner(settings: Settings, group: str, block: PlannerBlock | Mapping[str, Any] | str) -> Settings:
    """`settings` with the planner of `group` swapped for `block` (a name, or a whole block): `swap_planner`
    on loaded settings, as the library (`run_task(planner=)`) does it."""
    data: dict[str, Any] = {"planners": settings.planners.model_dump()}
    swap_planner(data, group, block)
    try:
        groups = PlannerGroups.model_validate(data["planners"])
    except ValidationError as err:
        raise ConfigError(format_validation("with_planner", err, PlannerGroups)) from None
    return settings.model_copy(update={"planners": groups})


def apply_override(data: dict[str, Any], override: str) -> None:
    """Apply one `key.path=value` override in place; the value is parsed as a YAML scalar (or flow
    collection), so `--set seed=3` gives an int and `--set x=[1,2]` a list; unparsable text stays a string."""
    if "=" not in override:
        raise ConfigError(f"override {short_repr(override)} must look like key.path=value")
    key, raw = override.split("=", 1)
    parts = [p.strip() for p in key.strip().split(".")]
    if not all(parts):
        raise ConfigError(f"override {short_repr(override)}: empty key in dotted path {short_repr(key)}")
    try:
        value = yaml.safe_load(raw)
    except yaml.YAMLError:
        value = raw
    except RecursionError:
        raise ConfigError(f"override {short_repr(override)}: the value is nested too deeply") from None
    node = data
    for i, p in enumerate(parts[:-1]):
        nxt = node.get(p)
        if nxt is None:
            nxt = node[p] = {}
        if not isinstance(nxt, dict):
            raise ConfigError(
                f"override {short_repr(override)}: {'.'.join(parts[: i + 1])!r} is a value, not a section"
            )
        node = nxt
    node[parts[-1]] = value


def _union_members(annotation: Any) -> dict[str, Any]:
    """tag -> model of a union of models (`Annotated[A, Tag('a')] | B`, pydantic's location names a member
    by its tag, else by its class name); {} for anything else."""
    if get_origin(annotation) is Annotated:
        return _union_members(get_args(annotation)[0])
    if get_origin(annotation) not in (Union, UnionType):
        return {}
    out: dict[str, Any] = {}
    for member in get_args(annotation):
        tag = None
        if get_origin(member) is Annotated:
            member, *meta = get_args(member)
            tag = next((m.tag for m in meta if isinstance(m, Tag)), None)
        if isinstance(member, type) and issubclass(member, BaseModel):
            out[tag or member.__name__] = member
    return out


def _walk(model: type[BaseModel], loc: Sequence[object]) -> type[BaseModel] | None:
    """The model class of the mapping at `loc` (None where it is not one of the models): through
    `X | None`, the items of `list[X]` and `dict[str, X]`, and tagged unions of models."""
    current: Any = model
    for part in loc:
        if isinstance(current, _Item):  # a list index or a mapping key: the item's model
            current = current.annotation
            continue
        members = _union_members(current)
        if len(members) > 1:  # the location names the member
            current = members.get(str(part))
            continue
        if not (isinstance(current, type) and issubclass(current, BaseModel)):
            return None
        field = current.model_fields.get(str(part))
        if field is None:
            return None
        ann = field.annotation
        members = _union_members(ann)
        if len(members) == 1:  # X | None
            ann = next(iter(members.values()))
        elif get_origin(ann) in (Union, UnionType):
            ann = next((a for a in get_args(ann) if a is not type(None)), ann)
        current = _Item(get_args(ann)[-1]) if get_origin(ann) in (list, dict) else ann
    return current if isinstance(current, type) and issubclass(current, BaseModel) else None


@dataclass(frozen=True)
class _Item:
    """In `_walk`: the next part of the location is a list index or mapping key of items of this type."""

    annotation: Any


def unknown_key_hint(model: type[BaseModel], loc: Sequence[object]) -> str:
    """' Did you mean 'x'? Allowed keys here: a, b, c' for an unknown key at `loc` of `model` ('' when
    the keys allowed there are not known)."""
    parent = _walk(model, loc[:-1])
    if parent is None:
        return ""
    allowed = [f.alias or name for name, f in parent.model_fields.items()]
    close = difflib.get_close_matches(str(loc[-1]), allowed, n=1, cutoff=0.6)
    hint = f" Did you mean {close[0]!r}?" if close else ""
    return f"{hint} Allowed keys here: {', '.join(allowed)}"


def format_validation(source: str, err: ValidationError, model: type[BaseModel] | None = None) -> str:
    """One line for a pydantic error: the dotted path of the first bad key and what is wrong with it; for
    an unknown key of `model`, the key probably meant and the keys allowed there."""
    errors = err.errors()
    e = errors[0]
    loc = _dotted(e["loc"]) or "(top level)"
    more = f" (and {len(errors) - 1} more)" if len(errors) > 1 else ""
    if e["type"] == "extra_forbidden":
        hint = unknown_key_hint(model, e["loc"]) if model is not None else ""
        return one_line(f"{source}: unknown key {loc!r}{more}.{hint}".rstrip("."), 700)
    scalar = isinstance(e.get("input"), (str, int, float)) and e["type"] != "missing"
    got = f" (got {short_repr(e['input'])})" if scalar else ""
    return one_line(f"{source}: {loc}: {e['msg']}{got}{more}", 500)


# cv2.aruco's predefined dictionaries that are not named DICT_<n>X<n>_<markers>, and their marker counts
_ARUCO_SIZES = {
    "DICT_ARUCO_ORIGINAL": 1024,
    "DICT_APRILTAG_16H5": 30,
    "DICT_APRILTAG_25H9": 35,
    "DICT_APRILTAG_36H10": 2320,
    "DICT_APRILTAG_36H11": 587,
    "DICT_ARUCO_MIP_36H12": 250,
}


def _check_settings(settings: Settings, source: str, overrides: Sequence[str] = ()) -> None:
    """Checks across what the models validate field by field, found by fuzzing (tests/test_config_fuzz.py):
    values the models accept but the world cannot use, caught here with the dotted key instead."""
    if settings.seed < 0:  # numpy's generators (object layout, noise) take non-negative seeds only
        where = blamed_source(source, ("seed",), overrides)
        raise ConfigError(f"{where}: seed: must be a non-negative integer, got {settings.seed}")
    name, marker = settings.aruco.dictionary, settings.aruco.id
    m = re.fullmatch(r"DICT_(\d)X\1_(\d+)", name)
    size = int(m.group(2)) if m else _ARUCO_SIZES.get(name.upper())
    if size is not None and marker >= size:  # OpenCV would fail when the marker image is drawn
        where = blamed_source(source, ("aruco",), overrides)
        raise ConfigError(f"{where}: aruco.id: {name} has markers 0..{size - 1}, got {marker}")


def settings_from_dict(
    data: dict[str, Any],
    *,
    source: str = "<dict>",
    config_dirs: Iterable[str | Path] = (),
    overrides: Sequence[str] = (),
) -> Settings:
    """Validate a plain mapping into Settings; raise ConfigError naming the dotted path on failure.

    `config_dirs`: where relative paths in it are looked up before twin's shipped data (`Settings.resolve`).
    `overrides`: the `key=value` overrides applied to `data`; an error at a key one of them set names it,
    not the file, as where the mistake is.
    """
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: the top level must be a mapping of keys, got {type(data).__name__}")
    _check_tree(data, source)
    try:
        settings = Settings.model_validate(data)
    except ValidationError as err:
        where = blamed_source(source, err.errors()[0]["loc"], overrides)
        raise ConfigError(format_validation(where, err, Settings)) from None
    except RecursionError:
        raise ConfigError(f"{source}: nested too deeply to validate") from None
    _check_settings(settings, source, overrides)
    dirs = tuple(Path(d) for d in config_dirs)
    return settings.with_config_dirs(dirs) if dirs else settings


def _override_key(override: str) -> tuple[str, ...]:
    """The dotted key an override sets, as `apply_override` reads it."""
    return tuple(p.strip() for p in override.split("=", 1)[0].strip().split("."))


def blamed_source(source: str, loc: Sequence[object], overrides: Sequence[str]) -> str:
    """Where a mistake at the dotted key `loc` was made: the last override that set that key, a section
    holding it or a key inside it ("override 'a.b=1' (on FILE)"), else the file `source`."""
    key = tuple(str(p) for p in loc)
    for o in reversed(overrides):
        k = _override_key(o)
        n = min(len(k), len(key))
        if k[:n] == key[:n]:
            return f"override {short_repr(o, 120)} (on {source})"
    return source


def _check_files(settings: Settings, source: str, overrides: Sequence[str] = ()) -> None:
    """Every URDF the config names must be a regular file: a directory, a device (/dev/zero never ends)
    or a missing file would otherwise fail deep inside the scene or the world, or not at all."""
    named = [("robot.urdf", settings.robot.urdf)] + [
        (f"world.fixtures.{i}.urdf", f.urdf) for i, f in enumerate(settings.world.fixtures)
    ]
    for where, name in named:
        source_of = blamed_source(source, where.split("."), overrides)
        try:
            resolved = settings.resolve(name)
            ok = resolved.is_file()
        except (OSError, ValueError) as e:  # an embedded NUL byte, a name too long for the system
            raise ConfigError(f"{source_of}: {where}: unusable path {short_repr(name)} ({one_line(e)})") from None
        if not ok:
            what = "is not a file" if resolved.exists() else "not found"
            raise ConfigError(
                f"{source_of}: {where}: {short_repr(name)} {what} (resolved to {short_repr(str(resolved), 200)})"
            )


def load_config(
    path: str | Path, overrides: Iterable[str] = (), *, planners: Mapping[str, PlannerBlock | str] | None = None
) -> Settings:
    """Load a YAML config (a path, or the name of a config twin ships: 'robocup'), following `extends`,
    swap the planner blocks of `planners` (group -> a name or a block: `swap_planner`), apply `a.b=value`
    overrides, validate.

    Raises ConfigError, with one line naming the file and the dotted key, for a missing, unreadable,
    binary, non-UTF-8, empty or invalid YAML file, an unknown key, a bad value, or a URDF that is not a file.
    """
    p = find_config(path)
    data, dirs = _read_chain(p)
    overrides = list(overrides)
    for group, block in (planners or {}).items():
        swap_planner(data, group, block, overrides)
    for o in overrides:
        apply_override(data, o)
    settings = settings_from_dict(data, source=str(p), config_dirs=dirs, overrides=overrides)
    _check_files(settings, str(p), overrides)
    _check_task(settings, blamed_source(str(p), ("task", "kind"), overrides))
    return settings


def _check_task(settings: Settings, source: str) -> None:
    """`task.kind` must name a registered task plugin (`twin planners` lists them): one line if not."""
    try:
        default_registry().entry(settings.task.kind, (Kind.TASK,))
    except UnknownNameError as e:
        raise ConfigError(f"{source}: task.kind: {e}") from None
