"""The shape of the house, counted: what issue 40 ("One robot, built once") asks to change, measured the same
way before and after.

Static (an AST walk of `twin/` and `plugins/`, nothing imported):
- import cycles among twin's own modules (and the built-in plugins'), counting imports inside functions;
  imports under `if TYPE_CHECKING:` do not count (they never run). An edge `a -> b` is an import in `a` of
  module `b` (a `from b import name` whose name is a module is an edge to that module). Cycles are the
  strongly connected components of that graph with more than one module;
- import statements of twin's own modules inside functions (how many, in how many modules), and those of them
  without a reason: a function-local import of a twin module is kept only where a top-level one would load a
  heavy library, slow the CLI's start-up or close an import cycle, and says which on its own line(s) as
  `# lazy: REASON`, one of
      # lazy: pybullet                  (or fcl, cv2, scipy, open3d, matplotlib, ...: the heavy library it loads)
      # lazy: cli start-up              (`twin --help` and a usage error stay fast)
      # lazy: breaks the cycle a <-> b  (a top-level import would close the cycle)
  The modules that still have local imports without one are listed;
- import statements of `twin_nmpc` in `twin_croc`;
- the largest classes and functions (lines, decorators included), with the limits 400 and 120;
- module basenames used in more than one place for different modules (`__init__.py` aside);
- `.from_settings(` calls and `UR5e(`/`URArm(` constructions in the source.

Dynamic (one `twin run CONFIG --seed N` in this process, with counters wrapped around the functions):
URDF files parsed for a robot model (`twin.robot.urdf_model._parse`), arms built (`URArm.__init__`), plugin contexts
made (`twin.planning.make_context`).

    .venv/bin/python bench/bench_house.py                     # static and one robocup run
    .venv/bin/python bench/bench_house.py --static            # no run
    .venv/bin/python bench/bench_house.py --config configs/warehouse.yaml --seed 1
"""

from __future__ import annotations

import argparse
import ast
import json
import re
import sys
from collections import Counter, defaultdict
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
CLASS_LIMIT, FUNCTION_LIMIT = 400, 120
LAZY_REASON = re.compile(r"#\s*lazy:\s*\S")  # the reason a function-local import gives for staying local


def _modules() -> dict[str, Path]:
    """Dotted module name -> file, for twin/ and every built-in plugin package under plugins/."""
    out: dict[str, Path] = {}
    for base, prefix in ((ROOT, "twin"), (ROOT / "plugins", None)):
        top = base / prefix if prefix else base
        for path in sorted(top.rglob("*.py")):
            rel = path.relative_to(base).with_suffix("")
            parts = list(rel.parts)
            if "__pycache__" in parts or (prefix is None and len(parts) < 2):
                continue
            if parts[-1] == "__init__":
                parts = parts[:-1]
            out[".".join(parts)] = path
    return out


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (
        isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING"
    )


def _imports(module: str, path: Path, known: set[str]) -> list[tuple[str, bool, int, bool]]:
    """(imported internal module, inside a function, line, gives a `# lazy:` reason) for every import that runs."""
    text = path.read_text()
    lines = text.splitlines()
    tree = ast.parse(text, str(path))
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    found: list[tuple[str, bool, int, bool]] = []

    def reasoned(node: ast.stmt) -> bool:
        span = lines[node.lineno - 1 : node.end_lineno or node.lineno]
        return any(LAZY_REASON.search(line) for line in span)

    def resolve(name: str) -> str | None:
        while name and name not in known:
            name = name.rpartition(".")[0]
        return name or None

    def visit(node: ast.AST, in_function: bool) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and _is_type_checking(child):
                for sub in child.orelse:
                    visit(sub, in_function)
                continue
            inner = in_function or isinstance(child, ast.FunctionDef | ast.AsyncFunctionDef | ast.Lambda)
            if isinstance(child, ast.Import):
                for alias in child.names:
                    target = resolve(alias.name)
                    if target is not None:
                        found.append((target, in_function, child.lineno, reasoned(child)))
            elif isinstance(child, ast.ImportFrom):
                if child.level:
                    base = package.split(".")
                    base = base[: len(base) - (child.level - 1)] if child.level > 1 else base
                    source = ".".join([*base, child.module] if child.module else base)
                else:
                    source = child.module or ""
                for alias in child.names:
                    target = resolve(f"{source}.{alias.name}") if f"{source}.{alias.name}" in known else None
                    target = target or resolve(source)
                    if target is not None:
                        found.append((target, in_function, child.lineno, reasoned(child)))
            visit(child, inner)

    visit(tree, False)
    return [(t, f, n, r) for t, f, n, r in found if t != module]


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    on: set[str] = set()
    stack: list[str] = []
    out: list[list[str]] = []
    counter = 0
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = counter
        counter += 1
        stack.append(root)
        on.add(root)
        while work:
            v, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter
                    counter += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(sorted(edges.get(w, ())))))
                    break
                if w in on:
                    low[v] = min(low[v], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[v])
                if low[v] == index[v]:
                    comp = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        comp.append(w)
                        if w == v:
                            break
                    if len(comp) > 1:
                        out.append(sorted(comp))
    return sorted(out, key=len, reverse=True)


