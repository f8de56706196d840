"""Microseconds per kinematics and collision call on the RoboCup cell (plain script, no assertions).

    PYTHONPATH=. python bench/bench_workcell.py [--n 2000]

Each number is the best of 5 repeats over the same seeded configurations (the machine is shared, so the
best repeat is the least disturbed one). "free"/"colliding" split the sampled configurations by the
answer, because a colliding configuration usually returns at the first hit.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from twin.collision import PlanningScene
from twin.config import PROJECT_ROOT, Settings, load_config
from twin.robot.kinematics import URArm
from twin.robot.urdf_model import RobotModel


def best_us(fn: Callable[[], object], count: int, repeat: int = 5) -> float:
    """Best-of-`repeat` wall time of fn() in microseconds per item (`count` items per call)."""
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best / count * 1e6


def settings() -> Settings:
    path = PROJECT_ROOT / "configs" / "robocup.yaml"
    return load_config(path) if path.is_file() else Settings()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=2000, help="configurations per measurement")
    n = ap.parse_args().n
    rng = np.random.default_rng(0)
    s = settings()
    kin = URArm()
    model = RobotModel.from_urdf(s.resolve(s.robot.urdf))
    t0 = time.perf_counter()
    scene = PlanningScene.from_settings(s)
    build_ms = (time.perf_counter() - t0) * 1e3

    lo = np.array([-math.pi, -math.pi, -math.pi, -math.pi, -math.pi, -math.pi])
    hi = np.array([math.pi, 0.0, math.pi, math.pi, math.pi, math.pi])
    qs = rng.uniform(lo, hi, size=(n, 6))
    poses = [kin.fk(q) for q in qs]
    hit = scene.in_collision_batch(qs)
    free, coll = qs[~hit], qs[hit]

    few = min(n, 500)
    path = np.linspace(free[0], free[1], 200)
    cases: list[tuple[str, Callable[[], object], int]] = [
        ("kinematics.fk (tcp)", lambda: [kin.fk(q) for q in qs], n),
        ("kinematics.fk_batch, per config", lambda: kin.fk_batch(qs), n),
        ("kinematics.ik (all branches + wraps)", lambda: [kin.ik(T) for T in poses[:few]], few),
        ("kinematics.jacobian", lambda: [kin.jacobian(q) for q in qs[:few]], few),
        ("urdf_model.link_poses, 1 config", lambda: [model.link_poses(q) for q in qs[:few]], few),
        ("urdf_model.link_poses, batch per config", lambda: model.link_poses(qs), n),
        ("in_collision, free configs", lambda: [scene.in_collision(q) for q in free], len(free)),
        ("in_collision, colliding configs", lambda: [scene.in_collision(q) for q in coll], len(coll)),
        ("in_collision_batch, per config", lambda: scene.in_collision_batch(qs), n),
        ("min_distance, free configs", lambda: [scene.min_distance(q) for q in free], len(free)),
        ("min_distance, colliding configs", lambda: [scene.min_distance(q) for q in coll], len(coll)),
        (
            "min_distance(include_self=False), free",
            lambda: [scene.min_distance(q, include_self=False) for q in free],
            len(free),
        ),
        ("min_distance_batch, per config", lambda: scene.min_distance_batch(qs), n),
        ("min_distance along a 200-point path", lambda: [scene.min_distance(q) for q in path], 200),
        ("  same, include_self=False", lambda: [scene.min_distance(q, include_self=False) for q in path], 200),
        ("first_collision over a 200-point path, per config", lambda: scene.first_collision(path), 200),
    ]
    rows = [(name, best_us(fn, count)) for name, fn, count in cases]

    print(f"scene: {s.name}, fixtures {scene.names()}, {n} configurations, {hit.mean():.0%} colliding")
    print(f"PlanningScene.from_settings: {build_ms:.1f} ms")
    width = max(len(r[0]) for r in rows)
    for name, us in rows:
        print(f"{name:<{width}}  {us:8.1f} us")


if __name__ == "__main__":
    main()
