"""Built-in perception detectors (registered through the `twin` entry-point group)."""

from __future__ import annotations

from twin import hookimpl
from twin.registry import Registry


@hookimpl
def twin_register_detectors(registry: Registry) -> None:
    pass
