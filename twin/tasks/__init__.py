"""Task runs (`twin run`): the reference systems end to end, perception to placed object.

`run_task(settings, seed=..., planner=...)` builds the world, runs the configured task
(`settings.task.kind`: robocup or warehouse) and judges every object by physics ground truth at the end.

The tasks decide with what a real cell senses (camera frames, joint encoders, the gripper's finger
position); the simulator's ground truth is read only by `twin.tasks.judge` (verdicts, metrics, the
labelled oracle detector's hand-off).
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable

from twin.config import Settings
from twin.types import RunSummary

__all__ = ["run_task"]

log = logging.getLogger("twin")


def run_task(
    settings: Settings,
    *,
    seed: int | None = None,
    planner: str | None = None,
    gui: bool = False,
    record: str | None = None,
    on_stage: Callable[[str], None] | None = None,
    config_name: str = "",
) -> RunSummary:
    """Run the configured task once on scene `seed` (default: the config's); `planner` replaces the
    transfer planner; `record` writes a video (.mp4/.gif) from the overview camera. Bad config or
    planner names raise before anything is simulated."""
    from twin.recording import Recorder
    from twin.tasks.cell import Cell, stage_planners

    seed = settings.seed if seed is None else int(seed)
    recorder = Recorder(record) if record else None
    t0 = time.perf_counter()
    planners = stage_planners(settings, planner)
    from twin.world import World  # pybullet prints a banner on import: only once the input is known good

    with World(settings, seed=seed, gui=gui) as world:
        cell = Cell(settings, world, planner_override=planner, on_stage=on_stage, planners=planners)
        if recorder is not None:
            recorder.attach(world)
        if gui:
            world.observe(lambda w: time.sleep(1.0 / 60.0), every_s=1.0 / 60.0)  # watchable, about real time
        if settings.task.kind == "warehouse":
            from twin.tasks.warehouse import run_warehouse

            outcomes = run_warehouse(cell)
        else:
            from twin.tasks.robocup import run_robocup

            outcomes = run_robocup(cell)
        sim_time = world.sim_time
    if recorder is not None:
        recorder.save()
    return RunSummary(
        config=config_name or settings.name,
        seed=seed,
        planner=cell.block("transfer").name,
        objects=tuple(outcomes),
        sim_time_s=sim_time,
        wall_time_s=time.perf_counter() - t0,
        metrics=cell.metrics(),
    )
