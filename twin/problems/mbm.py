"""MotionBenchMaker's UR5 suite as problem sets, on demand: a comparison scenario's `problems: mbm:ur5/<scene>`
names one. The problems come from vamp-planner 0.6.4's source distribution on the package index (pip downloads
it into twin's cache, `<cache>/mbm`, once; nothing of it ships with twin): `resources/ur5/problems.tar.bz2`,
MBM's `<scene>_ur5/sceneNNNN.yaml` + `requestNNNN.yaml`, imported as `twin problems import-moveit DIR --robot
ur5` does and kept in the cache."""

from __future__ import annotations

import os
import subprocess
import sys
import tarfile
from pathlib import Path

from twin.errors import ConfigError

__all__ = ["MBM_PREFIX", "SCENES", "SDIST", "mbm_problem_set", "mbm_problems_dir"]

MBM_PREFIX = "mbm:"  # `problems: mbm:ur5/box` in a comparison scenario
SDIST = "vamp-planner==0.6.4"
SCENES = ("table_pick", "table_under_pick", "box", "bookshelf_small", "bookshelf_tall", "bookshelf_thin", "cage")
_SET_VERSION = "v1"  # bump when the importer's output changes: the cached sets are made again


def _cache() -> Path:
    from twin.resources import cache_dir

    return cache_dir("mbm")


def mbm_problems_dir() -> Path:
    """MBM's unpacked UR5 problems (`<cache>/mbm/ur5_problems/problems`), downloaded and unpacked on first use;
    ConfigError when pip cannot fetch the source distribution."""
    cache = _cache()
    problems = cache / "ur5_problems" / "problems"
    if problems.is_dir():
        return problems
    sdists = sorted(cache.glob("vamp_planner-*.tar.gz"))
    if not sdists:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", "vamp-planner", SDIST]
        done = subprocess.run([*cmd, "-d", str(cache)], capture_output=True, text=True, check=False)
        sdists = sorted(cache.glob("vamp_planner-*.tar.gz"))
        if done.returncode != 0 or not sdists:
            why = (done.stderr.strip().splitlines() or ["no file"])[-1]
            raise ConfigError(f"cannot fetch MotionBenchMaker's problems ({SDIST} from the package index): {why}")
    with tarfile.open(sdists[-1]) as sd:
        member = next(m for m in sd.getmembers() if m.name.endswith("resources/ur5/problems.tar.bz2"))
        inner = sd.extractfile(member)
        assert inner is not None
        with tarfile.open(fileobj=inner, mode="r:bz2") as tb:
            tb.extractall(cache / "ur5_problems", filter="data")
    return problems


def mbm_problem_set(name: str) -> Path:
    """The problem-set file of `ur5/<scene>` (a scene of SCENES), imported on first use into the cache."""
    robot, _, scene = name.partition("/")
    if robot != "ur5" or scene not in SCENES:
        raise ConfigError(f"unknown MotionBenchMaker set {name!r}; known: " + ", ".join(f"ur5/{s}" for s in SCENES))
    path = _cache() / "sets" / f"{scene}-{_SET_VERSION}.json"
    if not path.is_file():
        from twin.problems.model import save_problem_set
        from twin.problems.moveit import problem_set_from_moveit_dir

        ps = problem_set_from_moveit_dir(mbm_problems_dir() / f"{scene}_ur5", robot="ur5", name=scene)
        tmp = save_problem_set(ps, path.with_suffix(f".{os.getpid()}.tmp"))
        os.replace(tmp, path)  # whole or not at all: two processes may import it at once
    return path
