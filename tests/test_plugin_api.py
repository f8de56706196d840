"""The public API for plugin authors (issue 17): built-in plugins import `twin` only through `twin.plugin`,
and every name `twin.plugin` promises resolves.

The scan is static (AST), so it also covers imports under `if TYPE_CHECKING:` and inside functions, and it
needs none of the optional backends (OMPL, CasADi, open3d) installed.
"""

from __future__ import annotations

import ast
import importlib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PLUGINS = ROOT / "plugins"
PLUGIN_FILES = sorted(PLUGINS.rglob("*.py"))


def _twin_imports(path: Path) -> list[tuple[int, str]]:
    """(line, what) for every import of `twin` or a `twin.*` module other than `twin.plugin` in `path`.

    `twin_ompl`, `twin_motion`, ... (a plugin's own package) are other top-level packages and are fine."""
    bad: list[tuple[int, str]] = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            bad.extend(
                (node.lineno, f"import {alias.name}")
                for alias in node.names
                if (alias.name == "twin" or alias.name.startswith("twin.")) and alias.name != "twin.plugin"
            )
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module is not None:
            mod = node.module
            if (mod == "twin" or mod.startswith("twin.")) and mod != "twin.plugin":
                names = ", ".join(a.name for a in node.names)
                bad.append((node.lineno, f"from {mod} import {names}"))
    return bad


def test_the_plugins_are_found() -> None:
    packages = {p.relative_to(PLUGINS).parts[0] for p in PLUGIN_FILES}
    assert {"twin_motion", "twin_ompl", "twin_nmpc", "twin_detectors"} <= packages


@pytest.mark.parametrize("path", PLUGIN_FILES, ids=[str(p.relative_to(PLUGINS)) for p in PLUGIN_FILES])
def test_plugins_import_twin_only_through_twin_plugin(path: Path) -> None:
    bad = _twin_imports(path)
    assert not bad, f"{path.relative_to(ROOT)} imports core modules; use `from twin.plugin import ...`:\n" + "\n".join(
        f"  line {line}: {what}" for line, what in bad
    )


def test_the_scan_catches_core_imports(tmp_path: Path) -> None:
    f = tmp_path / "p.py"
    f.write_text(
        "from twin import hookimpl\nimport twin.robot.kinematics\nfrom twin.plugin import URArm\n"
        "import twin_ompl.params\n"
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from twin.collision import PlanningScene\n"
        "def f():\n    from twin.types import Pose\n"
    )
    assert [line for line, _ in _twin_imports(f)] == [1, 2, 7, 9]


def test_every_exported_name_resolves() -> None:
    plugin = importlib.import_module("twin.plugin")
    assert len(plugin.__all__) == len(set(plugin.__all__)), "duplicate names in twin.plugin.__all__"
    assert set(plugin._LAZY) <= set(plugin.__all__), "a lazy name missing from twin.plugin.__all__"
    missing = []
    for name in plugin.__all__:
        try:
            getattr(plugin, name)
        except AttributeError as e:
            missing.append(f"{name}: {e}")
    assert not missing, missing
    assert sorted(dir(plugin)) == sorted(plugin.__all__)


def test_an_unknown_name_is_an_attribute_error() -> None:
    import twin.plugin

    with pytest.raises(AttributeError, match="no attribute 'DH_A'"):
        twin.plugin.DH_A  # noqa: B018 - an internal stays internal


def test_type_checkers_see_every_lazy_name() -> None:
    """Each lazily exported name is also imported, from the same module, under `if TYPE_CHECKING:`."""
    import twin.plugin

    tree = ast.parse((ROOT / "twin" / "plugin.py").read_text(encoding="utf-8"))
    seen: dict[str, str] = {}
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and isinstance(node.test, ast.Name) and node.test.id == "TYPE_CHECKING":
            for imp in ast.walk(node):
                if isinstance(imp, ast.ImportFrom) and imp.module is not None:
                    seen.update({a.asname or a.name: imp.module for a in imp.names})
    assert seen == twin.plugin._LAZY
