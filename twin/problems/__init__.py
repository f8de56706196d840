"""Problem sets: motion problems written out for other tools and read back in (`twin problems`).

    from twin.problems import export_problem_set, load_problem_set, save_problem_set
    ps = export_problem_set("robocup", count=10, seed=0, random={"straight": "blocked"})
    save_problem_set(ps, "robocup-blocked.json")

Modules: `model` (the file format, validated; its JSON Schema), `queries` (problems <-> compare queries),
`world` (a problem set's world as twin's fixtures and planning scene), `cells` (a scene config's cell
for motion queries, built once per process), `sampling` (seeded random queries in a cell), `export`
(from a scene config), `moveit` (from MoveIt PlanningScene / MotionPlanRequest YAML:
`problem_set_from_moveit`).
"""

from __future__ import annotations

from typing import Any

from twin.problems.problem_set import (
    FORMAT,
    VERSION,
    Problem,
    ProblemSet,
    json_schema,
    load_problem_set,
    problem_set_from_dict,
    save_problem_set,
)

__all__ = [
    "FORMAT",
    "VERSION",
    "Problem",
    "ProblemSet",
    "export_problem_set",
    "json_schema",
    "load_problem_set",
    "problem_set_from_dict",
    "problem_set_from_moveit",
    "problem_set_from_moveit_dir",
    "save_problem_set",
]


def __getattr__(name: str) -> Any:
    # the exporters load the robot model, the query cells and the sampler (14 more twin modules, no heavy
    # library: FCL and PyBullet load only when a cell is built), so reading a problem file does not
    if name == "export_problem_set":
        from twin.problems.export import export_problem_set  # lazy: import twin.problems stays light

        return export_problem_set
    if name in ("problem_set_from_moveit", "problem_set_from_moveit_dir"):
        from twin.problems import moveit  # lazy: import twin.problems stays light

        return getattr(moveit, name)
    raise AttributeError(f"module 'twin.problems' has no attribute {name!r}")
