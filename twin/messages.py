"""One-line messages that quote user input: `one_line`, `short_repr`.

A module at the bottom of the house (it imports nothing of twin's) because both the config loader and
the plugin registry word their errors with it, and the loader asks the registry whether a task is
registered: with these two functions in `twin.config.loader`, config -> registry -> config was a cycle.
"""

from __future__ import annotations

__all__ = ["one_line", "short_repr"]


def one_line(text: object, limit: int = 300) -> str:
    """`text` on one line (every line break and run of white space becomes one space), cut to `limit`
    characters: error messages quote user input, and a user mistake must print as ONE line."""
    out = " ".join(str(text).split())
    return out if len(out) <= limit else out[: limit - 3] + "..."


def short_repr(value: object, limit: int = 60) -> str:
    """repr of a user's value for an error message: one line, at most `limit` characters."""
    try:
        r = repr(value)
    except Exception:  # noqa: BLE001 - a message must never fail
        r = f"<{type(value).__name__}>"
    return one_line(r, limit)