def _sizes(modules: dict[str, Path]) -> tuple[list[tuple[int, str]], list[tuple[int, str]]]:
    """(lines, name) of every class and every function, largest first."""
    classes, functions = [], []
    for module, path in modules.items():
        tree = ast.parse(path.read_text(), str(path))
        for node in ast.walk(tree):
            if isinstance(node, ast.ClassDef | ast.FunctionDef | ast.AsyncFunctionDef):
                start = min([node.lineno, *(d.lineno for d in node.decorator_list)])
                lines = (node.end_lineno or node.lineno) - start + 1
                (classes if isinstance(node, ast.ClassDef) else functions).append((lines, f"{module}.{node.name}"))
    return sorted(classes, reverse=True), sorted(functions, reverse=True)


def static_report() -> dict[str, Any]:
    modules = _modules()
    known = set(modules)
    edges: dict[str, set[str]] = defaultdict(set)
    local: dict[str, set[int]] = defaultdict(set)  # module: lines of import statements inside functions
    unreasoned: dict[str, set[int]] = defaultdict(set)  # of them, those without a `# lazy:` reason
    croc_from_nmpc: set[tuple[str, int]] = set()
    for module, path in modules.items():
        edges.setdefault(module, set())
        for target, in_function, line, reason in _imports(module, path, known):
            edges[module].add(target)
            # importing a.b.c first runs a and a.b (their __init__): an edge to each, but not to the importer's
            # own packages (already being initialised when one of their modules imports a sibling)
            parts = target.split(".")
            for k in range(1, len(parts)):
                parent = ".".join(parts[:k])
                if parent in known and not (module == parent or module.startswith(parent + ".")):
                    edges[module].add(parent)
            if in_function:
                local[module].add(line)
                if not reason:
                    unreasoned[module].add(line)
            if module.startswith("twin_croc") and target.startswith("twin_nmpc"):
                croc_from_nmpc.add((module, line))
    cycles = _cycles(edges)
    classes, functions = _sizes(modules)
    names: dict[str, list[str]] = defaultdict(list)
    for module, path in modules.items():
        if path.name != "__init__.py":
            names[path.name].append(module)
    source = "\n".join(p.read_text() for p in modules.values())
    return {
        "modules": len(modules),
        "import_edges": sum(len(v) for v in edges.values()),
        "cycles": [", ".join(c) for c in cycles],
        "modules_in_cycles": sum(len(c) for c in cycles),
        "function_local_import_statements": sum(len(v) for v in local.values()),
        "  of_them_in_twin": sum(len(v) for m, v in local.items() if m.split(".")[0] == "twin"),
        "modules_with_function_local_imports": len(local),
        "function_local_imports_without_reason": sum(len(v) for v in unreasoned.values()),
        "modules_with_local_imports_without_reason": [
            f"{m}: {len(v)}" for m, v in sorted(unreasoned.items(), key=lambda kv: (-len(kv[1]), kv[0]))
        ],
        "twin_croc_import_statements_of_twin_nmpc": len(croc_from_nmpc),
        "classes_over_limit": [f"{n} lines {name}" for n, name in classes if n > CLASS_LIMIT],
        "functions_over_limit": [f"{n} lines {name}" for n, name in functions if n > FUNCTION_LIMIT],
        "largest_class": f"{classes[0][0]} lines {classes[0][1]}",
        "largest_function": f"{functions[0][0]} lines {functions[0][1]}",
        "repeated_basenames": {k: v for k, v in sorted(names.items()) if len(v) > 1},
        "from_settings_calls": source.count(".from_settings("),
        "arm_constructions_in_source": source.count("UR5e(") + source.count("URArm("),
    }


