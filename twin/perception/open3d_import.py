"""Importing open3d: on first use (importing twin never imports it), without the part perception never uses.

open3d's package imports `open3d.visualization`, whose `draw_plotly` module imports dash and plotly at
module level: ~0.2 s of a task run's ~1 s of imports on an idle machine, ~0.7 s on a loaded one. Nothing in
twin draws with plotly, so until something calls one of that module's functions it is a stand-in whose
functions import the real module when called: a user who draws with open3d still gets plotly, only later.
"""

from __future__ import annotations

import importlib
import sys
import types
from collections.abc import Callable
from typing import Any

from twin.errors import DependencyMissing
from twin.timing import stage

__all__ = ["load_open3d"]

_PLOTLY = "open3d.visualization.draw_plotly"
_PLOTLY_FUNCTIONS = ("get_plotly_fig", "draw_plotly", "draw_plotly_server")  # what open3d.visualization takes


class _DeferredPlotly(types.ModuleType):
    """`open3d.visualization.draw_plotly` until any other attribute of it is asked for."""

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):  # the import system asks for __path__ & co.: a plain module has none
            raise AttributeError(name)
        return getattr(_real_plotly(), name)


def _real_plotly() -> types.ModuleType:
    if isinstance(sys.modules.get(_PLOTLY), _DeferredPlotly):
        del sys.modules[_PLOTLY]
    parent = sys.modules.get("open3d.visualization")
    function = getattr(parent, "draw_plotly", None)
    module = importlib.import_module(_PLOTLY)
    if parent is not None and function is not None:
        # importing the submodule rebinds the package's name to it; open3d has the function there
        setattr(parent, "draw_plotly", function)  # noqa: B010
    return module


def _deferred(name: str) -> Callable[..., Any]:
    def call(*args: Any, **kwargs: Any) -> Any:
        return getattr(_real_plotly(), name)(*args, **kwargs)

    call.__name__ = call.__qualname__ = name
    return call


def load_open3d() -> Any:
    """The open3d module; DependencyMissing naming the extra when it is not installed."""
    loaded = sys.modules.get("open3d")
    if loaded is not None:  # the usual case, on hot paths (a neighbour search per ICP iteration)
        return loaded
    if _PLOTLY not in sys.modules:
        standin = _DeferredPlotly(_PLOTLY)
        for name in _PLOTLY_FUNCTIONS:
            setattr(standin, name, _deferred(name))
        sys.modules[_PLOTLY] = standin
    try:
        with stage("imports"):  # the first import takes ~0.2 s (a run's breakdown shows it as such)
            import open3d as o3d
    except ImportError as e:
        if isinstance(sys.modules.get(_PLOTLY), _DeferredPlotly):
            del sys.modules[_PLOTLY]
        raise DependencyMissing(
            "perception needs open3d, which is not installed. Install it with `pip install 'twin[perception]'`."
        ) from e
    return o3d
