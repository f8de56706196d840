"""Backing off a start in collision: the retreat a protective stop allows, along the way that separates.

After a contact the measured joints can lie inside something the planning scene holds: an obstacle or an
object perceived a couple of centimetres off (a camera error), which the gripper now overlaps although it
only touched the real one. Every planner then refuses the start ("invalid_start: the start configuration is
in collision (left_finger with seen_box)"), and the run would stop. A real cell has what it takes to get out:
the UR e-series reports the protective stop and has a wrist force/torque sensor (the contact and which way
it pushes), and the planning scene says which modelled thing the start penetrates. `back_off` moves the tcp
a few centimetres along the direction that separates that pair, as a checked motion, and the stage is
planned once more from there (`Cell.move`).

The direction: among a few tcp translations (straight up, horizontally away from the centre of the
penetrated thing's nearest shape, the two together, back along the tool axis, along +-x and +-y) the one
whose small probe step increases the pair's signed distance the most: the contact normal, measured the way
the planning scene can measure it, without reading FCL's nearest points. The motion: the tcp along that
straight line, orientation kept (IK solutions every 2.5 mm, each nearest the one before, a spline through
them), the shortest travel that ends `clear_m` clear, at most `max_travel_m`; timed by a quintic at a slow
tcp speed, judged by `twin.limit_check`, executed through `twin.executor.execute`. It is not planned by a
stage planner: no planner plans from a start in collision (a planner given a scene without the penetrated
thing would not be held to moving out of it), and the back-off must not be counted as the compared planner's
motion. It is checked instead: along its densified samples the penetrated pair's signed distance never
decreases, nothing else in the scene comes into collision, and it ends clear. On the arm it runs as a
retreat, as `Cell.move(..., retreat=True)` does: the safety monitor ignores what the robot touches as it
starts (here fixtures too, e.g. the bin wall the gripper was stopped against: the check above says the
motion moves away from it), and stops it for anything new. Bounded: at most `max_tries` motions, then a
one-line reason.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from twin.executor import execute
from twin.limit_check import limit_violations
from twin.planning import densify
from twin.types import Trajectory

if TYPE_CHECKING:
    from twin.collision import PlanningScene
    from twin.tasks.cell import Cell

__all__ = ["BACK_OFF_SPEED_M_S", "BackOff", "back_off", "penetrated_objects"]

log = logging.getLogger("twin")

# the tcp speed of a back-off: slow (a fifth of the 250 mm/s of ISO 10218's reduced speed), it moves off a
# contact it cannot see
BACK_OFF_SPEED_M_S = 0.05
_PROBE_M = 0.005  # the small step each candidate direction is judged by
_TRAVEL_STEP_M = 0.005  # travels tried: this, twice this, ... up to max_travel_m
_WAYPOINT_M = 0.0025  # IK waypoints along the tcp's line this far apart: the path between them is a spline
_SAMPLE_DT_S = 0.001
# the penetrated pair's signed distance may fall this far below its largest value so far along the way and
# still count as not decreasing (round-off; measured: at most 0.3 um along the back-offs from 15 boxes around
# the gripper, whose splines stayed within 0.1 um of the tcp's straight line)
_DISTANCE_NOISE_M = 2e-5
# a few centimetres of tcp travel is a small joint move away from singularities; a larger one would be
# another IK branch, a swing of the arm, not a back-off
_MAX_JOINT_MOVE_RAD = 0.5


@dataclass(frozen=True)
class BackOff:
    """What `back_off` did. `clear`: the measured joints are out of collision in the planning scene now.
    `pair`: what the start penetrated ('left_finger with seen_box'; '' when it was clear). `reason`: one
    line, what was done or why it failed. `tries`: back-off motions executed. `travel_m`: how far the tcp
    moved."""

    clear: bool
    pair: str
    reason: str
    tries: int = 0
    travel_m: float = 0.0


def penetrated_objects(scene: PlanningScene, q: np.ndarray) -> tuple[list[str], str | None]:
    """(the environment objects the arm at `q` (6,) is in collision with, in the order found; the pair
    that is a self-collision, if one is left once those are taken out, else None)."""
    rest = scene.padded(0.0)
    names: list[str] = []
    for _ in range(len(scene.names()) + 1):
        if not rest.in_collision(q):
            return names, None
        d = rest.min_distance(q)
        if d.self_collision or d.other not in rest.names():
            return names, f"{d.robot_part} with {d.other}"
        names.append(d.other)
        rest.remove(d.other)
    return names, None


def _split(scene: PlanningScene, names: list[str]) -> tuple[PlanningScene, PlanningScene]:
    """(a scene of only `names`, the scene without them): the pair's distance, and everything else."""
    solo, rest = scene.padded(0.0), scene.padded(0.0)
    for n in scene.names():
        (rest if n in names else solo).remove(n)
    return solo, rest


