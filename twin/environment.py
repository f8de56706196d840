"""Where a result was made: twin's version and commit, Python, the backends' versions, the machine.

Why: a planning time is only comparable with another from the same code on the same kind of machine, and
an install resolves whatever releases are newest on the day. So every result set records this (`twin
compare`'s compare.json, `twin run --json`, the OMPL export's header), and the regression gate names what
changed between a baseline and now (`environment_changes`), so a slower p95 on another CPU or a new numpy
is not mistaken for a code regression.

`environment()` is cheap (a few milliseconds once numpy is imported: two `git` calls with a short timeout,
package metadata, /proc/cpuinfo) and never touches the network. Every value may be None where it cannot
be known (no git, a wheel install, no /proc).
"""

from __future__ import annotations

import importlib
import importlib.metadata
import os
import platform
import re
import socket
import subprocess
from collections.abc import Mapping
from pathlib import Path
from typing import Any

__all__ = ["BACKENDS", "environment", "environment_changes", "machine_lines", "software_lines"]

# The distributions whose versions can change a result: numerics, physics, collision, IK, the planners'
# and retimers' backends, perception, parallel runs.
BACKENDS: tuple[str, ...] = (
    "numpy",
    "scipy",
    "pybullet",
    "python-fcl",
    "ur-analytic-ik",
    "ruckig",
    "toppra",
    "numba",
    "llvmlite",
    "opencv-contrib-python-headless",
    "ompl",
    "casadi",
    "open3d",
    "ray",
    "pydantic",
    "pluggy",
    "matplotlib",
)

_GIT_TIMEOUT_S = 2.0
# /proc/cpuinfo flags that decide which numerical kernels run (x86: SSE4/AVX/AVX-512/FMA/AMX; ARM: NEON,
# ASIMD, SVE); the rest (virtualisation, power management, ...) would only make the record long
_SIMD_FLAG = re.compile(r"(sse4_[12]|avx.*|fma4?|f16c|amx.*|neon|asimd.*|sve.*)")


def environment() -> dict[str, Any]:
    """This process's environment as a JSON-ready dict:

    `twin`: {version, commit, dirty} (commit and dirty from `git` when twin runs from a checkout, else
    None); `python`: {version, implementation}; `packages`: {distribution: version or None} for
    `BACKENDS`; `platform`: {system, release, machine, description}; `cpu`: {model, cores (the machine's),
    usable_cores (this process may use), flags (SIMD flags of /proc/cpuinfo), numpy_simd (numpy's
    runtime SIMD: baseline, found, not_found, as `np.show_runtime`), blas (numpy's BLAS, name and
    version)}; `hostname`."""
    commit, dirty = _git_state()
    return {
        "twin": {"version": _version("twin"), "commit": commit, "dirty": dirty},
        "python": {"version": platform.python_version(), "implementation": platform.python_implementation()},
        "packages": {name: _version(name) for name in BACKENDS},
        "platform": {
            "system": platform.system(),
            "release": platform.release(),
            "machine": platform.machine(),
            "description": platform.platform(terse=True),
        },
        "cpu": {
            "model": _cpu_model(),
            "cores": os.cpu_count(),
            "usable_cores": _usable_cores(),
            "flags": _simd_flags(),
            "numpy_simd": _numpy_simd(),
            "blas": _numpy_blas(),
        },
        "hostname": socket.gethostname(),
    }


