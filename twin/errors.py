"""Typed errors of twin.

    TwinError
     +-- ConfigError            invalid or missing configuration (file, key, value)
     +-- UnknownNameError       a planner/retimer/detector name that is not registered (also LookupError)
     +-- DuplicateNameError     two plugins registered the same name
     +-- PluginError            a plugin implements a hook twin does not have (a misspelling)
     +-- DependencyMissing      an optional backend is not installed (also ImportError)
     +-- InvalidRequestError    a malformed motion request or bad argument (also ValueError)
     +-- PlanningError          a planner broke its contract (not "no solution": that is a status)
     |    +-- PluginCrashed     a plugin raised an exception of its own (a bug in the plugin, not the input)
     +-- WorldError             the simulated world cannot be built as asked

"No solution" is never an exception: it is a status with a reason in a result.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable

__all__ = [
    "ConfigError",
    "DependencyMissing",
    "DuplicateNameError",
    "InvalidRequestError",
    "PlanningError",
    "PluginCrashed",
    "PluginError",
    "TwinError",
    "UnknownNameError",
    "WorldError",
]


class TwinError(Exception):
    """Base of every error twin raises on purpose."""


class ConfigError(TwinError):
    """A configuration file, key or value is wrong."""


class UnknownNameError(TwinError, LookupError):
    """A name was looked up that is not registered."""

    def __init__(self, kind: str, name: str, known: Iterable[str], hint: str = "Run `twin planners` for all names."):
        self.kind = kind
        self.name = name
        self.known = sorted(known)
        close = difflib.get_close_matches(name, self.known, n=1, cutoff=0.6)
        # also match on the last dotted part, so 'rrtconect' finds 'ompl.rrtconnect'
        if not close:
            tails = {k.rsplit(".", 1)[-1]: k for k in self.known}
            t = difflib.get_close_matches(name.rsplit(".", 1)[-1], list(tails), n=1, cutoff=0.6)
            close = [tails[t[0]]] if t else []
        msg = f"{kind} {name!r} is not registered."
        if close:
            msg += f" Did you mean {close[0]!r}?"
        msg += f" Registered: {', '.join(self.known) if self.known else '(none)'}. {hint}"
        super().__init__(msg)


class PluginError(TwinError):
    """A plugin does not fit twin's hooks (an implementation of a hook that does not exist)."""


class DuplicateNameError(TwinError):
    """Two plugins tried to register the same name."""


class DependencyMissing(TwinError, ImportError):
    """An optional backend is not installed; the message names the extra to install."""


class InvalidRequestError(TwinError, ValueError):
    """A request or argument is malformed (wrong shape, out of range, unknown frame)."""


class PlanningError(TwinError):
    """A planner broke its contract (for example returned a colliding trajectory)."""


class PluginCrashed(PlanningError):
    """A plugin raised an exception that is not one of twin's (a bug in the plugin): the message names the
    plugin, what it was doing and the exception; the original is the `__cause__` (its traceback)."""

    def __init__(self, plugin: str, doing: str, error: BaseException):
        super().__init__(f"{plugin} raised {type(error).__name__} in {doing}: {error}")
        self.plugin = plugin
        self.error = error


class WorldError(TwinError):
    """The simulated world cannot be built or driven as asked."""