def _directions(cell: Cell, q: np.ndarray, names: list[str]) -> list[tuple[str, np.ndarray]]:
    """Candidate tcp translations (unit, base frame): up, horizontally away from the centre of the nearest
    shape of each penetrated object, both together, back along the tool's z axis, along +-x and +-y (the
    contact normal of a thing whose centre is right below or above the tcp is one of those)."""
    T = cell.kin.fk(q)
    p = T[:3, 3]
    up = np.array([0.0, 0.0, 1.0])
    out: list[tuple[str, np.ndarray]] = [("up", up)]
    shapes = cell.scene.environment_shapes()
    for n in names:
        centres = [S[:3, 3] for _, _, S in shapes.get(n, [])]
        if not centres:
            continue
        c = min(centres, key=lambda x: float(np.linalg.norm(x - p)))
        away = np.array([p[0] - c[0], p[1] - c[1], 0.0])
        if np.linalg.norm(away) > 1e-6:
            away /= np.linalg.norm(away)
            out += [(f"away from {n}", away), (f"up and away from {n}", (up + away) / math.sqrt(2.0))]
    out.append(("back along the tool", -T[:3, 2]))
    for label, v in (("+x", (1, 0, 0)), ("-x", (-1, 0, 0)), ("+y", (0, 1, 0)), ("-y", (0, -1, 0))):
        out.append((f"along {label}", np.array(v, dtype=float)))
    unique: list[tuple[str, np.ndarray]] = []
    for name, u in out:
        if all(float(u @ v) < 0.999 for _, v in unique):
            unique.append((name, u))
    return unique


def _ik_near(cell: Cell, T: np.ndarray, q_near: np.ndarray, q_start: np.ndarray) -> np.ndarray | None:
    """The IK solution of the tcp pose `T` (4, 4) nearest `q_near` (6,), None when there is none within
    `_MAX_JOINT_MOVE_RAD` of `q_start` on every joint."""
    sols = cell.kin.ik(T)
    if len(sols) == 0:
        return None
    best = sols[int(np.argmin(np.abs(sols - q_near).max(axis=1)))]
    return best if float(np.abs(best - q_start).max()) <= _MAX_JOINT_MOVE_RAD else None


def _moved(cell: Cell, q: np.ndarray, offset: np.ndarray) -> np.ndarray | None:
    """The joints near `q` with the tcp moved by `offset` (3,), orientation kept."""
    T = cell.kin.fk(q)
    T[:3, 3] += offset
    return _ik_near(cell, T, q, q)


def _timed(cell: Cell, path: np.ndarray, travel_m: float) -> Trajectory | None:
    """Rest to rest through the joint waypoints `path` (m, 6): a cubic spline q(s) through them, s(t) the
    quintic 10u^3 - 15u^4 + 6u^5 over T = 1.875 travel / `BACK_OFF_SPEED_M_S` (the tcp's peak speed), made
    longer until `twin.limit_check` finds no joint limit exceeded; None if that does not happen."""
    from scipy.interpolate import CubicSpline

    spline = CubicSpline(np.linspace(0.0, 1.0, path.shape[0]), path, axis=0)
    T = max(1.875 * travel_m / BACK_OFF_SPEED_M_S, 0.05)
    for _ in range(8):
        t = np.linspace(0.0, T, max(2, math.ceil(T / _SAMPLE_DT_S)) + 1)
        u = t / T
        s = u**3 * (10.0 - 15.0 * u + 6.0 * u**2)
        sd = (30.0 * u**2 * (1.0 - u) ** 2 / T)[:, None]
        sdd = (60.0 * u * (1.0 - u) * (1.0 - 2.0 * u) / T**2)[:, None]
        q, dq, ddq = spline(s), spline(s, 1), spline(s, 2)
        q[0], q[-1] = path[0], path[-1]
        traj = Trajectory(t, q, dq * sd, ddq * sd**2 + dq * sdd)
        if not limit_violations(traj, cell.limits):
            return traj
        T *= 1.5
    return None


