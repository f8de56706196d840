"""constraints.txt, the versions setup.sh installs: it pins every distribution twin needs at run time and in
its tests, recursively (twin's dependencies, the extras `all` and `test`, and what those require in turn),
each pin is one valid `name==version` that satisfies what requires it, and setup.sh installs with it unless
told to resolve the newest releases."""

from __future__ import annotations

import importlib.metadata
import os
import subprocess
import tomllib
from pathlib import Path

from packaging.requirements import InvalidRequirement, Requirement
from packaging.utils import canonicalize_name
from packaging.version import InvalidVersion, Version

ROOT = Path(__file__).resolve().parent.parent
LOCK = ROOT / "constraints.txt"
EXTRAS = ("all", "test")  # what setup.sh installs: `pip install -e '.[all,test]'`


def pins() -> dict[str, Version]:
    """The pins of constraints.txt by canonical name; every other line must be a comment or blank."""
    out: dict[str, Version] = {}
    for n, line in enumerate(LOCK.read_text().splitlines(), 1):
        text = line.strip()
        if not text or text.startswith("#"):
            continue
        try:
            req = Requirement(text)
        except InvalidRequirement as e:
            raise AssertionError(f"constraints.txt:{n}: {text!r} is not a requirement: {e}") from None
        specs = list(req.specifier)
        assert len(specs) == 1 and specs[0].operator == "==" and "*" not in specs[0].version, (
            f"constraints.txt:{n}: {text!r} is not one exact pin `name==version`"
        )
        assert not req.extras and req.marker is None and req.url is None, f"constraints.txt:{n}: {text!r}"
        assert text == f"{req.name}=={specs[0].version}", f"constraints.txt:{n}: {text!r} has extra characters"
        try:
            version = Version(specs[0].version)
        except InvalidVersion:
            raise AssertionError(f"constraints.txt:{n}: {specs[0].version!r} is not a version") from None
        key = canonicalize_name(req.name)
        assert key not in out, f"constraints.txt:{n}: {req.name} is pinned twice"
        out[key] = version
    return out


def twin_requirements() -> list[Requirement]:
    """twin's own requirements from pyproject.toml (the source, not possibly stale egg-info): its
    dependencies and the extras setup.sh installs, with `twin[...]` self-references expanded."""
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras: dict[str, list[str]] = project["optional-dependencies"]
    out = [Requirement(r) for r in project["dependencies"]]
    todo, seen = list(EXTRAS), set()
    while todo:
        extra = todo.pop()
        if extra in seen:
            continue
        seen.add(extra)
        for text in extras[extra]:
            req = Requirement(text)
            if canonicalize_name(req.name) == "twin":
                todo.extend(req.extras)
            else:
                out.append(req)
    return out


def _applies(req: Requirement, extras: frozenset[str]) -> bool:
    """Whether a requirement applies here, installed with `extras` (its marker evaluated on this machine)."""
    if req.marker is None:
        return True
    return any(req.marker.evaluate({"extra": e}) for e in (extras or {""}))


def required_closure() -> dict[str, list[Requirement]]:
    """Every distribution twin needs here, recursively, by canonical name -> the requirements on it (from
    twin's pyproject and from the installed distributions' metadata, markers evaluated)."""
    needed: dict[str, list[Requirement]] = {}
    visited: set[tuple[str, frozenset[str]]] = set()
    todo: list[Requirement] = [r for r in twin_requirements() if _applies(r, frozenset())]
    while todo:
        req = todo.pop()
        key = canonicalize_name(req.name)
        needed.setdefault(key, []).append(req)
        node = (key, frozenset(req.extras))
        if node in visited:
            continue
        visited.add(node)
        try:
            dist = importlib.metadata.distribution(req.name)
        except importlib.metadata.PackageNotFoundError:
            raise AssertionError(f"{req} is required but not installed: run ./setup.sh") from None
        todo += [r for text in dist.requires or [] if _applies(r := Requirement(text), frozenset(req.extras))]
    return needed


def test_every_line_of_the_lockfile_is_one_exact_pin() -> None:
    assert len(pins()) > 20  # the file parses, and it is the whole set, not a handful


def test_every_dependency_of_twin_is_pinned_recursively_at_a_version_that_satisfies_it() -> None:
    locked = pins()
    needed = required_closure()
    # the walk reaches well past twin's direct requirements (numpy, pybullet, ... and theirs)
    assert {"numpy", "scipy", "pybullet", "ompl", "casadi", "open3d", "ray", "pytest", "setuptools"} <= set(needed)
    missing = sorted(k for k in needed if k not in locked and k != "twin")
    assert not missing, f"required but not pinned in constraints.txt: {missing}"
    unsatisfied = [
        f"{k}=={locked[k]} does not satisfy {r}"
        for k, reqs in needed.items()
        if k in locked
        for r in reqs
        if not r.specifier.contains(locked[k], prereleases=True)
    ]
    assert not unsatisfied, unsatisfied


def test_setup_installs_with_the_lockfile_unless_told_otherwise() -> None:
    text = (ROOT / "setup.sh").read_text()
    assert "-c constraints.txt" in text and "TWIN_RESOLVE" in text
    # an unknown mode is refused before anything is installed
    env = {**os.environ, "TWIN_RESOLVE": "newest-please"}
    r = subprocess.run(
        ["bash", str(ROOT / "setup.sh")], env=env, capture_output=True, text=True, timeout=60, check=False
    )
    assert r.returncode == 2 and "TWIN_RESOLVE must be 'locked'" in r.stderr, (r.stdout, r.stderr)
