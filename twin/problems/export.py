"""`twin problems export`: a scene config's seeded random motion queries as a problem set.

The queries are drawn exactly as a `twin compare` scenario draws them (`twin.problems.sampling.sample_query`
with the generator seeded by (seed, scenario name, index)), so exporting with a compare scenario's name,
`random:` settings and seed gives that scenario's problems; the world is the planning scene those
queries are planned in (fixtures, and the obstacles a task perceives, as `unknown_fixtures: box` gives
them).
"""

from __future__ import annotations

import zlib
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from pydantic import ValidationError

from twin.config import find_config
from twin.errors import ConfigError
from twin.problems.cells import cell_for
from twin.problems.problem_set import ProblemSet
from twin.problems.queries import problem_of_query
from twin.problems.sampling import RandomQueries, sample_query
from twin.problems.world import robot_spec, world_of_scene

if TYPE_CHECKING:
    from twin.collision.scene import UnknownFixtures

__all__ = ["export_problem_set"]


def export_problem_set(
    config: str | Path,
    *,
    count: int,
    seed: int = 0,
    name: str | None = None,
    random: dict[str, Any] | None = None,
    time_limit_s: float = 1.0,
    overrides: Iterable[str] = (),
    unknown_fixtures: UnknownFixtures = "box",
) -> ProblemSet:
    """`count` random queries in the cell of `config` (a path or a shipped config's name), drawn with
    `seed` as the compare scenario `name` (default: the config's name) would draw them with `random`
    (RandomQueries fields: goal, straight, regions, clearances; `count` is the argument).

    Raises ConfigError for a bad config, bad `random` fields or a region that yields no query."""
    path = str(find_config(config).resolve())
    scenario = name or Path(path).stem
    try:
        rq = RandomQueries.model_validate({**(random or {}), "count": count})
    except ValidationError as e:
        err = e.errors()[0]
        where = ".".join(str(p) for p in err["loc"])
        if err["type"] == "extra_forbidden":
            allowed = ", ".join(k for k in RandomQueries.model_fields if k != "count")
            raise ConfigError(f"unknown random-query setting {where!r}; allowed: {allowed}") from None
        raise ConfigError(f"random.{where}: {err['msg'].removeprefix('Value error, ')}") from None
    if time_limit_s <= 0:
        raise ConfigError(f"time_limit_s must be positive, got {time_limit_s}")
    if seed < 0:
        raise ConfigError(f"seed must be >= 0, got {seed}")
    cell = cell_for(path, tuple(overrides), unknown_fixtures)
    settings = cell.settings
    model = cell.scene.model
    home = np.asarray(settings.robot.home, dtype=float)
    spec = rq.model_dump()
    problems = []
    for i in range(count):
        rng = np.random.default_rng([seed & 0xFFFFFFFF, zlib.crc32(scenario.encode()), i])
        q = sample_query(
            spec,
            rng,
            scene=cell.scene,
            kin=cell.kin,
            home=home,
            resolution_rad=settings.collision.check_resolution_rad,
        )
        problems.append(problem_of_query(q, id=f"{scenario}#{i}", time_limit_s=time_limit_s, seed=seed))
    return ProblemSet(
        name=scenario,
        description=f"{count} random {rq.goal} queries ({rq.straight} straight motion) in {Path(path).name}",
        source={
            "config": Path(path).name,
            "overrides": list(overrides),
            "seed": seed,
            "random": rq.model_dump(mode="json"),
        },
        robot=robot_spec(cell.scene, settings),
        world=world_of_scene(cell.scene, frame=model.root),
        problems=problems,
    )
