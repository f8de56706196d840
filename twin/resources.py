"""Where twin's files live: shipped data in the package, generated files in a cache directory.

Shipped data (the robot, fixture and object URDFs, the reference configs) is package data under
`twin/data/` and is read through `importlib.resources`, so it is found the same way from a checkout, an
editable install and an installed wheel. In the checkout, `twin/data/urdf` and `twin/data/configs` are
links to the top-level `urdf/` and `configs/` directories, where the files are edited.

Generated files (textures and meshes made from a config, e.g. the ArUco marker) go to a cache directory,
never into the package or the checkout: `$TWIN_CACHE` if set, else `$XDG_CACHE_HOME/twin`, else
`~/.cache/twin`; a temporary directory when that cannot be written.

Paths in configs are relative to the config file first and to the shipped data second
(`Settings.resolve`); config names are the stems of the shipped configs (`load_config("robocup")`).
"""

from __future__ import annotations

import atexit
import contextlib
import logging
import os
import tempfile
from importlib.resources import as_file, files
from importlib.resources.abc import Traversable
from pathlib import Path, PurePosixPath

__all__ = [
    "CONFIG_SUFFIXES",
    "cache_dir",
    "config_names",
    "data_files",
    "packaged_config",
    "packaged_path",
]

log = logging.getLogger("twin")

CONFIG_SUFFIXES = (".yaml", ".yml")

# files extracted by `as_file` from a package that is not on the file system (a zip): they stay until exit
_extracted = contextlib.ExitStack()
atexit.register(_extracted.close)
_real_paths: dict[str, Path] = {}


def data_files() -> Traversable:
    """The root of the shipped data (`urdf/`, `configs/`), as an importlib.resources Traversable."""
    return files("twin") / "data"


def _traversable(relative: str | PurePosixPath) -> Traversable | None:
    """The shipped file or directory at `relative` (posix, below the data root), or None.

    Only plain relative paths name shipped data: an absolute path, `..` or an empty name never does."""
    text = str(relative).replace("\\", "/")
    parts = [p for p in PurePosixPath(text).parts if p != "."]
    if not parts or text.startswith("/") or any(p == ".." for p in parts):
        return None
    node = data_files()
    for p in parts:
        node = node / p
    try:
        return node if node.is_file() or node.is_dir() else None
    except (OSError, ValueError):  # a NUL byte, a name too long for the system
        return None


def packaged_path(relative: str | PurePosixPath) -> Path | None:
    """A real file-system path of the shipped file (or directory) `relative`, e.g. 'urdf/ur5e.urdf',
    for what needs one (PyBullet, FCL, a URDF parser); None when twin does not ship it.

    From a package on the file system (a checkout, an editable or a regular install) this is the file
    itself; from a zipped package a file is extracted (`importlib.resources.as_file`) and kept until exit.
    """
    node = _traversable(relative)
    if node is None:
        return None
    if isinstance(node, Path):
        return node
    key = str(relative)
    if key not in _real_paths:
        if node.is_dir():  # as_file extracts directories from Python 3.12 on only
            return None
        _real_paths[key] = _extracted.enter_context(as_file(node))
    return _real_paths[key]


def config_names() -> list[str]:
    """Names of the shipped configs (file stems), sorted: 'compare', 'compare-smoke', 'robocup', ..."""
    names = []
    try:
        entries = list((data_files() / "configs").iterdir())
    except OSError:
        return []
    for e in entries:
        suffix = next((s for s in CONFIG_SUFFIXES if e.name.endswith(s)), None)
        if suffix is not None and e.is_file():
            names.append(e.name[: -len(suffix)])
    return sorted(names)


def packaged_config(name: str) -> Path | None:
    """The shipped config called `name` ('robocup' or 'robocup.yaml'), or None."""
    stem = name
    for suffix in CONFIG_SUFFIXES:
        if stem.endswith(suffix):
            stem = stem[: -len(suffix)]
            break
    if not stem or "/" in stem or "\\" in stem or stem in (".", ".."):
        return None
    for suffix in CONFIG_SUFFIXES:
        p = packaged_path(f"configs/{stem}{suffix}")
        if p is not None and p.is_file():
            return p
    return None


def _user_cache_root() -> Path:
    explicit = os.environ.get("TWIN_CACHE")
    if explicit:
        return Path(explicit).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    if xdg and Path(xdg).is_absolute():  # the XDG spec: a relative value is ignored
        return Path(xdg) / "twin"
    return Path.home() / ".cache" / "twin"


def _writable_dir(path: Path) -> bool:
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return path.is_dir() and os.access(path, os.W_OK | os.X_OK)


def cache_dir(*parts: str) -> Path:
    """A writable cache directory for generated files, created if needed: `<cache>/<parts...>`.

    `<cache>` is `$TWIN_CACHE`, else `$XDG_CACHE_HOME/twin`, else `~/.cache/twin`. When that cannot be
    written (a read-only home, a sandbox), a per-user directory in the system's temporary directory.
    Writers must write atomically (a temporary file, then `os.replace`): workers share the cache.
    """
    try:
        preferred: Path | None = _user_cache_root().joinpath(*parts)
    except RuntimeError:  # no home directory to expand
        preferred = None
    if preferred is not None and _writable_dir(preferred):
        return preferred
    uid = os.getuid() if hasattr(os, "getuid") else "user"
    fallback = Path(tempfile.gettempdir()).joinpath(f"twin-cache-{uid}", *parts)
    log.debug("cache directory %s is not writable, using %s", preferred, fallback)
    fallback.mkdir(parents=True, exist_ok=True)
    return fallback
