"""The plugin registry: every planner, retimer, detector and task by dotted name, loaded lazily.

`plugin_manager()` builds a fresh pluggy manager (built-ins and third-party plugins both come from the
entry-point group `twin`); `Registry.from_plugin_manager(pm)` asks every plugin to register its names.
`default_registry()` caches the one built from installed entry points.

Whether a name can be created here is a question an entry answers without creating anything
(`Entry.availability()`): it imports the module and the class, then asks the class's optional
`unavailable_reason()` classmethod (the OMPL plugin uses it for planners its installed bindings lack).
`Registry.create` applies the same check before constructing, so every plugin gets it.
"""

from __future__ import annotations

import enum
import importlib
from collections.abc import Iterable
from dataclasses import dataclass
from functools import lru_cache
from typing import TYPE_CHECKING, Any

import pluggy
from pydantic import BaseModel, ValidationError

from twin.errors import ConfigError, DependencyMissing, DuplicateNameError, PluginError, TwinError, UnknownNameError
from twin.hookspecs import TwinSpec
from twin.messages import one_line, short_repr
from twin.timing import stage

if TYPE_CHECKING:
    from twin.config import Settings
    from twin.robot import Robot
    from twin.robot.kinematics import URArm

__all__ = ["HOOKS", "Availability", "Entry", "Kind", "PluginContext", "Registry", "default_registry", "plugin_manager"]

HOOKS = ("twin_register_planners", "twin_register_retimers", "twin_register_detectors", "twin_register_tasks")


class Kind(enum.Enum):
    """What a registered name is; the value is what `twin planners` prints."""

    PLANNER = "one-shot planner"
    RECEDING_HORIZON = "receding-horizon planner"
    RETIMER = "retimer"
    DETECTOR = "detector"
    TASK = "task"


_PLANNER_KINDS = (Kind.PLANNER, Kind.RECEDING_HORIZON)


@dataclass(frozen=True)
class Availability:
    """Whether a registered name can be created in this installation, and if not, why (one line)."""

    available: bool
    reason: str = ""

    def __bool__(self) -> bool:
        return self.available


@dataclass(frozen=True)
class Entry:
    """One registered name: what it is, where its class lives, who provides it."""

    name: str
    kind: Kind
    target: str | type
    provider: str
    description: str = ""
    extra: str | None = None  # the pip extra that installs its backend, named in DependencyMissing

    def load(self) -> type:
        """The plugin class; imports its module now (and only now)."""
        if not isinstance(self.target, str):
            return self.target
        module, _, attr = self.target.partition(":")
        try:
            with stage("imports"):
                mod = importlib.import_module(module)
        except ImportError as e:
            hint = f" Install it with `pip install 'twin[{self.extra}]'`." if self.extra else ""
            raise DependencyMissing(
                f"{self.kind.value} {self.name!r} needs {e.name or module!r}, which is not installed.{hint}"
            ) from e
        try:
            return getattr(mod, attr)
        except AttributeError:
            raise TwinError(f"{self.name!r} points at {self.target!r}, but {module} has no {attr!r}") from None

    def availability(self) -> Availability:
        """Can this name be created here? Imports its module and class (never instantiates it) and asks the
        class's optional `unavailable_reason()` classmethod (None: usable; else why not), so `twin planners`
        can tell a registered name from a usable one."""
        try:
            reason = _unavailable_reason(self.load())
        except TwinError as e:
            reason = str(e)
        except Exception as e:  # noqa: BLE001 - a broken third-party plugin must not break the listing
            reason = f"importing {self.target!r} raised {type(e).__name__}: {e}"
        return Availability(True) if reason is None else Availability(False, one_line(reason, 500))


def _unavailable_reason(cls: type) -> str | None:
    """The plugin class's own answer (its optional classmethod `unavailable_reason() -> str | None`)."""
    check = getattr(cls, "unavailable_reason", None)
    if check is None:
        return None
    try:
        reason = check()
    except TwinError as e:
        return str(e)
    return None if reason is None else str(reason)