def run_report(config: str, seed: int) -> dict[str, Any]:
    """Counters around one `twin run` of `config` in this process (`counted_run`)."""
    from twin.config import load_config

    return {"config": config, **counted_run(load_config(config), seed)}


def counted_run(settings: Any, seed: int) -> dict[str, Any]:
    """Counters around one `run_task(settings, seed=seed)` in this process: URDF files parsed (by file), arms
    built (`URArm`), robots built (`Robot.from_settings`) and plugin contexts made (`PluginContext`, however
    it is made)."""
    import twin.registry as registry
    import twin.robot.kinematics as kinematics
    import twin.robot.urdf_model as urdf_model
    from twin.robot import Robot
    from twin.tasks import run_task

    counts: Counter[str] = Counter()
    parse, arm_init, context_init = urdf_model._parse, kinematics.URArm.__init__, registry.PluginContext.__init__
    robot_from = Robot.__dict__["from_settings"]

    def counted_parse(source: Any, text: Any = None) -> Any:
        counts["urdf_parses"] += 1
        counts[f"urdf_parses:{Path(str(source)).name if text is None else '<text>'}"] += 1
        return parse(source, text)

    def counted_arm(self: Any, *args: Any, **kwargs: Any) -> None:
        counts["arms_built"] += 1
        arm_init(self, *args, **kwargs)

    def counted_context(self: Any, *args: Any, **kwargs: Any) -> None:
        counts["plugin_contexts"] += 1
        context_init(self, *args, **kwargs)

    def counted_robot(cls: Any, settings: Any) -> Any:
        counts["robots_built"] += 1
        return robot_from.__func__(cls, settings)

    urdf_model._parse = counted_parse  # type: ignore[assignment]
    kinematics.URArm.__init__ = counted_arm  # type: ignore[method-assign]
    registry.PluginContext.__init__ = counted_context  # type: ignore[method-assign]
    Robot.from_settings = classmethod(counted_robot)  # type: ignore[assignment,method-assign]
    try:
        summary = run_task(settings, seed=seed)
    finally:
        urdf_model._parse, kinematics.URArm.__init__ = parse, arm_init  # type: ignore[method-assign]
        registry.PluginContext.__init__ = context_init  # type: ignore[method-assign]
        Robot.from_settings = robot_from  # type: ignore[method-assign]
    placed = sum(o.placed for o in summary.objects)
    done = f"{placed}/{len(summary.objects)}"
    return {"seed": seed, "placed": done, **dict(sorted(counts.items()))}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--static", action="store_true", help="the source only, no run")
    ap.add_argument("--config", default="configs/robocup.yaml")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--json", help="also write the numbers here")
    args = ap.parse_args(argv)
    sys.path[:0] = [str(ROOT), str(ROOT / "plugins")]
    report: dict[str, Any] = {"static": static_report()}
    if not args.static:
        report["run"] = run_report(args.config, args.seed)
    for section, values in report.items():
        print(f"[{section}]")
        for key, value in values.items():
            if isinstance(value, dict):
                print(f"  {key}:")
                for k, v in value.items():
                    print(f"    {k}: {', '.join(v) if isinstance(v, list) else v}")
            elif isinstance(value, list):
                print(f"  {key}: {len(value)}")
                for v in value if key == "modules_with_local_imports_without_reason" else value[:12]:
                    print(f"    {v}")
            else:
                print(f"  {key}: {value}")
    if args.json:
        Path(args.json).write_text(json.dumps(report, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