def _plan(
    cell: Cell,
    q: np.ndarray,
    u: np.ndarray,
    solo: PlanningScene,
    rest: PlanningScene,
    *,
    max_travel_m: float,
    clear_m: float,
) -> tuple[Trajectory, float] | str:
    """The shortest checked back-off along `u` that ends `clear_m` clear (or, at `max_travel_m`, clear at
    all), or why there is none. Its path follows the tcp's straight line: IK solutions every
    `_WAYPOINT_M`, each nearest the one before."""
    col = cell.settings.collision
    n = max(1, math.floor(max_travel_m / _TRAVEL_STEP_M + 1e-9))
    per_step = math.ceil(_TRAVEL_STEP_M / _WAYPOINT_M - 1e-9)
    T0 = cell.kin.fk(q)
    path = [q]
    d1 = float(solo.min_distance(q, include_self=False).distance)
    for k in range(1, n + 1):
        travel = k * _TRAVEL_STEP_M
        for j in range(1, per_step + 1):
            T = T0.copy()
            T[:3, 3] += (travel - _TRAVEL_STEP_M + j * _TRAVEL_STEP_M / per_step) * u
            qj = _ik_near(cell, T, path[-1], q)
            if qj is None:
                return f"no IK solution near the start {100 * travel:.1f} cm along it"
            path.append(qj)
        q1 = path[-1]
        if rest.in_collision(q1):  # going on along it would only go further in
            other = rest.min_distance(q1)
            return f"{100 * travel:.1f} cm along it {other.robot_part} would hit {other.other}"
        d1 = float(solo.min_distance(q1, include_self=False).distance)
        if (k < n and d1 < clear_m - 1e-6) or cell.scene.in_collision(q1):
            continue  # not `clear_m` clear yet: a little further, up to the last travel, which need only be clear
        traj = _timed(cell, np.array(path), travel)
        if traj is None:
            return "it cannot be timed within the joint limits"
        qs = densify(traj, cell.kin, max_step_rad=col.check_resolution_rad, max_step_m=col.check_resolution_m)
        hits = np.flatnonzero(rest.in_collision_batch(qs))
        if hits.size:
            other = rest.min_distance(qs[hits[0]])
            return f"on the way {other.robot_part} would hit {other.other}"
        dist = solo.min_distance_batch(qs, include_self=False)
        deeper = np.flatnonzero(dist < np.maximum.accumulate(dist) - _DISTANCE_NOISE_M)
        if deeper.size:
            i = int(deeper[0])
            return f"the way goes deeper in ({1000 * dist[:i].max():.2f} mm, then {1000 * dist[i]:.2f} mm)"
        return traj, travel
    state = f"{-1000 * d1:.0f} mm in" if d1 < 0 else f"only {1000 * d1:.1f} mm clear"
    return f"{100 * max_travel_m:.0f} cm along it leaves it {state}"


def back_off(cell: Cell, *, max_tries: int = 3, max_travel_m: float = 0.05, clear_m: float = 0.005) -> BackOff:
    """Move the arm out of a collision of its measured joints with the planning scene (`cell.scene`), along
    the direction that separates the penetrated pair, by at most `max_travel_m` of tcp travel per motion,
    ending `clear_m` clear of it; at most `max_tries` motions (another one only when the arm, tracking the
    first, stopped short of clear). Each motion takes the first of the directions that move the pair apart,
    best first, with a checked way out (at most 9 directions of at most `max_travel_m` / 5 mm travels each,
    planned only). See the module docstring."""
    world, scene = cell.world, cell.scene
    q = world.joint_positions()
    if not scene.in_collision(q):
        return BackOff(True, "", "the start is not in collision")
    hit = scene.min_distance(q)
    pair = f"{hit.robot_part} with {hit.other}"
    tries, travelled = 0, 0.0
    why = f"still in collision after {max_tries} back-off motion{'' if max_tries == 1 else 's'}"
    while tries < max_tries:
        names, self_pair = penetrated_objects(scene, q)
        if self_pair is not None:
            why = f"{self_pair} is a self-collision, which no tcp translation undoes"
            break
        solo, rest = _split(scene, names)
        d0 = float(solo.min_distance(q, include_self=False).distance)
        ranked = []
        for label, u in _directions(cell, q, names):
            qp = _moved(cell, q, _PROBE_M * u)
            if qp is None or rest.in_collision(qp):
                continue
            gain = float(solo.min_distance(qp, include_self=False).distance) - d0
            if gain > 0.0:
                ranked.append((gain, label, u))
        ranked.sort(key=lambda x: -x[0])
        plan: tuple[Trajectory, float, str] | None = None
        refused: list[str] = []
        for _, label, u in ranked:
            found = _plan(cell, q, u, solo, rest, max_travel_m=max_travel_m, clear_m=clear_m)
            if isinstance(found, str):
                refused.append(f"{label}: {found}")
                log.debug("back-off from %s: %s: %s", pair, label, found)
                continue
            plan = (*found, label)
            break
        if plan is None:
            if not ranked:
                why = f"no tcp step of {1000 * _PROBE_M:.0f} mm moves it apart ({-1000 * d0:.0f} mm in)"
            else:
                more = len(refused) - 1
                why = f"no checked way out: {refused[0]}" + (f" (and {more} more directions)" if more else "")
            break
        traj, travel, label = plan
        tries += 1
        # a retreat: the safety monitor lets it move off whatever the arm touches as it starts (a loose object,
        # a fixture it was stopped against), and stops it for anything new
        ignore = {cell.held_body} if cell.held_body is not None else set()
        ignore |= {c.body_b for c in world.robot_contacts() if c.link_a != -1}
        report = execute(world, traj, hold_s=0.1, ignore_bodies=tuple(sorted(ignore)))
        p0 = cell.kin.fk(q)[:3, 3]
        q = world.joint_positions()
        travelled += float(np.linalg.norm(cell.kin.fk(q)[:3, 3] - p0))
        if report.stopped_by is not None:
            why = f"{label}: stopped: {report.stopped_by}"
            break
        log.info("back-off from %s: %.1f cm %s", pair, 100 * travel, label)
        if not scene.in_collision(q):
            return BackOff(True, pair, f"backed off {100 * travelled:.1f} cm ({label})", tries, travelled)
    return BackOff(False, pair, f"backing off failed: {why}", tries, travelled)
