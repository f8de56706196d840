"""The tasks' perception pipelines, bound in one place for `twin.perception.evaluate.run_perception`.

Why here: the pipelines belong to the tasks (`twin.tasks.<name>.perception`), which sit above perception, so
perception's evaluation is handed them; every caller (`twin perceive`, the tests, the perception bench)
takes this one binding instead of assembling its own.
"""

from __future__ import annotations

from twin.perception.evaluate import Pipelines
from twin.tasks.robocup.perception import perceive_robocup
from twin.tasks.warehouse.perception import perceive_warehouse

__all__ = ["TASK_PIPELINES"]

TASK_PIPELINES = Pipelines(warehouse=perceive_warehouse, robocup=perceive_robocup)