@dataclass(frozen=True)
class PluginContext:
    """What a plugin gets besides its parameters: the settings, the robot (built once per run from
    `settings.robot`: `twin.robot.Robot`) and the registry."""

    settings: Settings
    robot: Robot
    registry: Registry

    @property
    def kinematics(self) -> URArm:
        """The robot's arm (DH kinematics, joint limits, IK): `robot.arm`."""
        return self.robot.arm


def validate_params(entry: Entry, cls: type, params: dict[str, Any] | BaseModel | None) -> Any:
    """Validate `params` with the plugin's own `Params` model (if it has one); ConfigError names the key."""
    model = getattr(cls, "Params", None)
    params = params or {}
    if not isinstance(params, (dict, BaseModel)):
        raise ConfigError(f"{entry.name}: parameters must be a mapping of names to values, got {type(params).__name__}")
    if model is None:
        if params:
            names = ", ".join(sorted(map(str, dict(params))))
            raise ConfigError(one_line(f"{entry.kind.value} {entry.name!r} takes no parameters, got: {names}", 500))
        return None
    if isinstance(params, model):
        return params
    try:
        return model.model_validate(dict(params))
    except ValidationError as err:
        e = err.errors()[0]
        key = ".".join(str(p) for p in e["loc"]) or "(params)"
        allowed = ", ".join(model.model_fields)
        if e["type"] == "extra_forbidden":
            raise ConfigError(one_line(f"{entry.name}: unknown parameter {key!r}; allowed: {allowed}", 2000)) from None
        got = f" (got {short_repr(e['input'])})" if "input" in e else ""
        raise ConfigError(one_line(f"{entry.name}: parameter {key!r}: {e['msg']}{got}", 500)) from None
    except RecursionError:
        raise ConfigError(f"{entry.name}: parameters nested too deeply") from None


