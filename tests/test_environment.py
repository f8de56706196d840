"""The environment record (twin.environment): what a result says about where it ran, and which differences
between two records the regression gate names (twin commit, Python, a backend, CPU model, cores)."""

from __future__ import annotations

import copy
import importlib.util
import json
import os
import platform
import shutil
import socket
import subprocess
from pathlib import Path
from types import ModuleType
from typing import Any

import numpy as np
import pytest

from twin.environment import BACKENDS, environment, environment_changes, machine_lines, software_lines

ROOT = Path(__file__).resolve().parent.parent


def test_the_record_says_where_this_process_runs() -> None:
    env = environment()
    assert json.loads(json.dumps(env)) == env  # JSON-ready
    assert env["python"] == {"version": platform.python_version(), "implementation": platform.python_implementation()}
    assert env["packages"]["numpy"] == np.__version__
    assert set(env["packages"]) == set(BACKENDS)
    assert env["hostname"] == socket.gethostname()
    assert env["cpu"]["cores"] == os.cpu_count()
    assert 1 <= env["cpu"]["usable_cores"] <= env["cpu"]["cores"]
    simd = env["cpu"]["numpy_simd"]
    assert simd is not None and set(simd) == {"baseline", "found", "not_found"}
    assert env["twin"]["version"] == importlib.metadata.version("twin")


@pytest.mark.skipif(not Path("/proc/cpuinfo").is_file(), reason="no /proc/cpuinfo")
def test_cpu_model_and_simd_flags_come_from_proc_cpuinfo() -> None:
    text = Path("/proc/cpuinfo").read_text()
    lines = text.splitlines()
    flags = next(line.split(":", 1)[1].split() for line in lines if line.startswith(("flags", "Features")))
    cpu = environment()["cpu"]
    assert cpu["flags"] and set(cpu["flags"]) <= set(flags)
    assert all(f.startswith(("sse4", "avx", "fma", "f16c", "amx", "neon", "asimd", "sve")) for f in cpu["flags"])
    if "avx2" in flags:
        assert "avx2" in cpu["flags"]
    if "model name" in text:
        assert cpu["model"] and cpu["model"] in text


@pytest.mark.skipif(shutil.which("git") is None or not (ROOT / ".git").exists(), reason="not a git checkout")
def test_from_a_checkout_the_record_names_the_commit() -> None:
    head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "HEAD"], capture_output=True, text=True, check=True)
    twin = environment()["twin"]
    assert twin["commit"] == head.stdout.strip()
    assert isinstance(twin["dirty"], bool)


def _load_copy(path: Path) -> ModuleType:
    """twin/environment.py copied to `path` and imported from there (as an installed wheel would have it)."""
    path.parent.mkdir(parents=True)
    shutil.copy(ROOT / "twin" / "environment.py", path)
    spec = importlib.util.spec_from_file_location("twin_environment_copy", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.mark.skipif(shutil.which("git") is None, reason="no git")
def test_installed_outside_a_checkout_the_record_has_no_commit(tmp_path: Path) -> None:
    # a wheel in site-packages, and one in a venv that lives inside some other git repository: neither is a
    # checkout of twin, so neither may report a commit (the enclosing repository's would be wrong)
    alone = _load_copy(tmp_path / "venv" / "lib" / "site-packages" / "twin" / "environment.py")
    repo = tmp_path / "repo"
    repo.mkdir()
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    nested = _load_copy(repo / ".venv" / "lib" / "site-packages" / "twin" / "environment.py")
    for module in (alone, nested):
        twin = module.environment()["twin"]
        assert (twin["commit"], twin["dirty"]) == (None, None)


def _record() -> dict[str, Any]:
    return {
        "twin": {"version": "0.1.0", "commit": "a" * 40, "dirty": False},
        "python": {"version": "3.11.7", "implementation": "CPython"},
        "packages": {"numpy": "2.4.6", "ompl": "2.0.1", "ray": None},
        "platform": {"system": "Linux", "release": "6.1", "machine": "x86_64", "description": "Linux-6.1-x86_64"},
        "cpu": {
            "model": "AMD EPYC",
            "cores": 2,
            "usable_cores": 2,
            "flags": ["avx", "avx2", "fma"],
            "numpy_simd": {"baseline": ["X86_V2"], "found": ["X86_V3"], "not_found": ["X86_V4"]},
            "blas": "scipy-openblas 0.3.31",
        },
        "hostname": "ci-1",
    }


def test_the_same_environment_has_no_changes_and_a_new_host_or_os_is_none() -> None:
    a, b = _record(), _record()
    b["hostname"], b["platform"]["release"] = "ci-2", "6.5"
    assert environment_changes(a, b) == []
    assert environment_changes(None, a) == environment_changes(a, None) == environment_changes({}, {}) == []


def test_each_difference_that_can_move_a_result_is_one_line() -> None:
    a, b = _record(), _record()
    b["twin"]["commit"] = "b" * 40
    b["python"]["version"] = "3.12.1"
    b["packages"].update(numpy="2.5.0", ray="2.60.0")
    b["cpu"].update(model="Intel Xeon Gold", cores=16, usable_cores=4)
    assert environment_changes(a, b) == [
        f"twin: 0.1.0 at {'a' * 10} -> 0.1.0 at {'b' * 10}",
        "python: 3.11.7 -> 3.12.1",
        "numpy: 2.4.6 -> 2.5.0",
        "ray: not installed -> 2.60.0",
        "CPU: AMD EPYC -> Intel Xeon Gold",
        "cores: 2 (2 usable) -> 16 (4 usable)",
    ]


def test_uncommitted_changes_are_named_and_unknown_keys_are_no_difference() -> None:
    a, b = _record(), _record()
    b["twin"]["dirty"] = True
    assert environment_changes(a, b) == [
        f"twin: 0.1.0 at {'a' * 10} -> 0.1.0 at {'a' * 10} with uncommitted changes (the code may differ)"
    ]
    old = copy.deepcopy(a)  # a record of an older twin: fewer packages, no cpu section
    del old["cpu"]
    old["packages"] = {"numpy": "2.4.6"}
    assert environment_changes(old, a) == []


def test_machine_and_software_lines() -> None:
    env = _record()
    assert machine_lines(env) == [
        "CPU: AMD EPYC",
        "cores: 2 (2 usable)",
        "SIMD flags: avx avx2 fma",
        "numpy SIMD: baseline X86_V2; found X86_V3; not found X86_V4",
        "BLAS: scipy-openblas 0.3.31",
        "OS: Linux-6.1-x86_64",
    ]
    assert software_lines(env) == [
        f"twin 0.1.0 at {'a' * 40}",
        "Python: CPython 3.11.7",
        "packages: numpy 2.4.6, ompl 2.0.1, ray not installed",
    ]
    assert machine_lines({}) == software_lines({}) == []
