"""MotionBenchMaker's UR5 suite as problem sets, on demand: a comparison scenario's `problems: mbm:ur5/<scene>`
names one. The problems come from vamp-planner 0.6.4's source distribution on the package index (pip downloads
it into twin's cache, `<cache>/mbm`, once; nothing of it ships with twin): `resources/ur5/problems.tar.bz2`,
MBM's `<scene>_ur5/sceneNNNN.yaml` + `requestNNNN.yaml`, imported as `twin problems import-moveit DIR --robot
ur5` does and kept in the cache."""

from __future__ import annotations

import io
import os
import subprocess
import sys
import tarfile
from pathlib import Path
from typing import IO

from twin.assets import write_atomic
from twin.errors import ConfigError
from twin.problems.moveit import problem_set_from_moveit_dir
from twin.problems.problem_set import save_problem_set
from twin.resources import cache_dir

__all__ = ["MBM_PREFIX", "SCENES", "SDIST", "mbm_problem_set", "mbm_problems_dir", "mbm_spherized_urdf"]

MBM_PREFIX = "mbm:"  # `problems: mbm:ur5/box` in a comparison scenario
SDIST = "vamp-planner==0.6.4"
SCENES = ("table_pick", "table_under_pick", "box", "bookshelf_small", "bookshelf_tall", "bookshelf_thin", "cage")
_SET_VERSION = "v1"  # bump when the importer's output changes: the cached sets are made again


def _cache() -> Path:
    return cache_dir("mbm")


def mbm_problems_dir() -> Path:
    """MBM's unpacked UR5 problems (`<cache>/mbm/ur5_problems/problems`), downloaded and unpacked on first use;
    ConfigError when pip cannot fetch the source distribution."""
    problems = _cache() / "ur5_problems" / "problems"
    if not problems.is_dir():
        with tarfile.open(fileobj=_sdist_member("resources/ur5/problems.tar.bz2"), mode="r:bz2") as tb:
            tb.extractall(_cache() / "ur5_problems", filter="data")
    return problems


def mbm_spherized_urdf() -> Path:
    """MBM's spheres-only collision model of the UR5 with its Robotiq 2F-85 (`ur5_spherized.urdf`, the model
    VAMP plans with; root `offset_link`, the world frame of the problems), taken from the sdist on first use.
    Usable as `robot.urdf` with `robot.model: ur5` for planning (no finger joints: it cannot run physics)."""
    path = _cache() / "ur5_spherized.urdf"
    if not path.is_file():
        write_atomic(path, _sdist_member("resources/ur5/ur5_spherized.urdf").read())
    return path


def _sdist_member(suffix: str) -> IO[bytes]:
    """A file of the vamp-planner sdist (downloaded into the cache by pip once), by the end of its path."""
    cache = _cache()
    sdists = sorted(cache.glob("vamp_planner-*.tar.gz"))
    if not sdists:
        cmd = [sys.executable, "-m", "pip", "download", "--no-deps", "--no-binary", "vamp-planner", SDIST]
        done = subprocess.run([*cmd, "-d", str(cache)], capture_output=True, text=True, check=False)
        sdists = sorted(cache.glob("vamp_planner-*.tar.gz"))
        if done.returncode != 0 or not sdists:
            why = (done.stderr.strip().splitlines() or ["no file"])[-1]
            raise ConfigError(f"cannot fetch MotionBenchMaker's problems ({SDIST} from the package index): {why}")
    with tarfile.open(sdists[-1]) as sd:
        member = next((m for m in sd.getmembers() if m.name.endswith(suffix)), None)
        inner = sd.extractfile(member) if member is not None else None
        if inner is None:
            raise ConfigError(f"{sdists[-1]} has no {suffix}")
        return io.BytesIO(inner.read())


def mbm_problem_set(name: str) -> Path:
    """The problem-set file of `ur5/<scene>` (a scene of SCENES), imported on first use into the cache."""
    robot, _, scene = name.partition("/")
    if robot != "ur5" or scene not in SCENES:
        raise ConfigError(f"unknown MotionBenchMaker set {name!r}; known: " + ", ".join(f"ur5/{s}" for s in SCENES))
    path = _cache() / "sets" / f"{scene}-{_SET_VERSION}.json"
    if not path.is_file():
        ps = problem_set_from_moveit_dir(mbm_problems_dir() / f"{scene}_ur5", robot="ur5", name=scene)
        tmp = save_problem_set(ps, path.with_suffix(f".{os.getpid()}.tmp"))
        os.replace(tmp, path)  # whole or not at all: two processes may import it at once
    return path
