"""Task runs (`twin run`): the reference systems end to end, perception to placed object.

`run_task(settings, seed=..., planner=...)` builds the world, runs the configured task and judges every
object by physics ground truth at the end. Tasks are plugins (hook `twin_register_tasks`), found by the
name in `settings.task.kind`; the built-in ones are `robocup` and `warehouse` (`twin.tasks.builtin`).

The tasks decide with what a real cell senses (camera frames, joint encoders, the gripper's finger
position); the simulator's ground truth is read only by the judging: `twin.tasks.judge` and each task's
referee (`twin.tasks.robocup.judge`, `twin.tasks.warehouse.judge`: verdicts, metrics, the labelled oracle
detector's hand-off).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from pydantic import BaseModel

from twin.config import with_planner
from twin.timing import collect_timings, stage
from twin.types import CalibrationOutcome, Landmark, RunSummary

if TYPE_CHECKING:
    from twin.config import PlannerBlock, Settings
    from twin.planning import CheckedPlanner
    from twin.registry import PluginContext

__all__ = ["make_task", "ran_block", "run_task", "task_landmarks"]

log = logging.getLogger("twin")


def make_task(settings: Settings, context: PluginContext | None = None) -> Any:
    """The task plugin named by `settings.task.kind`, built with its validated `task.params`; an unknown
    name raises UnknownNameError listing the registered tasks."""
    from twin.planning import make_context  # lazy: cli start-up (twin --help imports twin.tasks)

    context = context or make_context(settings)
    return context.registry.task(settings.task.kind, settings.task.params, context)


def task_landmarks(settings: Settings) -> list[Landmark]:
    """The places the configured task puts things that no body marks (its plugin's optional
    `landmarks()`: the warehouse's drop zones), for pictures of the cell; none for a task that has none."""
    return _landmarks_of(make_task(settings))


def _landmarks_of(task: Any) -> list[Landmark]:
    fn = getattr(task, "landmarks", None)
    return list(fn()) if callable(fn) else []


def _to_both(first: Callable[[str], None], second: Callable[[str], None] | None) -> Callable[[str], None]:
    def both(text: str) -> None:
        first(text)
        if second is not None:
            second(text)

    return both


def run_task(
    settings: Settings,
    *,
    seed: int | None = None,
    planner: str | None = None,
    gui: bool = False,
    record: str | None = None,
    record_speed: float = 1.0,
    rerun: str | None = None,
    rerun_serve: bool = False,
    on_stage: Callable[[str], None] | None = None,
    on_objects: Callable[[int, int], None] | None = None,
    config_name: str = "",
) -> RunSummary:
    """Run the configured task once on scene `seed` (default: the config's); `planner` replaces the
    transfer planner; `record` writes a video (.mp4/.gif) from the overview camera, played `record_speed`
    times faster than the run (`twin.recording.Recorder`), `rerun` a Rerun
    recording (.rrd: `twin.rerun_log`), `rerun_serve` serves it live in Rerun's web viewer on 127.0.0.1 (the
    address is logged; the viewer keeps serving after the run). `on_stage(text)` is told each stage as it starts,
    `on_objects(done, total)` how many of the objects the task knows of it is done with (`Cell.objects_done`).
    Bad config or planner names raise before anything is simulated."""
    from twin.planning import make_context  # lazy: cli start-up (twin --help imports twin.tasks)
    from twin.recording import Recorder  # lazy: cli start-up
    from twin.rerun_log import RerunRecording, rerun_module  # lazy: cli start-up
    from twin.tasks.cell import Cell, stage_planners  # lazy: fcl, scipy

    if planner is not None:
        settings = with_planner(settings, "transfer", planner)
    seed = settings.seed if seed is None else int(seed)
    recorder = Recorder(record, speed=record_speed) if record else None
    if rerun or rerun_serve:
        rerun_module()  # a missing SDK fails here, before anything is built
    t0 = time.perf_counter()
    with collect_timings() as clock:
        with stage("setup"):  # planners built, task, the world and its bodies
            context = make_context(settings)  # the run's robot: built once, handed to everything below
            planners = stage_planners(settings, context)
            task = make_task(settings, context)
            if recorder is not None:
                recorder.landmarks = tuple(_landmarks_of(task))
            with stage("imports"):  # pybullet prints a banner on import: only once the input is known good
                from twin.world import World  # lazy: pybullet

            world = World(settings, seed=seed, gui=gui, robot=context.robot)
        with world:
            shown = on_stage if recorder is None else _to_both(recorder.stage, on_stage)
            cell = Cell(settings, world, context=context, on_stage=shown, planners=planners, on_objects=on_objects)
            if recorder is not None:
                recorder.attach(world)
            recording = None
            if rerun or rerun_serve:
                from twin.collision import PlanningScene  # lazy: fcl

                recording = RerunRecording(
                    rerun,
                    scene=PlanningScene.from_settings(settings, robot=context.robot),  # every fixture, as the cell has
                    kin=cell.kin,
                    recording_id=f"{config_name or settings.name}-seed{seed}",
                    serve=rerun_serve,
                )
                if recording.live is not None:
                    log.warning(
                        "live view: %s (Rerun's server, pid %d, keeps serving after the run: kill -- -%d stops it)",
                        recording.live.web_url,
                        recording.live.pid,
                        recording.live.pid,
                    )
                cell.trace = recording.attach(world)
            if gui:
                world.observe(lambda w: time.sleep(1.0 / 60.0), every_s=1.0 / 60.0)  # watchable, about real time
            try:
                outcomes = task.run(cell)
            except BaseException:
                if recording is not None:  # what was recorded up to the failure is what shows why
                    recording.close()
                raise
            sim_time = world.sim_time
        if recorder is not None:
            with stage("recording"):
                recorder.save()
        if recording is not None:
            with stage("recording"):
                recording.verdicts(sim_time, outcomes)
                recording.close()
    wall = time.perf_counter() - t0
    return RunSummary(
        config=config_name or settings.name,
        seed=seed,
        planner=cell.block("transfer").name,
        objects=tuple(outcomes),
        sim_time_s=sim_time,
        wall_time_s=wall,
        metrics=cell.metrics(),
        timings=clock.breakdown(wall),
        planners={group: ran_block(cell.block(group), p) for group, p in sorted(planners.items())},
        plugin_errors=tuple(cell.plugin_errors),
        calibration=cell.calibration or CalibrationOutcome("configured", reason="the task did not calibrate"),
    )


def ran_block(block: PlannerBlock, planner: CheckedPlanner) -> dict[str, Any]:
    """A planner block as it ran: its name, the parameters the plugin was built with (its validated `params`,
    defaults included) and its retimer's (the block's as given where a plugin keeps no model)."""
    params = getattr(planner.inner, "params", None)
    retimer = getattr(planner.inner, "retimer", None) if block.retimer is not None else None
    retimer_params = getattr(retimer, "params", None)
    return {
        "name": block.name,
        "params": params.model_dump(mode="json") if isinstance(params, BaseModel) else dict(block.params),
        "retimer": block.retimer,
        "retimer_params": retimer_params.model_dump(mode="json")
        if isinstance(retimer_params, BaseModel)
        else dict(block.retimer_params),
    }
