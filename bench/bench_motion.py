"""Benchmark of the MoveJ/MoveL planners (issue 4). A plain script: prints numbers, asserts nothing.

    python bench/bench_motion.py [--pairs 200] [--lines 60]

Prints
- the median ratio of ruckig.movej to seed.quintic_movej duration on the same random start/goal pairs,
- the median ratio of toppra.movel to seed.slerp_movel duration on the same random lines in the work area,
- microseconds per plan for each planner, without obstacles (the planner alone) and in the FCL scene of
  the default config (including the collision check of the trajectory),
- the worst sampled limit use (1.0 = at the limit) and the worst MoveL deviation from the line / SLERP.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import time
from collections.abc import Iterator
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from twin.config import settings_from_dict
from twin.planning import limits_from_settings, make_context
from twin.types import JointGoal, MotionRequest, Pose, PoseGoal, Trajectory

TOP_DOWN = np.diag([1.0, -1.0, -1.0])


class FreeScene:
    """No obstacles: measures the planner alone."""

    def in_collision(self, q: np.ndarray) -> bool:
        return False

    def in_collision_batch(self, qs: np.ndarray) -> np.ndarray:
        return np.zeros(len(qs), dtype=bool)


def fcl_only_time(planner: Any, req: MotionRequest, scene: Any) -> float:
    """Planning time in `scene` with its sphere filter off (FCL checks every configuration, as before issue 14)."""
    scene.sphere_filter = False
    try:
        return timed(planner, req, scene)[1]
    finally:
        scene.sphere_filter = True


def timed(planner: Any, req: MotionRequest, scene: Any) -> tuple[Any, float]:
    t0 = time.perf_counter()
    res = planner.plan(req, scene)
    return res, time.perf_counter() - t0


@contextlib.contextmanager
def no_trajectory_check() -> Iterator[None]:
    """Bench only: skip the planners' own collision check of the trajectory, to time the planning alone."""
    import twin_motion.movej as mj

    saved = mj.first_collision
    mj.first_collision = lambda *a, **k: None  # type: ignore[assignment]
    try:
        yield
    finally:
        mj.first_collision = saved


def limit_use(traj: Trajectory, lim: Any) -> tuple[float, float, float]:
    r = traj.resampled(0.001)
    ms = np.arange(0.0, traj.duration, 0.001)
    _, _, a = traj.sample(ms)
    jerk = np.abs(np.diff(a, axis=0)) / 0.001 if ms.size > 1 else np.zeros((1, 6))
    return (
        float((np.abs(r.qd) / lim.max_joint_vel).max()),
        float((np.abs(r.qdd) / lim.max_joint_acc).max()),
        float((jerk / lim.max_joint_jerk).max()),
    )


