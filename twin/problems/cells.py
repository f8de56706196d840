"""The cell a motion query is planned in, built once per process: `QueryCell`, `cell_for`.

Motion queries (a `twin compare` run, a problem set's export) need a scene config's static cell: its
settings without loose objects, the FCL planning scene, the kinematics and, once a run executes, a
PyBullet world. Building the scene and the world costs more than a typical plan, so a process builds
each cell on first use and reuses it. Below `twin.compare` (its worker takes cells from here), so that
exporting problems never reaches up into the comparison machinery.

Not the tasks' `Cell` (`twin.tasks.cell`), which runs a whole sorting task with perception and grasping.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from twin.config import load_config
from twin.problems.problem_set import load_problem_set
from twin.problems.world import check_robot, planning_scene, settings_for
from twin.robot import Robot

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.collision.scene import UnknownFixtures
    from twin.config import Settings
    from twin.problems.problem_set import ProblemSet
    from twin.robot.kinematics import URArm
    from twin.world import World

__all__ = ["QueryCell", "cell_for"]


@dataclass
class QueryCell:
    """A scene config's static cell for motion queries, built once per process: settings without loose
    objects, the robot (built once for the cell), its FCL scene, and (once a query is executed in physics) the
    PyBullet world."""

    settings: Settings
    robot: Robot
    scene: PlanningScene
    world: World | None = None
    key: tuple[Any, ...] = ()  # its key in _CELLS

    @property
    def kin(self) -> URArm:
        """The robot's arm."""
        return self.robot.arm


_CellKey = tuple[str, tuple[str, ...], str, str | None, int | None]
_CELLS: dict[_CellKey, QueryCell] = {}
_OWN_WORLD_CELLS = 2  # cells of problems with their own world kept at once (each may hold a PyBullet world)
_SETS: dict[str, ProblemSet] = {}  # problem sets read in this process, by path
# what the cells of one problem set share (MotionBenchMaker's 700 problems each have a world of their own, and
# reading the config again and building the robot again cost more than planning a problem): the config as
# read, and the robot, per robot model and URDF
_CONFIGS: dict[tuple[str, tuple[str, ...]], Settings] = {}
_ROBOTS: dict[tuple[str, str], Robot] = {}


def _config(config: str, overrides: tuple[str, ...]) -> Settings:
    s = _CONFIGS.get((config, overrides))
    if s is None:
        s = _CONFIGS[(config, overrides)] = load_config(config, overrides)
    return s


def _robot(settings: Settings) -> Robot:
    key = (settings.robot.model, str(settings.resolve(settings.robot.urdf)))
    robot = _ROBOTS.get(key)
    if robot is None:
        robot = _ROBOTS[key] = Robot.from_settings(settings)
    return robot


def _problem_set(path: str) -> ProblemSet:
    ps = _SETS.get(path)
    if ps is None:
        ps = _SETS[path] = load_problem_set(path)
    return ps


def _keep(key: _CellKey, cell: QueryCell) -> QueryCell:
    """Remember a cell; of the cells of problems with their own world only the latest few stay (a set
    of 700 worlds would otherwise hold 700 scenes and PyBullet worlds)."""
    cell.key = key
    if key[4] is not None:
        own = [k for k in _CELLS if k[4] is not None]
        for old in own[: max(0, len(own) - _OWN_WORLD_CELLS + 1)]:
            gone = _CELLS.pop(old)
            if gone.world is not None:
                gone.world.close()
    _CELLS[key] = cell
    return cell


def cell_for(
    config: str,
    overrides: tuple[str, ...],
    unknown_fixtures: UnknownFixtures,
    problems: str | None = None,
    problem_index: int | None = None,
) -> QueryCell:
    """The static cell of a scene config (built on first use in this process, then reused); with
    `problems`, the world of that problem set in the config's robot cell (`twin.problems.world`): the
    world of problem `problem_index` when it has its own (format version 2), else the set's."""
    own = None
    if problems is not None and problem_index is not None and _problem_set(problems).problems[problem_index].world:
        own = problem_index
    key: _CellKey = (config, overrides, unknown_fixtures, problems, own)
    cell = _CELLS.get(key)
    if cell is None and problems is not None:
        ps = _problem_set(problems)
        s = _config(config, overrides)
        check_robot(ps, s, source=problems)
        world = ps.world_of(own) if own is not None else None
        s = settings_for(ps, s, world=world)
        robot = _robot(s)
        cell = _keep(key, QueryCell(s, robot, planning_scene(ps, s, world=world, robot=robot)))
    if cell is None:
        from twin.collision import PlanningScene  # lazy: fcl

        s = _config(config, overrides)
        # loose objects are unknown to the planning scene; leaving them out of the physics as well keeps
        # "contacts seen in physics" a measure of the trajectory, not of objects the planner never saw
        no_objects = s.world.objects.model_copy(update={"items": []})
        s = s.model_copy(update={"world": s.world.model_copy(update={"objects": no_objects})})
        # no perception step in a motion query: with "box", fixtures marked `known: false` are in the scene
        # as a perfect detector reports them (the default scene of `PlanningScene.from_settings`)
        robot = _robot(s)
        scene = PlanningScene.from_settings(s, robot=robot, unknown_fixtures=unknown_fixtures)
        cell = _keep(key, QueryCell(s, robot, scene))
    return cell