def environment_changes(before: Mapping[str, Any] | None, now: Mapping[str, Any] | None) -> list[str]:
    """One line per difference between two records that can move a result: twin's version or commit
    (or uncommitted changes), the Python version, a backend's version, the CPU model, the core count.
    Hostnames and OS releases are left out (CI machines differ in both without mattering). Missing
    records or keys (a record from an older twin) compare as unknown, and unknown is no difference."""
    b, n = before or {}, now or {}
    lines: list[str] = []
    twin_line = _twin_change(_get(b, "twin") or {}, _get(n, "twin") or {})
    if twin_line:
        lines.append(twin_line)
    for label, path in (("python", ("python", "version")), ("python implementation", ("python", "implementation"))):
        x, y = _get(b, *path), _get(n, *path)
        if x is not None and y is not None and x != y:
            lines.append(f"{label}: {x} -> {y}")
    pb, pn = _get(b, "packages") or {}, _get(n, "packages") or {}
    lines.extend(
        f"{name}: {pb[name] or 'not installed'} -> {pn[name] or 'not installed'}"
        for name in dict.fromkeys([*pb, *pn])
        if name in pb and name in pn and pb[name] != pn[name]
    )
    x, y = _get(b, "cpu", "model"), _get(n, "cpu", "model")
    if x is not None and y is not None and x != y:
        lines.append(f"CPU: {x} -> {y}")
    cores = [(_get(r, "cpu", "cores"), _get(r, "cpu", "usable_cores")) for r in (b, n)]
    if any(v is not None for v in cores[0]) and any(v is not None for v in cores[1]) and cores[0] != cores[1]:
        lines.append(f"cores: {_cores(*cores[0])} -> {_cores(*cores[1])}")
    return lines


def machine_lines(record: Mapping[str, Any] | None) -> list[str]:
    """The machine of a record as short text lines (CPU, cores, SIMD, BLAS, OS): what a benchmark log's
    cpuinfo block holds. [] for an empty record; a value the record lacks is left out."""
    cpu = _get(record, "cpu") or {}
    lines: list[str] = []
    if cpu.get("model"):
        lines.append(f"CPU: {cpu['model']}")
    if cpu.get("cores") is not None or cpu.get("usable_cores") is not None:
        lines.append(f"cores: {_cores(cpu.get('cores'), cpu.get('usable_cores'))}")
    if cpu.get("flags") is not None:
        lines.append(f"SIMD flags: {' '.join(cpu['flags']) or 'none'}")
    simd = cpu.get("numpy_simd")
    if isinstance(simd, Mapping):
        parts = [
            f"{k.replace('_', ' ')} {' '.join(simd.get(k) or []) or '-'}" for k in ("baseline", "found", "not_found")
        ]
        lines.append(f"numpy SIMD: {'; '.join(parts)}")
    if cpu.get("blas"):
        lines.append(f"BLAS: {cpu['blas']}")
    if _get(record, "platform", "description"):
        lines.append(f"OS: {_get(record, 'platform', 'description')}")
    return lines


def software_lines(record: Mapping[str, Any] | None) -> list[str]:
    """The software of a record as short text lines: twin (version, commit), Python, the backends."""
    lines: list[str] = []
    t = _get(record, "twin")
    if isinstance(t, Mapping) and t:
        lines.append(f"twin {_describe_twin(t)}")
    py = _get(record, "python")
    if isinstance(py, Mapping) and py:
        lines.append("Python: " + " ".join(str(v) for v in (py.get("implementation"), py.get("version")) if v))
    packages = _get(record, "packages")
    if isinstance(packages, Mapping) and packages:
        lines.append("packages: " + ", ".join(f"{k} {v or 'not installed'}" for k, v in packages.items()))
    return lines


# ---- twin ---------------------------------------------------------------------------------------------
def _version(distribution: str) -> str | None:
    try:
        return importlib.metadata.version(distribution)
    except importlib.metadata.PackageNotFoundError:
        return None


def _checkout() -> Path | None:
    """The git checkout twin is imported from (the folder holding both `twin/` and `.git`), or None: an
    installed wheel lives in site-packages, and a venv inside a checkout must not report that checkout."""
    root = Path(__file__).resolve().parent.parent
    return root if (root / ".git").exists() and (root / "pyproject.toml").is_file() else None


def _git_state() -> tuple[str | None, bool | None]:
    """(HEAD's commit, whether tracked files differ from it) of twin's checkout; (None, None) without one,
    without git, or when git does not answer in time."""
    root = _checkout()
    if root is None:
        return None, None
    head = _git(root, "rev-parse", "HEAD")
    if head is None:
        return None, None
    status = _git(root, "status", "--porcelain", "--untracked-files=no")
    return head.strip(), None if status is None else bool(status.strip())


