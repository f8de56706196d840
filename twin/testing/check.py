"""The entry points a user calls: `check_planner` builds the planner exactly as the runs do, so what it
judges is what a run would get; `assert_conformant` is the same for a plugin's own test suite."""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING, Any

from twin.config import PlannerBlock, load_config
from twin.errors import InvalidRequestError
from twin.planning import make_context, make_planner
from twin.registry import Registry, plugin_manager
from twin.testing.contract import RULES, ConformanceReport
from twin.testing.examiner import _Checker

if TYPE_CHECKING:
    from twin.config import Settings

__all__ = ["DEFAULT_CONFIG", "assert_conformant", "check_planner"]

DEFAULT_CONFIG = "robocup"  # the shipped reference config whose scene and limits the check uses by default


def _default_settings() -> Settings:
    return load_config(DEFAULT_CONFIG)


def _block(
    planner: PlannerBlock | str | dict[str, Any] | type, registry: Registry | None
) -> tuple[PlannerBlock, Registry | None]:
    """A config block for `planner` (a name, a block or its dict, or a planner class, registered here
    under 'check.<class name>' in a registry of every installed plugin plus this class)."""
    if isinstance(planner, PlannerBlock):
        return planner, registry
    if isinstance(planner, str):
        return PlannerBlock(name=planner), registry
    if isinstance(planner, dict):
        return PlannerBlock(**planner), registry
    if isinstance(planner, type):
        reg = registry or Registry.from_plugin_manager(plugin_manager())
        name = f"check.{planner.__name__.lower()}"
        rh = callable(getattr(planner, "reset", None)) and callable(getattr(planner, "step", None))
        if name not in reg.names():
            reg.add_planner(name, planner, receding_horizon=rh, description="checked by twin.testing")
        return PlannerBlock(name=name), reg
    raise TypeError(f"planner must be a name, a PlannerBlock, a dict or a class, got {type(planner).__name__}")


def check_planner(
    planner: PlannerBlock | str | dict[str, Any] | type,
    *,
    settings: Settings | None = None,
    seed: int = 0,
    queries: int | None = None,
    time_limit_s: float = 1.0,
    registry: Registry | None = None,
    config_name: str | None = None,
    on_progress: Callable[[str], None] | None = None,
) -> ConformanceReport:
    """Check one planner against the planner contract (the `twin.testing` docstring lists the rules).

    `planner`: a registered name, a config block (`{name, params, retimer}`), or a planner class (then
    registered for the check). `settings`: the scene and limits (default: the shipped config 'robocup').
    `queries`: collision-free queries to plan (default 3 for one-shot planners, 2 for receding-horizon
    ones, whose every step is a solve). `time_limit_s`: the requests' time limit. `registry`: where the
    name is looked up (default: every installed plugin). `on_progress(text)` is told each request asked.

    Bad input (an unknown name, bad params, a missing backend) raises a TwinError, as `make_planner` does;
    every breach of the contract is a failed `CheckResult` in the report, never an exception."""
    from twin.collision import PlanningScene  # lazy: fcl

    if not (math.isfinite(time_limit_s) and time_limit_s > 0):
        raise InvalidRequestError(f"time_limit_s must be positive, got {time_limit_s}")
    t0 = time.perf_counter()
    block, registry = _block(planner, registry)
    if settings is None:
        settings = _default_settings()
        config_name = config_name or DEFAULT_CONFIG
    context = make_context(settings, registry)
    checked = make_planner(block, context)
    rh = checked.receding_horizon
    n = queries if queries is not None else (2 if rh else 3)
    if n < 1:
        raise InvalidRequestError(f"queries must be at least 1, got {n}")
    scene = PlanningScene.from_settings(settings)  # with the obstacles perception would report, as boxes
    checker = _Checker(
        checked,
        block.name,
        settings,
        scene,
        context,
        seed=seed,
        time_limit_s=time_limit_s,
        progress=on_progress or (lambda _: None),
    )
    results, outcomes = checker.run(n)
    return ConformanceReport(
        planner=block.name,
        kind="receding-horizon" if rh else "one-shot",
        config=config_name or settings.name,
        seed=seed,
        time_limit_s=time_limit_s,
        goal_kinds=checker.kinds,
        results=tuple(results),
        requests=tuple(o.to_json() for o in outcomes),
        wall_time_s=time.perf_counter() - t0,
    )


def assert_conformant(
    planner: PlannerBlock | str | dict[str, Any] | type, *, ignore: Iterable[str] = (), **kwargs: Any
) -> ConformanceReport:
    """`check_planner(planner, **kwargs)`, raising AssertionError that lists every failed rule (those in
    `ignore` aside); returns the report. For a plugin's own test suite."""
    report = check_planner(planner, **kwargs)
    skip = set(ignore)
    unknown = skip - set(RULES)
    if unknown:
        raise ValueError(f"unknown rules {sorted(unknown)}; rules: {', '.join(RULES)}")
    failed = [r for r in report.failures if r.rule not in skip]
    if failed:
        lines = "\n".join(f"  rule {r.number} {r.rule}: {r.detail}" for r in failed)
        raise AssertionError(
            f"{report.planner} breaks the planner contract ({report.config}, seed {report.seed}):\n{lines}"
        )
    return report
