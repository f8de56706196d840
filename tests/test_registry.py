"""The plugin registry: lazy names, typed errors, duplicate detection, third-party plugins by entry point."""

from __future__ import annotations

import sys

import numpy as np
import pytest

from twin import hookimpl
from twin.errors import ConfigError, DependencyMissing, DuplicateNameError, UnknownNameError
from twin.registry import Availability, Kind, Registry, default_registry, plugin_manager


class _Echo:
    def __init__(self, params, context):
        self.params = params


class _PluginA:
    @hookimpl
    def twin_register_planners(self, registry):
        registry.add_planner("demo.echo", _Echo, description="test")
        registry.add_planner("demo.lazy", "twin_missing_backend_xyz:Planner", extra="demo")

    @hookimpl
    def twin_register_retimers(self, registry):
        registry.add_retimer("demo.retimer", _Echo)


class _PluginDup:
    @hookimpl
    def twin_register_planners(self, registry):
        registry.add_planner("demo.echo", _Echo)


class _Unbound:
    """A planner whose backend is installed but lacks what it needs; building it would be a failure here."""

    built = 0

    @classmethod
    def unavailable_reason(cls):
        return "the frob backend 1.0 does not bind Frobnicator (frob >= 2 does)"

    def __init__(self, params, context):
        type(self).built += 1


class _PluginAvailability:
    @hookimpl
    def twin_register_planners(self, registry):
        registry.add_planner("demo.ok", _Echo)
        registry.add_planner("demo.nobackend", "twin_missing_backend_xyz:Planner", extra="demo")
        registry.add_planner("demo.noclass", "twin.errors:NoSuchPlanner")
        registry.add_planner("demo.unbound", _Unbound)


def fresh(*plugins):
    return Registry.from_plugin_manager(plugin_manager(entry_points=False, plugins=plugins))


def test_names_and_kinds_from_an_inline_plugin():
    reg = fresh(_PluginA())
    assert reg.names() == ["demo.echo", "demo.lazy", "demo.retimer"]
    assert reg.names([Kind.RETIMER]) == ["demo.retimer"]
    assert reg.entry("demo.echo").kind is Kind.PLANNER


def test_registration_is_lazy_and_a_missing_backend_names_the_extra():
    reg = fresh(_PluginA())
    assert "twin_missing_backend_xyz" not in sys.modules
    with pytest.raises(DependencyMissing, match=r"twin\[demo\]"):
        reg.entry("demo.lazy").load()


def test_duplicate_name_is_an_immediate_error():
    with pytest.raises(DuplicateNameError, match=r"demo\.echo"):
        fresh(_PluginA(), _PluginDup())


def test_unknown_name_lists_what_exists_and_suggests():
    reg = fresh(_PluginA())
    with pytest.raises(UnknownNameError) as info:
        reg.entry("demo.ecoh", (Kind.PLANNER, Kind.RECEDING_HORIZON))
    msg = str(info.value)
    assert "Did you mean 'demo.echo'?" in msg and "demo.lazy" in msg
    assert isinstance(info.value, LookupError)


def test_a_planner_name_is_not_found_among_retimers():
    reg = fresh(_PluginA())
    with pytest.raises(UnknownNameError):
        reg.entry("demo.retimer", (Kind.PLANNER,))


def test_plugin_without_params_rejects_params():
    reg = fresh(_PluginA())
    with pytest.raises(ConfigError, match="takes no parameters"):
        reg.create("demo.echo", {"x": 1}, context=None, kinds=(Kind.PLANNER,))


def test_builtin_plugins_register_through_entry_points():
    names = default_registry().names()
    assert "ruckig.movej" in names and "toppra" in names


def test_importing_twin_loads_no_heavy_backend():
    import subprocess

    heavy = ("pybullet", "fcl", "toppra", "ruckig", "open3d", "casadi", "ompl")
    code = f"import sys, twin, twin.registry; print(sorted(m for m in {heavy!r} if m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout.strip()
    assert out == "[]"