def _git(root: Path, *args: str) -> str | None:
    try:
        r = subprocess.run(
            ["git", "-C", str(root), *args],
            capture_output=True,
            text=True,
            timeout=_GIT_TIMEOUT_S,
            check=False,
            env={**os.environ, "GIT_OPTIONAL_LOCKS": "0"},  # `status` must not take the index lock
        )
    except (OSError, subprocess.SubprocessError):
        return None
    return r.stdout if r.returncode == 0 else None


def _describe_twin(t: Mapping[str, Any], *, short: bool = False) -> str:
    """'0.1.0 at <commit>[ with uncommitted changes]' (the commit cut to 10 digits when `short`)."""
    text = str(t.get("version") or "?")
    if t.get("commit"):
        text += f" at {str(t['commit'])[:10] if short else t['commit']}"
    elif t.get("version"):
        text += " (not from a git checkout)"
    return text + (" with uncommitted changes" if t.get("dirty") else "")


def _twin_change(b: Mapping[str, Any], n: Mapping[str, Any]) -> str | None:
    if not b or not n:
        return None
    same_code = b.get("version") == n.get("version") and b.get("commit") == n.get("commit")
    if same_code and not b.get("dirty") and not n.get("dirty"):
        return None
    line = f"twin: {_describe_twin(b, short=True)} -> {_describe_twin(n, short=True)}"
    return line + " (the code may differ)" if same_code else line


# ---- the machine --------------------------------------------------------------------------------------
def _cpuinfo() -> dict[str, str]:
    """The first processor's `key: value` lines of /proc/cpuinfo (and ARM's trailing machine lines);
    {} where there is no /proc."""
    try:
        text = Path("/proc/cpuinfo").read_text(errors="replace")
    except OSError:
        return {}
    out: dict[str, str] = {}
    for line in text.splitlines():
        key, sep, value = line.partition(":")
        if sep:
            out.setdefault(key.strip().lower(), value.strip())
    return out


def _cpu_model() -> str | None:
    info = _cpuinfo()
    for key in ("model name", "cpu model", "hardware", "model", "processor"):
        value = info.get(key)
        if value and not value.isdigit():  # ARM's `processor: 0` is an index, not a name
            return value
    if info.get("cpu implementer") and info.get("cpu part"):  # ARM Linux names no model, only its ids
        return f"ARM implementer {info['cpu implementer']} part {info['cpu part']}"
    return platform.processor() or None


def _simd_flags() -> list[str] | None:
    info = _cpuinfo()
    flags = info.get("flags") or info.get("features")
    if flags is None:
        return None
    return sorted({f for f in flags.split() if _SIMD_FLAG.fullmatch(f)})


def _usable_cores() -> int | None:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count()


def _numpy_simd() -> dict[str, list[str]] | None:
    """numpy's SIMD extensions as `np.show_runtime` reports them: the baseline it was built for, and of
    the ones it dispatches to at run time those this CPU has (found) and lacks (not_found)."""
    try:
        umath: Any = importlib.import_module("numpy._core._multiarray_umath")
    except ImportError:
        return None
    features: dict[str, bool] = getattr(umath, "__cpu_features__", {})
    dispatch: list[str] = list(getattr(umath, "__cpu_dispatch__", []))
    return {
        "baseline": list(getattr(umath, "__cpu_baseline__", [])),
        "found": [f for f in dispatch if features.get(f)],
        "not_found": [f for f in dispatch if not features.get(f)],
    }


def _numpy_blas() -> str | None:
    try:
        import numpy as np

        deps = (np.show_config(mode="dicts") or {}).get("Build Dependencies", {})
    except (ImportError, AttributeError, TypeError, ValueError):
        return None
    blas = deps.get("blas") or {}
    name, version = blas.get("name"), blas.get("version")
    return None if not name else f"{name} {version}" if version else str(name)


def _cores(total: int | None, usable: int | None) -> str:
    return f"{total if total is not None else '?'} ({usable if usable is not None else '?'} usable)"


def _get(record: Mapping[str, Any] | None, *path: str) -> Any:
    value: Any = record
    for key in path:
        if not isinstance(value, Mapping):
            return None
        value = value.get(key)
    return value
