"""Configs: validated on load, `extends`, `--set` overrides, errors that name the dotted path."""

from __future__ import annotations

from pathlib import Path

import pytest

from twin.config import load_config, settings_from_dict
from twin.errors import ConfigError

ROOT = Path(__file__).resolve().parent.parent


def write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_shipped_configs_load():
    for name in ("robocup.yaml", "warehouse.yaml"):
        s = load_config(ROOT / "configs" / name)
        assert s.world.fixtures, name


def test_unknown_key_is_rejected_with_dotted_path(tmp_path):
    cfg = write(tmp_path / "c.yaml", "world:\n  objects:\n    regoin_x: [0, 1]\n")
    with pytest.raises(ConfigError, match=r"unknown key 'world\.objects\.regoin_x'"):
        load_config(cfg)


def test_bad_value_type_names_the_key(tmp_path):
    cfg = write(tmp_path / "c.yaml", "robot:\n  max_joint_vel: fast\n")
    with pytest.raises(ConfigError, match=r"robot\.max_joint_vel"):
        load_config(cfg)


def test_out_of_range_value_is_rejected():
    with pytest.raises(ConfigError, match=r"gripper\.force_n"):
        settings_from_dict({"gripper": {"force_n": 500}})


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError, match="not found"):
        load_config(tmp_path / "nope.yaml")


def test_invalid_yaml_is_a_config_error(tmp_path):
    cfg = write(tmp_path / "c.yaml", "robot: [unclosed\n")
    with pytest.raises(ConfigError, match="not valid YAML"):
        load_config(cfg)


def test_extends_merges_and_child_wins(tmp_path):
    write(tmp_path / "base.yaml", "seed: 3\nrobot:\n  max_joint_vel: 2.0\n  max_joint_acc: 5.0\n")
    child = write(tmp_path / "child.yaml", "extends: base.yaml\nrobot:\n  max_joint_acc: 7.0\n")
    s = load_config(child)
    assert (s.seed, s.robot.max_joint_vel, s.robot.max_joint_acc) == (3, 2.0, 7.0)


def test_extends_cycle_is_reported(tmp_path):
    write(tmp_path / "a.yaml", "extends: b.yaml\n")
    write(tmp_path / "b.yaml", "extends: a.yaml\n")
    with pytest.raises(ConfigError, match="cycle"):
        load_config(tmp_path / "a.yaml")


def test_overrides_apply_last_and_are_validated(tmp_path):
    cfg = write(tmp_path / "c.yaml", "seed: 1\n")
    s = load_config(cfg, ["seed=9", "world.objects.lying_probability=0.25", "planners.transfer.name=ruckig.movej"])
    assert s.seed == 9 and s.world.objects.lying_probability == 0.25
    assert s.planners.transfer.name == "ruckig.movej"
    with pytest.raises(ConfigError, match=r"unknown key 'robot\.nope'"):
        load_config(cfg, ["robot.nope=1"])
    with pytest.raises(ConfigError, match=r"key\.path=value"):
        load_config(cfg, ["seed"])