def line_deviation(kin: Any, traj: Trajectory, T0: np.ndarray, T1: np.ndarray) -> tuple[float, float]:
    from scipy.spatial.transform import Slerp

    q = traj.resampled(0.001).q
    F = kin.fk_batch(q)
    p0, p1 = T0[:3, 3], T1[:3, 3]
    u = p1 - p0
    s = np.clip((F[:, :3, 3] - p0) @ u / max(float(u @ u), 1e-12), 0.0, 1.0)
    dev = np.linalg.norm(F[:, :3, 3] - (p0 + s[:, None] * u), axis=1)
    sl = Slerp([0.0, 1.0], Rotation.from_matrix(np.array([T0[:3, :3], T1[:3, :3]])))
    ang = (sl(s).inv() * Rotation.from_matrix(F[:, :3, :3])).magnitude()
    return float(dev.max()), float(np.degrees(ang.max()))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=200)
    ap.add_argument("--lines", type=int, default=60)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    settings = settings_from_dict({})
    ctx = make_context(settings)
    kin = ctx.kinematics
    lim = limits_from_settings(settings)
    home = np.array(settings.robot.home)
    rng = np.random.default_rng(args.seed)
    free = FreeScene()
    try:
        from twin.collision import PlanningScene

        fcl_scene: Any = PlanningScene.from_settings(settings)
    except ImportError:
        fcl_scene = None
    names = ["ruckig.movej", "seed.quintic_movej", "toppra.movel", "seed.slerp_movel"]
    planners = {n: ctx.registry.planner(n, {}, ctx) for n in names}
    times: dict[str, list[float]] = {n: [] for n in names}
    times_alone: dict[str, list[float]] = {n: [] for n in names}
    times_fcl: dict[str, list[float]] = {n: [] for n in names}
    times_fcl_only: dict[str, list[float]] = {n: [] for n in names}  # the FCL scene without its sphere filter
    worst: dict[str, list[float]] = {n: [0.0, 0.0, 0.0] for n in names}

    def note(name: str, res: Any) -> None:
        if res.success:
            worst[name] = [max(a, b) for a, b in zip(worst[name], limit_use(res.trajectory, lim), strict=True)]

    # ---- MoveJ: random joint pairs ----
    ratios_j = []
    for _ in range(args.pairs):
        a, b = rng.uniform(-math.pi, math.pi, 6), rng.uniform(-math.pi, math.pi, 6)
        req = MotionRequest(a, JointGoal(b), lim)
        rr, tr = timed(planners["ruckig.movej"], req, free)
        rq, tq = timed(planners["seed.quintic_movej"], req, free)
        with no_trajectory_check():
            for n in ("ruckig.movej", "seed.quintic_movej"):
                times_alone[n].append(timed(planners[n], req, free)[1])
        times["ruckig.movej"].append(tr)
        times["seed.quintic_movej"].append(tq)
        note("ruckig.movej", rr)
        note("seed.quintic_movej", rq)
        ratios_j.append(rr.trajectory.duration / rq.trajectory.duration)
    for _ in range(min(args.pairs, 50)):
        if fcl_scene is None:
            break
        g = home + rng.uniform(-0.8, 0.8, 6)
        req = MotionRequest(home, JointGoal(g), lim)
        for n in ("ruckig.movej", "seed.quintic_movej"):
            times_fcl[n].append(timed(planners[n], req, fcl_scene)[1])
            times_fcl_only[n].append(fcl_only_time(planners[n], req, fcl_scene))

    # ---- MoveL: random lines in the work area (top-down, yaw changes, descents and lateral moves) ----
    ratios_l, dev_m, dev_deg, fails = [], 0.0, 0.0, dict.fromkeys(("toppra.movel", "seed.slerp_movel"), 0)
    ik = planners["toppra.movel"].ik
    reasons: list[str] = []
    done = 0
    while done < args.lines:
        p0 = rng.uniform([-0.65, -0.30, 0.15], [-0.30, 0.30, 0.45])
        p1 = p0 + (
            rng.uniform([-0.25, -0.25, -0.2], [0.25, 0.25, 0.2])
            if rng.random() < 0.5
            else [0, 0, rng.uniform(-0.25, 0.1)]
        )
        p1[2] = max(p1[2], 0.12)
        y0, y1 = rng.uniform(-math.pi, math.pi), 0.0
        y1 = y0 + rng.uniform(-math.pi / 4, math.pi / 4)
        T0, T1 = np.eye(4), np.eye(4)
        T0[:3, :3], T0[:3, 3] = Rotation.from_euler("z", y0).as_matrix() @ TOP_DOWN, p0
        T1[:3, :3], T1[:3, 3] = Rotation.from_euler("z", y1).as_matrix() @ TOP_DOWN, p1
        start = ik.solve(T0, home, home).q
        if start is None:
            continue
        done += 1
        req = MotionRequest(start, PoseGoal(Pose.from_matrix(T1)), lim)
        rt, tt = timed(planners["toppra.movel"], req, free)
        rs, ts = timed(planners["seed.slerp_movel"], req, free)
        with no_trajectory_check():
            for n in ("toppra.movel", "seed.slerp_movel"):
                times_alone[n].append(timed(planners[n], req, free)[1])
        times["toppra.movel"].append(tt)
        times["seed.slerp_movel"].append(ts)
        if fcl_scene is not None and done <= 30:
            for n in ("toppra.movel", "seed.slerp_movel"):
                times_fcl[n].append(timed(planners[n], req, fcl_scene)[1])
                times_fcl_only[n].append(fcl_only_time(planners[n], req, fcl_scene))
        note("toppra.movel", rt)
        note("seed.slerp_movel", rs)
        for n, r in (("toppra.movel", rt), ("seed.slerp_movel", rs)):
            if not r.success:
                fails[n] += 1
                reasons.append(f"  {n} from {np.round(p0, 3)} to {np.round(p1, 3)}: {r.status.value}: {r.reason}")
        if rt.success:
            d, a = line_deviation(kin, rt.trajectory, T0, T1)
            dev_m, dev_deg = max(dev_m, d), max(dev_deg, a)
        if rt.success and rs.success:
            ratios_l.append(rt.trajectory.duration / rs.trajectory.duration)

    print(
        f"MoveJ, {args.pairs} random pairs: "
        f"median duration ruckig.movej / seed.quintic_movej = {np.median(ratios_j):.3f} "
        f"(min {np.min(ratios_j):.3f}, max {np.max(ratios_j):.3f})"
    )
    print(
        f"MoveL, {args.lines} random lines: "
        f"median duration toppra.movel / seed.slerp_movel = {np.median(ratios_l):.3f} "
        f"on {len(ratios_l)} lines both planned (failures: {fails})"
    )
    print("\n".join(reasons))
    print(
        f"MoveL worst deviation of toppra.movel at 1 kHz: {dev_m * 1e3:.4f} mm from the line, "
        f"{dev_deg:.4f} deg from SLERP"
    )
    print()
    print(f"{'':22s} {'microseconds per plan (median)':^80s}")
    print(
        f"{'planner':22s} {'planning alone':>18s} {'+ trajectory check':>20s} {'in the FCL scene':>18s} "
        f"{'(FCL only)':>12s}   worst |qd|/v, |qdd|/a, |jerk|/j at 1 kHz"
    )
    for n in names:
        fcl = f"{np.median(times_fcl[n]) * 1e6:18.0f}" if times_fcl[n] else f"{'-':>18s}"
        only = f"{np.median(times_fcl_only[n]) * 1e6:12.0f}" if times_fcl_only[n] else f"{'-':>12s}"
        w = worst[n]
        print(
            f"{n:22s} {np.median(times_alone[n]) * 1e6:18.0f} {np.median(times[n]) * 1e6:20.0f} {fcl} {only}   "
            f"{w[0]:.6f}, {w[1]:.6f}, {w[2]:.6f}"
        )
    print(
        "(planning alone / + trajectory check: no obstacles, the same random queries; FCL scene: default config,"
        " moves within +-0.8 rad of home and the first 30 lines, collision check included; FCL only: the same"
        " with collision.sphere_filter off, as before issue 14)"
    )
    if times_fcl["ruckig.movej"] and times_fcl["toppra.movel"]:
        print("issue 14's goals, planning time in the FCL scene including the planner's checks (median):")
        for n, bound in (("ruckig.movej", 2e-3), ("toppra.movel", 5e-3)):
            med = float(np.median(times_fcl[n]))
            print(f"  {n:14s} {med * 1e3:6.2f} ms <= {bound * 1e3:.0f} ms  {'met' if med <= bound else 'NOT MET'}")


if __name__ == "__main__":
    main()
