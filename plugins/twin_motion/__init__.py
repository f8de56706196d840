"""Built-in MoveJ/MoveL planners and retimers (Ruckig, TOPP-RA, the seed-002 baselines)."""

from __future__ import annotations

from twin import hookimpl
from twin.registry import Registry


@hookimpl
def twin_register_planners(registry: Registry) -> None:
    pass


@hookimpl
def twin_register_retimers(registry: Registry) -> None:
    pass