def test_third_party_plugin_is_listed_and_plans_by_name_from_config(acme_plugin, tmp_path):
    from twin.config import load_config
    from twin.planning import limits_from_settings, plan
    from twin.types import JointGoal, MotionRequest, Status

    entry = default_registry().entry("acme.straight")
    assert entry.provider.startswith("acme-twin-plugin")
    cfg = tmp_path / "c.yaml"
    cfg.write_text("planners:\n  transfer:\n    name: acme.straight\n    params: {speed_fraction: 0.25}\n")
    s = load_config(cfg)
    start, goal = np.array([0.0, -1.6, 1.5, -1.5, -1.57, 0.0]), np.array([0.3, -1.4, 1.2, -1.4, -1.57, 0.2])
    req = MotionRequest(start, JointGoal(goal), limits_from_settings(s))
    res = plan(s, s.planners.transfer, req)
    assert res.status is Status.SUCCESS, res.reason
    np.testing.assert_allclose(res.trajectory.q[-1], goal, atol=1e-9)
    # a quarter of the velocity limit was asked for
    assert np.abs(res.trajectory.qd).max() <= 0.25 * s.robot.max_joint_vel + 1e-9
    with pytest.raises(ConfigError, match=r"acme.straight: parameter 'speed_fraction'"):
        plan(s, load_config(cfg, ["planners.transfer.params.speed_fraction=3"]).planners.transfer, req)
    with pytest.raises(ConfigError, match=r"unknown parameter 'sped'; allowed: speed_fraction"):
        plan(s, load_config(cfg, ["planners.transfer.params.sped=0.1"]).planners.transfer, req)


def test_every_hook_is_documented_in_the_readme():
    from pathlib import Path

    from twin.hookspecs import TwinSpec
    from twin.registry import HOOKS

    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    specs = {n for n in dir(TwinSpec) if n.startswith("twin_")}
    assert specs == set(HOOKS)
    for hook in specs:
        assert f"`{hook}(registry)`" in readme, f"{hook} is not documented in README.md"


def test_availability_is_known_without_building_a_planner():
    reg = fresh(_PluginAvailability())
    assert reg.entry("demo.ok").availability() == Availability(True)
    missing = reg.entry("demo.nobackend").availability()
    assert not missing and "twin_missing_backend_xyz" in missing.reason and "twin[demo]" in missing.reason
    noclass = reg.entry("demo.noclass").availability()
    assert not noclass and "NoSuchPlanner" in noclass.reason
    unbound = reg.entry("demo.unbound").availability()
    assert not unbound.available and "Frobnicator" in unbound.reason and "\n" not in unbound.reason
    assert _Unbound.built == 0
    # the factory applies the same check: an unavailable planner is a typed error, not a half-built object
    with pytest.raises(DependencyMissing, match="Frobnicator"):
        reg.planner("demo.unbound", {}, context=None)
    assert _Unbound.built == 0


def test_ompl_planners_the_bindings_lack_are_unavailable_with_the_reason():
    og = pytest.importorskip("ompl.geometric")
    reg = default_registry()
    assert reg.entry("ompl.rrtconnect").availability()
    for name, cls in (
        ("ompl.lazyprmstar", "LazyPRMstar"),
        ("ompl.bitrrt", "BiTRRT"),
        ("ompl.fmt", "FMT"),
        ("ompl.bfmt", "BFMT"),
    ):
        a = reg.entry(name).availability()
        assert a.available == hasattr(og, cls), (name, a)
        if not a:
            assert f"ompl.geometric.{cls}" in a.reason and "bindings" in a.reason


def test_parameter_errors_are_one_line_whatever_the_value():
    reg = fresh(_PluginA())
    from pydantic import BaseModel, ConfigDict

    class _WithParams:
        class Params(BaseModel):
            model_config = ConfigDict(extra="forbid")
            speed: float = 1.0

        def __init__(self, params, context):
            pass

    reg.add_planner("demo.params", _WithParams)
    for bad in ({"speed": "fast\nslow\r\n" * 50}, {"speed": {"a\nb": [1] * 1000}}, {"spe\ned": 1}, ["speed"]):
        with pytest.raises(ConfigError) as info:
            reg.planner("demo.params", bad, context=None)
        assert len(str(info.value).splitlines()) == 1 and len(str(info.value)) < 700, str(info.value)
