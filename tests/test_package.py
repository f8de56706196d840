"""twin as an installed package: shipped configs load by name (also through `extends`), paths in a config
are found next to it or in the shipped data from any working directory, generated files go to the cache
directory and never into the checkout, and a wheel installed elsewhere runs `twin run robocup` and
`twin compare compare-smoke` from an empty directory."""

from __future__ import annotations

import importlib.metadata
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from twin.compare import load_compare_config
from twin.config import load_config
from twin.errors import ConfigError
from twin.resources import cache_dir, config_names, packaged_path

ROOT = Path(__file__).resolve().parent.parent


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)
    return path


def checkout_files() -> dict[str, float]:
    """Every file under the checkout's data directories (where generated files used to go), with its
    modification time."""
    return {str(p): p.stat().st_mtime for d in ("urdf", "configs") for p in (ROOT / d).rglob("*") if p.is_file()}


# ---- configs by name ------------------------------------------------------------------------------
def test_shipped_configs_load_by_name_from_any_directory(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    assert {"robocup", "warehouse", "compare", "compare-smoke"} <= set(config_names())
    by_path = load_config(ROOT / "configs" / "robocup.yaml")
    for ref in ("robocup", "robocup.yaml"):
        s = load_config(ref)
        assert s.model_dump() == by_path.model_dump()
        assert s.resolve(s.robot.urdf).is_file()


def test_extends_names_a_shipped_config(tmp_path):
    for parent in ("robocup", "robocup.yaml"):
        cfg = write(tmp_path / "mine" / f"{parent}-child.yaml", f"extends: {parent}\nseed: 7\n")
        s = load_config(cfg, ["world.objects.lying_probability=0.0"])
        assert (s.name, s.seed, s.world.objects.lying_probability) == ("robocup", 7, 0.0)
        assert [f.name for f in s.world.fixtures] == [f.name for f in load_config("robocup").world.fixtures]


def test_a_file_beside_the_config_wins_over_the_shipped_name(tmp_path):
    write(tmp_path / "robocup.yaml", "name: local\n")
    child = write(tmp_path / "child.yaml", "extends: robocup.yaml\nseed: 2\n")
    assert load_config(child).name == "local"


def test_an_unknown_name_is_one_line_listing_the_shipped_configs(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ConfigError) as e:
        load_config("robocupp")
    msg = str(e.value)
    assert "\n" not in msg and "config file not found" in msg and "Did you mean 'robocup'" in msg
    for name in ("compare-smoke", "robocup", "warehouse"):
        assert name in msg
    cfg = write(tmp_path / "c.yaml", "extends: nope\n")
    with pytest.raises(ConfigError, match=r"c\.yaml: extends: config file not found: 'nope'.*Shipped configs: ") as e:
        load_config(cfg)
    assert "\n" not in str(e.value)
    with pytest.raises(ConfigError, match="config file not found"):  # a path is a path: no name lookup
        load_config("configs/robocup.yaml")


def test_compare_configs_and_their_scenes_load_by_name(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    spec = load_compare_config("compare-smoke")
    assert spec.name == "compare-smoke"
    for sc in spec.scenarios:
        assert Path(sc.scene).is_file() and Path(sc.scene).name in ("warehouse.yaml", "robocup.yaml")
    mine = write(
        tmp_path / "cmp.yaml",
        "name: x\nseeds: [0]\nplanners: [ruckig.movej]\nscenarios:\n"
        "  - {name: w, scene: warehouse, random: {count: 1, goal: joint}}\n",
    )
    assert Path(load_compare_config(mine).scenarios[0].scene).name == "warehouse.yaml"


# ---- paths inside a config -----------------------------------------------------------------------
def test_urdfs_resolve_next_to_the_config_then_in_the_shipped_data(tmp_path, monkeypatch):
    d = tmp_path / "cell"
    (tmp_path / "elsewhere").mkdir()
    monkeypatch.chdir(tmp_path / "elsewhere")
    table = write(d / "urdf" / "table.urdf", (ROOT / "urdf" / "table.urdf").read_text())
    write(d / "parts" / "bin.urdf", (ROOT / "urdf" / "bin_blue.urdf").read_text())
    base = write(
        d / "parts" / "base.yaml",
        "world:\n  fixtures:\n    - {name: table, urdf: urdf/table.urdf}\n"
        "    - {name: bin, urdf: bin.urdf, position: [-0.3, 0.4, 0]}\n",
    )
    cfg = write(d / "cell.yaml", f"extends: {base.relative_to(d)}\nrobot: {{urdf: urdf/ur5e.urdf}}\n")
    s = load_config(cfg)
    assert s.resolve("urdf/table.urdf") == table  # beside the config: it wins over the shipped one
    assert s.resolve("bin.urdf") == d / "parts" / "bin.urdf"  # beside the file that extends
    assert s.resolve("urdf/ur5e.urdf") == packaged_path("urdf/ur5e.urdf")  # shipped
    assert s.resolve(str(table)) == table  # absolute: as it is
    with pytest.raises(ConfigError, match=r"robot\.urdf: 'urdf/nope\.urdf' not found"):
        load_config(cfg, ["robot.urdf=urdf/nope.urdf"])
    # shipped data is not a way out of the package
    assert packaged_path("../pyproject.toml") is None and packaged_path("urdf/../../README.md") is None


# ---- the cache directory -------------------------------------------------------------------------
def test_generated_files_go_to_the_cache_never_into_the_checkout(tmp_path, monkeypatch):
    from twin.world import World

    monkeypatch.setenv("TWIN_CACHE", str(tmp_path / "cache"))
    before = checkout_files()
    settings = load_config("warehouse", ["aruco.id=7"])
    with World(settings, 0, renderer="tiny") as w:
        assert w.object_ids()
    made = sorted(p.name for p in (tmp_path / "cache" / "generated").iterdir())
    assert made == [f"aruco_DICT_4X4_50_7_v1.{ext}" for ext in ("mtl", "obj", "png")]
    assert checkout_files() == before


def test_cache_dir_follows_xdg_and_falls_back_when_not_writable(tmp_path, monkeypatch):
    monkeypatch.delenv("TWIN_CACHE", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_dir("generated") == tmp_path / "xdg" / "twin" / "generated"
    blocker = write(tmp_path / "a-file", "")
    monkeypatch.setenv("TWIN_CACHE", str(blocker))  # a file where the directory should be: not writable
    fallback = cache_dir("generated")
    assert fallback.is_dir() and not str(fallback).startswith(str(blocker))


# ---- a wheel installed elsewhere -------------------------------------------------------------------
def _build_wheel(tmp: Path) -> Path:
    """A wheel of a copy of the checkout (so the build writes nothing into it)."""
    src = tmp / "src"
    src.mkdir()
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(ROOT / name, src / name)
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info", "generated", "build")
    for name in ("twin", "plugins", "urdf", "configs"):
        shutil.copytree(ROOT / name, src / name, symlinks=True, ignore=ignore)
    # without isolation when this environment's setuptools can build the project (no download needed)
    new_setuptools = int(importlib.metadata.version("setuptools").split(".")[0]) >= 77
    cmd = [sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "-q", "-w", str(tmp / "dist")]
    r = subprocess.run(
        cmd + (["--no-build-isolation"] if new_setuptools else []),
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    (wheel,) = (tmp / "dist").glob("twin-*.whl")
    return wheel


def test_an_installed_wheel_runs_from_an_empty_directory(tmp_path):
    if subprocess.run([sys.executable, "-m", "pip", "--version"], capture_output=True, check=False).returncode != 0:
        pytest.skip("pip is not available in this environment")
    wheel = _build_wheel(tmp_path)
    target = tmp_path / "site"
    r = subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "-q", "--target", str(target), str(wheel)],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert r.returncode == 0, r.stderr[-2000:]
    work = tmp_path / "empty"
    work.mkdir()
    # the target shadows the editable install; the dependencies come from this environment
    env = dict(os.environ, PYTHONPATH=str(target), TWIN_CACHE=str(tmp_path / "cache"))

    def run(*args: str) -> subprocess.CompletedProcess:
        return subprocess.run(
            [sys.executable, *args], capture_output=True, text=True, cwd=work, env=env, timeout=300, check=False
        )

    r = run(
        "-c",
        "import twin, twin_motion; from twin.config import load_config; s = load_config('robocup'); "
        "print(twin.__file__); print(twin_motion.__file__); print(s.resolve(s.robot.urdf))",
    )
    assert r.returncode == 0, r.stderr
    for line in r.stdout.split():
        assert Path(line).is_relative_to(target), r.stdout

    before = checkout_files()
    r = run("-m", "twin", "run", "robocup", "--seed", "1", "--json", "out.json")
    assert r.returncode == 0, r.stdout[-2000:] + r.stderr[-2000:]
    result = json.loads((work / "out.json").read_text())
    assert result["config"] == "robocup" and result["seed"] == 1
    assert len(result["objects"]) == 8 and any(o["placed"] for o in result["objects"])
    assert sorted(p.suffix for p in (tmp_path / "cache" / "generated").iterdir()) == [".mtl", ".obj", ".png"]

    r = run("-m", "twin", "compare", "compare-smoke", "--dry-run")
    assert r.returncode == 0, r.stderr
    assert "runs" in r.stdout and "warehouse-blocked" in r.stdout and "robocup" in r.stdout
    assert checkout_files() == before
    assert sorted(p.name for p in work.iterdir()) == ["out.json"]