class Registry:
    """Names -> lazily loaded plugin classes. Plugins call `add_planner`, `add_retimer`, `add_detector`,
    `add_task`."""

    def __init__(self) -> None:
        self._entries: dict[str, Entry] = {}
        self._provider = "(direct)"

    # ---- registration (called from hooks) ------------------------------------------------------
    def add(
        self, kind: Kind, name: str, target: str | type, *, description: str = "", extra: str | None = None
    ) -> None:
        if not name or name != name.strip() or name.lower() != name:
            raise TwinError(f"plugin names are lower-case dotted words, got {name!r}")
        if name in self._entries:
            old = self._entries[name]
            raise DuplicateNameError(f"{name!r} is registered twice: by {old.provider} and by {self._provider}")
        if isinstance(target, str) and ":" not in target:
            raise TwinError(f"{name!r}: target must be 'module:Class', got {target!r}")
        self._entries[name] = Entry(name, kind, target, self._provider, description, extra)

    def add_planner(
        self,
        name: str,
        target: str | type,
        *,
        receding_horizon: bool = False,
        description: str = "",
        extra: str | None = None,
    ) -> None:
        """Register a planner: one-shot (`plan`) or receding-horizon (`reset`/`step`)."""
        self.add(
            Kind.RECEDING_HORIZON if receding_horizon else Kind.PLANNER,
            name,
            target,
            description=description,
            extra=extra,
        )

    def add_retimer(self, name: str, target: str | type, *, description: str = "", extra: str | None = None) -> None:
        self.add(Kind.RETIMER, name, target, description=description, extra=extra)

    def add_detector(self, name: str, target: str | type, *, description: str = "", extra: str | None = None) -> None:
        self.add(Kind.DETECTOR, name, target, description=description, extra=extra)

    def add_task(self, name: str, target: str | type, *, description: str = "", extra: str | None = None) -> None:
        """Register a task (what `twin run` runs, chosen by `task.kind`): `cls(params, context)`, then
        `run(cell) -> list[ObjectOutcome]`."""
        self.add(Kind.TASK, name, target, description=description, extra=extra)

    # ---- lookup ---------------------------------------------------------------------------------
    def entries(self, kinds: Iterable[Kind] | None = None) -> list[Entry]:
        ks = set(kinds) if kinds is not None else set(Kind)
        return sorted((e for e in self._entries.values() if e.kind in ks), key=lambda e: (e.kind.value, e.name))

    def names(self, kinds: Iterable[Kind] | None = None) -> list[str]:
        return sorted(e.name for e in self.entries(kinds))

    def entry(self, name: str, kinds: Iterable[Kind] = tuple(Kind)) -> Entry:
        kinds = tuple(kinds)
        e = self._entries.get(name)
        if e is None or e.kind not in kinds:
            what = "planner" if set(kinds) <= set(_PLANNER_KINDS) else kinds[0].value if len(kinds) == 1 else "name"
            raise UnknownNameError(what, name, self.names(kinds))
        return e

    def create(self, name: str, params: dict[str, Any] | None, context: PluginContext, kinds: Iterable[Kind]) -> Any:
        """Instantiate the plugin `name` with validated `params`: `cls(params, context)`."""
        entry = self.entry(name, kinds)
        cls = entry.load()
        reason = _unavailable_reason(cls)
        if reason is not None:
            raise DependencyMissing(reason)
        p = validate_params(entry, cls, params)
        return cls(p, context)

    def planner(self, name: str, params: dict[str, Any] | None, context: PluginContext) -> Any:
        return self.create(name, params, context, _PLANNER_KINDS)

    def retimer(self, name: str, params: dict[str, Any] | None, context: PluginContext) -> Any:
        return self.create(name, params, context, (Kind.RETIMER,))

    def detector(self, name: str, params: dict[str, Any] | None, context: PluginContext) -> Any:
        return self.create(name, params, context, (Kind.DETECTOR,))

    def task(self, name: str, params: dict[str, Any] | None, context: PluginContext) -> Any:
        return self.create(name, params, context, (Kind.TASK,))

    # ---- building from plugins ------------------------------------------------------------------
    @classmethod
    def from_plugin_manager(cls, pm: pluggy.PluginManager) -> Registry:
        """Ask every plugin of `pm`, one at a time, to register its names (so each name has a provider)."""
        reg = cls()
        dists = {id(plugin): f"{d.project_name} {d.version}" for plugin, d in pm.list_plugin_distinfo()}
        plugins = pm.get_plugins()
        for plugin in sorted(plugins, key=lambda p: pm.get_name(p) or ""):
            others = [p for p in plugins if p is not plugin]
            reg._provider = dists.get(id(plugin), pm.get_name(plugin) or repr(plugin))
            for hook in HOOKS:
                pm.subset_hook_caller(hook, remove_plugins=others)(registry=reg)
        reg._provider = "(direct)"
        return reg


def plugin_manager(*, entry_points: bool = True, plugins: Iterable[object] = ()) -> pluggy.PluginManager:
    """A fresh plugin manager with twin's hooks, the installed `twin` entry points, and `plugins`."""
    pm = pluggy.PluginManager("twin")
    pm.add_hookspecs(TwinSpec)
    if entry_points:
        pm.load_setuptools_entrypoints("twin")
    for p in plugins:
        pm.register(p)
    _check_hooks(pm)
    return pm


def _check_hooks(pm: pluggy.PluginManager) -> None:
    """A `@hookimpl` whose name is not one of twin's hooks would be ignored silently; refuse it instead."""
    try:
        pm.check_pending()
    except pluggy.PluginValidationError as e:
        hooks = sorted(name for name in dir(TwinSpec) if name.startswith("twin_"))
        plugin = getattr(e.plugin, "__name__", None) or type(e.plugin).__name__
        unknown = sorted(
            name
            for name, caller in vars(pm.hook).items()
            if not caller.has_spec() and any(impl.plugin is e.plugin for impl in caller.get_hookimpls())
        )
        raise PluginError(
            f"plugin {plugin!r} implements unknown hook(s) {', '.join(unknown) or '?'}; "
            f"twin's hooks are: {', '.join(hooks)}"
        ) from None


@lru_cache(maxsize=1)
def default_registry() -> Registry:
    """The registry of every installed plugin (cached; call `default_registry.cache_clear()` to rescan)."""
    return Registry.from_plugin_manager(plugin_manager())
