"""Retimers: turn a geometric joint path (m, 6) into a densely sampled `Trajectory` under joint limits.

- `toppra`: time-optimal path parameterisation (TOPP-RA) of a cubic spline through the waypoints (straight
  segments subdivided first, so the spline hugs the polyline), with the constant-acceleration parametrizer.
  TOPP-RA enforces the limits at its grid points only: it gets slightly tightened limits, grid intervals
  whose samples still overshoot are refined, and any overshoot left is removed by a uniform slow-down, so
  neither the sampled |qd| and |qdd| nor the divided differences of the sampled q exceed the limits. Jerk
  is not bounded (it declares `jerk_limited = False`, so a path planner timed by it does too).
- `ruckig`: jerk-limited. The community Ruckig has no offline intermediate waypoints, so the path is a chain
  of point-to-point Ruckig segments. To keep it smooth the chain passes each interior waypoint with a
  velocity estimated from its neighbours (the velocity a time-optimal motion over the window
  previous -> next waypoint has where it passes this one; zero for a joint that reverses there) and zero
  acceleration, so position, velocity and acceleration are continuous and jerk stays bounded. A
  pass-through velocity that makes a segment stray more than `max_deviation_rad` from its straight chord
  (or overshoot its end) is halved, and finally dropped to a stop (then the segment is an exact straight
  line, by phase synchronisation).

Both sample the native trajectory exactly every <= `sample_dt_s` (1 kHz by default) and hit the endpoints
exactly. Both raise `RetimingFailed` (a `PlanningError`) when a path cannot be timed; planners turn that
into `Status.LIMIT_VIOLATION` with the reason.
"""

from __future__ import annotations

import contextlib
import functools
import importlib
import importlib.util
import itertools
import logging
import math
import sys
import types
from collections.abc import Iterator
from dataclasses import dataclass
from typing import Any, ClassVar, Literal

import numpy as np
import ruckig
from pydantic import BaseModel, ConfigDict, Field
from scipy.interpolate import CubicSpline

from twin.plugin import Limits, PlanningError, Trajectory, densify_path, stage

__all__ = [
    "RetimingFailed",
    "RuckigRetimer",
    "TimedSamples",
    "ToppraRetimer",
    "dedupe_path",
    "limit_ratios",
    "ruckig_point_to_point",
    "ruckig_samples",
    "toppra_time_spline",
]

log = logging.getLogger("twin")
_OK = (ruckig.Result.Working, ruckig.Result.Finished)
# a pass-through segment is first sampled this far apart: where it strays from its chord there, the velocities
# are halved without sampling it finely (most segments a halving redoes are refused so)
_COARSE_DT_S = 0.01


class RetimingFailed(PlanningError):
    """A path could not be time-parameterised under the limits (the message says why)."""


@dataclass(frozen=True)
class TimedSamples:
    """Samples of a timed path: t (n,), q, qd, qdd (n, 6); `s` (n,) the path parameter, when there is one."""

    t: np.ndarray
    q: np.ndarray
    qd: np.ndarray
    qdd: np.ndarray
    s: np.ndarray | None = None

    def trajectory(self) -> Trajectory:
        return Trajectory(self.t, self.q, self.qd, self.qdd)


def dedupe_path(path: np.ndarray, eps: float = 1e-9) -> np.ndarray:
    """(m', 6) the path without consecutive repeated waypoints (max-abs difference <= eps)."""
    path = np.asarray(path, dtype=float)
    if path.ndim != 2 or path.shape[1] != 6 or path.shape[0] < 1:
        raise RetimingFailed(f"a path must be an (m, 6) array of joint angles, got shape {path.shape}")
    if not np.all(np.isfinite(path)):
        raise RetimingFailed("the path contains non-finite joint angles")
    keep = np.ones(path.shape[0], dtype=bool)
    keep[1:] = np.abs(np.diff(path, axis=0)).max(axis=1) > eps
    keep[-1] = True
    out = path[keep]
    if out.shape[0] >= 2 and np.abs(out[-1] - out[-2]).max() <= eps:
        out = np.delete(out, -2, axis=0)
    return out


def limit_ratios(traj: Trajectory | TimedSamples, limits: Limits) -> tuple[float, float]:
    """Worst |qd| / max_joint_vel and |qdd| / max_joint_acc over the samples (1.0 = at the limit)."""
    return (
        float(np.max(np.abs(traj.qd) / limits.max_joint_vel)),
        float(np.max(np.abs(traj.qdd) / limits.max_joint_acc)),
    )


def _stationary(q: np.ndarray) -> Trajectory:
    q = np.asarray(q, dtype=float).reshape(1, 6)
    return Trajectory(np.zeros(1), q.copy(), np.zeros((1, 6)), np.zeros((1, 6)))


# ---- Ruckig ---------------------------------------------------------------------------------------------
_SYNC = {"phase": ruckig.Synchronization.Phase, "time": ruckig.Synchronization.Time}


def ruckig_point_to_point(
    q0: np.ndarray,
    q1: np.ndarray,
    limits: Limits,
    *,
    v0: np.ndarray | None = None,
    v1: np.ndarray | None = None,
    synchronization: Literal["phase", "time"] = "phase",
) -> ruckig.Trajectory:
    """Time-optimal jerk-limited motion from (q0, v0, a=0) to (q1, v1, a=0); raises RetimingFailed."""
    inp = ruckig.InputParameter(6)
    inp.current_position = np.asarray(q0, dtype=float).tolist()
    inp.target_position = np.asarray(q1, dtype=float).tolist()
    if v0 is not None:
        inp.current_velocity = np.asarray(v0, dtype=float).tolist()
    if v1 is not None:
        inp.target_velocity = np.asarray(v1, dtype=float).tolist()
    inp.max_velocity = limits.max_joint_vel.tolist()
    inp.max_acceleration = limits.max_joint_acc.tolist()
    inp.max_jerk = limits.max_joint_jerk.tolist()
    inp.synchronization = _SYNC[synchronization]
    traj = ruckig.Trajectory(6)
    try:
        res = ruckig.Ruckig(6).calculate(inp, traj)
    except Exception as e:  # noqa: BLE001 -- the binding raises RuckigError (and others) for invalid input
        raise RetimingFailed(f"Ruckig rejected the segment: {e}") from None
    if res not in _OK:
        raise RetimingFailed(f"Ruckig could not compute the segment: {res}")
    return traj


def _sample_times(duration: float, dt: float) -> np.ndarray:
    n = max(1, math.ceil(duration / dt - 1e-9))
    return np.linspace(0.0, duration, n + 1)


def ruckig_samples(traj: ruckig.Trajectory, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Exact q, qd, qdd (len(ts), 6) of a Ruckig trajectory, evaluated from its jerk profiles with numpy.

    ~50x faster than calling `at_time` per sample; falls back to `at_time` for profiles with a brake or
    acceleration pre-phase (only when the initial state violates the limits).
    """
    ts = np.asarray(ts, dtype=float)
    n = ts.shape[0]
    q, qd, qdd = np.empty((n, 6)), np.empty((n, 6)), np.empty((n, 6))
    profiles = traj.profiles[-1]
    if any(p.brake.duration > 0 or p.accel.duration > 0 for p in profiles) or len(traj.profiles) != 1:
        for k, t in enumerate(ts):
            p, v, a = traj.at_time(float(t))
            q[k], qd[k], qdd[k] = p, v, a
        return q, qd, qdd
    dur = np.array([p.t for p in profiles])  # (6, 7) phase durations
    cum = np.concatenate((np.zeros((6, 1)), np.cumsum(dur, axis=1)), axis=1)  # (6, 8)
    J = np.array([p.j for p in profiles])  # (6, 7)
    A0 = np.array([p.a for p in profiles])  # (6, 8): state at the start of each phase (8th: the end)
    V0 = np.array([p.v for p in profiles])
    P0 = np.array([p.p for p in profiles])
    # phase index per (sample, dof); 7 = past the end (a DOF keeps its final state, as Ruckig does)
    idx = np.stack([np.searchsorted(cum[d, 1:], ts, side="right") for d in range(6)], axis=1)  # (n, 6)
    flat = idx + np.arange(6)[None, :] * 8  # flat gathers are ~4x faster than 2-D fancy indexing
    J8 = np.concatenate((J, np.zeros((6, 1))), axis=1).ravel()
    h = ts[:, None] - cum.ravel()[flat]
    jj, aa, vv, pp = J8[flat], A0.ravel()[flat], V0.ravel()[flat], P0.ravel()[flat]
    q[:] = pp + h * (vv + h * (aa / 2.0 + h * jj / 6.0))
    qd[:] = vv + h * (aa + h * jj / 2.0)
    qdd[:] = aa + h * jj
    return q, qd, qdd


def _strays(traj: ruckig.Trajectory, q0: np.ndarray, q1: np.ndarray, limit: float, dt: float) -> bool:
    """Whether the segment's samples `dt` apart already stray more than `limit` from its chord: a lower bound
    on the deviation the fine samples have, so a segment it refuses is refused by them too (the answer for a
    segment it passes comes from the fine samples)."""
    q, _, _ = ruckig_samples(traj, _sample_times(traj.duration, dt))
    return _chord_deviation(q, q0, q1) > limit


def _chord_deviation(q: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """Largest joint-space distance (rad) of the samples `q` (n, 6) from the segment q0 -> q1."""
    u = q1 - q0
    uu = float(u @ u)
    if uu <= 0.0:
        return float(np.linalg.norm(q - q0, axis=1).max())
    s = np.clip((q - q0) @ u / uu, 0.0, 1.0)
    return float(np.linalg.norm(q - q0 - s[:, None] * u, axis=1).max())


class RuckigRetimer:
    """Jerk-limited retimer: a smooth chain of Ruckig point-to-point segments through every waypoint."""

    jerk_limited: ClassVar[bool] = True  # declared: keeps max_joint_jerk (a path planner timed by it answers so)

    class Params(BaseModel):
        model_config = ConfigDict(extra="forbid")

        sample_dt_s: float = Field(0.001, gt=0, le=0.05, description="sampling period of the output")
        pass_through: bool = Field(True, description="keep moving through interior waypoints when possible")
        pass_through_gain: float = Field(1.0, gt=0, le=3, description="scales the estimated waypoint velocity")
        max_deviation_rad: float = Field(0.05, gt=0, description="largest allowed distance from a segment's chord")
        max_halvings: int = Field(4, ge=0, le=20, description="velocity halvings before stopping at a waypoint")
        estimate_passes: int = Field(1, ge=1, le=5, description="passes of the waypoint velocity estimate")
        synchronization: Literal["phase", "time"] = "phase"

    def __init__(self, params: RuckigRetimer.Params | None = None, context: Any = None):
        self.params = params or self.Params()
        self.context = context

    def retime(self, path: np.ndarray, limits: Limits) -> Trajectory:
        """Trajectory (sampled every <= sample_dt_s) through every waypoint of `path` (m, 6), from rest to rest."""
        return self.retime_samples(path, limits).trajectory()

    def retime_samples(self, path: np.ndarray, limits: Limits) -> TimedSamples:
        p = self.params
        P = dedupe_path(path)
        m = P.shape[0]
        if m == 1:
            s = _stationary(P[0])
            return TimedSamples(s.t, s.q, s.qd, s.qdd)
        V = self._waypoint_velocities(P, limits) if p.pass_through and m > 2 else np.zeros((m, 6))
        factor = np.ones(m)  # scale of each waypoint's pass-through velocity
        factor[0] = factor[-1] = 0.0
        halvings = np.zeros(m, dtype=int)
        segs: list[Any] = [None] * (m - 1)
        dirty = set(range(m - 1))
        while dirty:
            bad: set[int] = set()
            for i in sorted(dirty):
                moving = factor[i] > 0 or factor[i + 1] > 0
                try:
                    traj = ruckig_point_to_point(
                        P[i],
                        P[i + 1],
                        limits,
                        v0=V[i] * factor[i],
                        v1=V[i + 1] * factor[i + 1],
                        synchronization=p.synchronization,
                    )
                except RetimingFailed:
                    if not moving:
                        raise
                    bad.add(i)
                    continue
                if moving and _strays(traj, P[i], P[i + 1], p.max_deviation_rad, _COARSE_DT_S):
                    bad.add(i)  # already beyond the chord at a coarse sampling: no need to sample it finely
                    continue
                ts = _sample_times(traj.duration, p.sample_dt_s)
                q, qd, qdd = ruckig_samples(traj, ts)
                segs[i] = (ts, q, qd, qdd)
                if moving and _chord_deviation(q, P[i], P[i + 1]) > p.max_deviation_rad:
                    bad.add(i)
            # halve the pass-through velocity at both ends of every bad segment; after max_halvings, stop
            # there. Factors only shrink and a segment between two stops is straight, so this terminates.
            dirty = set()
            for i in bad:
                for w in (i, i + 1):
                    if 0 < w < m - 1 and factor[w] > 0:
                        halvings[w] += 1
                        factor[w] = 0.0 if halvings[w] > p.max_halvings else factor[w] * 0.5
                        dirty.update(j for j in (w - 1, w) if 0 <= j < m - 1)
        return self._concat(segs, P, V * factor[:, None])

    def _waypoint_velocities(self, P: np.ndarray, limits: Limits) -> np.ndarray:
        """(m, 6) pass-through velocities at the waypoints (zero at both ends).

        For waypoint i, a time-optimal Ruckig motion over the window P[i-1] -> P[i+1] (straight when the
        boundary velocities allow it) is evaluated where it passes P[i]; its velocity there is the estimate.
        Further passes (`estimate_passes` > 1) repeat this with the neighbours' estimates as the window's
        boundary velocities; measured on random paths, one pass is best (more overshoot and halving after).
        A joint that reverses or stops at a waypoint gets zero velocity there.
        """
        m = P.shape[0]
        V = np.zeros((m, 6))
        gain = self.params.pass_through_gain
        for _ in range(self.params.estimate_passes):
            Vn = np.zeros((m, 6))
            for i in range(1, m - 1):
                a, b, c = P[i - 1], P[i], P[i + 1]
                d_in, d_out = b - a, c - b
                moving = d_in * d_out > 0.0
                if not moving.any():
                    continue
                chord = c - a
                try:
                    w = ruckig_point_to_point(a, c, limits, v0=V[i - 1], v1=V[i + 1], synchronization="phase")
                except RetimingFailed:
                    continue
                d = int(np.argmax(np.abs(chord)))
                frac = float(np.clip((b - a) @ chord / (chord @ chord), 0.0, 1.0))
                t = w.get_first_time_at_position(d, float(a[d] + frac * chord[d]))
                t = frac * w.duration if t is None else t
                v = np.asarray(w.at_time(t)[1]) * gain
                v[~moving | (v * d_out <= 0.0)] = 0.0
                with np.errstate(divide="ignore"):
                    scale = np.min(np.where(v != 0, limits.max_joint_vel / np.abs(v), np.inf))
                Vn[i] = v * min(1.0, float(scale))
            V = Vn
        return V

    @staticmethod
    def _concat(segs: list[Any], P: np.ndarray, V: np.ndarray) -> TimedSamples:
        t_all, q_all, qd_all, qdd_all = [], [], [], []
        offset = 0.0
        for i, (ts, q, qd, qdd) in enumerate(segs):
            q, qd, qdd = q.copy(), qd.copy(), qdd.copy()
            q[0], qd[0], qdd[0] = P[i], V[i], 0.0
            q[-1], qd[-1], qdd[-1] = P[i + 1], V[i + 1], 0.0
            first = 0 if i == 0 else 1
            t_all.append(ts[first:] + offset)
            q_all.append(q[first:])
            qd_all.append(qd[first:])
            qdd_all.append(qdd[first:])
            offset += float(ts[-1])
        return TimedSamples(
            np.concatenate(t_all), np.concatenate(q_all), np.concatenate(qd_all), np.concatenate(qdd_all)
        )


# ---- TOPP-RA --------------------------------------------------------------------------------------------
def _grid(knots: np.ndarray, n_target: int) -> np.ndarray:
    """Grid points containing every spline knot, each interval split to about length / n_target."""
    L = float(knots[-1] - knots[0])
    step = L / max(n_target, 1)
    pieces = [knots[:1]]
    for a, b in itertools.pairwise(knots):
        k = max(1, math.ceil((b - a) / step - 1e-9))
        pieces.append(np.linspace(a, b, k + 1)[1:])
    return np.concatenate(pieces)


def _worst_ratios(
    t: np.ndarray, q: np.ndarray, r_v: np.ndarray, r_a: np.ndarray, vel: np.ndarray, acc: np.ndarray
) -> tuple[float, float]:
    """Worst velocity and acceleration ratios (1.0 = at the limit) of timed samples t (n,), q (n, 6): the
    per-sample ratios r_v, r_a (n,) of the declared qd and qdd, and the first and second divided differences
    of q, with the arm at rest before the first sample and after the last one (as `twin.testing` judges)."""
    if t.shape[0] < 2:
        return float(r_v.max(initial=0.0)), float(r_a.max(initial=0.0))
    h0, h1 = t[1] - t[0], t[-1] - t[-2]
    T = np.concatenate([[t[0] - h0], t, [t[-1] + h1]])
    Q = np.vstack([q[:1], q, q[-1:]])
    d1 = np.diff(Q, axis=0) / np.diff(T)[:, None]
    d2 = 2.0 * np.diff(d1, axis=0) / (T[2:] - T[:-2])[:, None]
    worst_v = max(float(r_v.max()), float((np.abs(d1) / vel).max()))
    worst_a = max(float(r_a.max()), float((np.abs(d2) / acc).max()))
    return worst_v, worst_a


def _const_accel_samples(
    ss: np.ndarray, sd: np.ndarray, dt: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """t, s, sdot, sddot sampled every <= dt for TOPP-RA's constant-acceleration parametrisation, and the
    grid interval of every sample."""
    ds = np.diff(ss)
    denom = sd[:-1] + sd[1:]
    if np.any(denom <= 0):
        raise RetimingFailed("TOPP-RA returned a zero path velocity on a whole grid interval")
    u = 0.5 * (sd[1:] ** 2 - sd[:-1] ** 2) / ds
    tg = np.concatenate(([0.0], np.cumsum(2.0 * ds / denom)))
    t = _sample_times(float(tg[-1]), dt)
    idx = np.clip(np.searchsorted(tg, t, side="right") - 1, 0, ds.shape[0] - 1)
    h = t - tg[idx]
    s = np.clip(ss[idx] + h * sd[idx] + 0.5 * h * h * u[idx], ss[0], ss[-1])
    sdot = np.maximum(sd[idx] + h * u[idx], 0.0)
    s[-1], sdot[-1] = ss[-1], sd[-1]
    return t, s, sdot, u[idx], idx


@functools.lru_cache(maxsize=64)
def _limit_constraints(vlim: tuple[float, ...], alim: tuple[float, ...]) -> list[Any]:
    """TOPP-RA's joint velocity and acceleration constraints for these limits, built once: a request's limits
    repeat, and building them formats a description string per joint (~1 ms a retime). They hold only the
    limits; TOPP-RA evaluates them on each path afresh."""
    from toppra import constraint

    return [
        constraint.JointVelocityConstraint(np.array(vlim)),
        constraint.JointAccelerationConstraint(np.array(alim)),
    ]


class _DeferredPyplot(types.ModuleType):
    """Stands in for matplotlib.pyplot until an attribute of it is asked for, then imports it, takes its
    place in `sys.modules` and passes every attribute on."""

    def __getattr__(self, name: str) -> Any:
        if name.startswith("__"):  # the import system asks for __path__ & co.: a plain module has none
            raise AttributeError(name)
        if sys.modules.get("matplotlib.pyplot") is self:
            del sys.modules["matplotlib.pyplot"]
        real = importlib.import_module("matplotlib.pyplot")
        return getattr(real, name)


@contextlib.contextmanager
def _deferred_pyplot() -> Iterator[None]:
    """TOPP-RA imports matplotlib.pyplot at module level for its plotting helpers (~0.4 s, a third of a
    task run's imports) and needs it only when asked to plot: within this block (TOPP-RA's import) it gets
    a stand-in that imports pyplot on first use. `import matplotlib.pyplot as plt` also imports the parent
    package (~0.2 s of the 0.4) even when the submodule is in `sys.modules`, so the parent is stood in for
    too, by a bare module, for the block only: `plt` is then found in `sys.modules` (IMPORT_FROM's
    fallback), and afterwards `import matplotlib` anywhere gets the real package. Nothing changes when
    pyplot or TOPP-RA was imported already."""
    if "matplotlib.pyplot" in sys.modules or "toppra" in sys.modules or importlib.util.find_spec("matplotlib") is None:
        yield
        return
    sys.modules["matplotlib.pyplot"] = _DeferredPyplot("matplotlib.pyplot")
    parent = None
    if "matplotlib" not in sys.modules:
        parent = sys.modules["matplotlib"] = types.ModuleType("matplotlib")
    try:
        yield
    finally:
        if parent is not None and sys.modules.get("matplotlib") is parent:
            del sys.modules["matplotlib"]


def toppra_time_spline(
    knots: np.ndarray,
    waypoints: np.ndarray,
    limits: Limits,
    *,
    sample_dt_s: float = 0.001,
    margin: float = 0.01,
    min_gridpoints: int = 100,
    max_gridpoints: int = 2000,
    limit_tolerance: float = 0.0,
    refinements: int = 1,
    tcp_length_m: float | None = None,
    tcp_speed: float | None = None,
) -> TimedSamples:
    """Time-optimal timing of the cubic spline q(s) through `waypoints` (m, 6) at `knots` (m,), rest to rest.

    TOPP-RA (constant-acceleration parametrizer) gets the limits tightened by `margin` and keeps them at
    its grid points only; between grid points the sampled |qdd| can overshoot where the path bends
    sharply. Grid intervals with overshooting samples are bisected and TOPP-RA rerun (`refinements`
    times); what overshoot is left beyond `limit_tolerance` (default none), in the samples' qd and qdd or in
    the divided differences of their q (which show an overshoot between samples), is removed by slowing the
    whole trajectory uniformly (time x k scales qd by 1/k and qdd by 1/k^2) and sampling it again, so both
    keep the limits.
    If `tcp_speed` is given, the TCP travels `tcp_length_m * (s - s0) / (s1 - s0)` along a straight line
    and its speed is limited too, through a virtual seventh coordinate.
    """
    with stage("imports"), _deferred_pyplot():  # the first call imports TOPP-RA: not planning
        import toppra
        import toppra.algorithm as algo
        import toppra.solverwrapper as sw
    if not hasattr(sw.available_solvers, "cache_info"):
        # every TOPPRA instance asks importlib which optional QP solvers are installed (~0.25 ms, twice a
        # retime); the answer cannot change within a process, so it is asked once
        sw.available_solvers = functools.cache(sw.available_solvers)

    knots = np.asarray(knots, dtype=float)
    W = np.asarray(waypoints, dtype=float)
    spline = CubicSpline(knots, W, bc_type="not-a-knot")
    d1s, d2s = spline.derivative(1), spline.derivative(2)
    vel, acc = limits.max_joint_vel, limits.max_joint_acc
    use_tcp = tcp_speed is not None and tcp_length_m is not None and tcp_length_m > 1e-9
    W7 = W
    vlim, alim = vel * (1.0 - margin), acc * (1.0 - margin)
    if use_tcp:
        assert tcp_speed is not None and tcp_length_m is not None
        W7 = np.column_stack([W, (knots - knots[0]) / (knots[-1] - knots[0]) * tcp_length_m])
        vlim = np.append(vlim, float(tcp_speed) * (1.0 - margin))
        alim = np.append(alim, 1e9)

    def _timed(grid: np.ndarray, sd: np.ndarray, k: float) -> tuple[np.ndarray, ...]:
        """Samples of the parameterisation `sd` (path velocity at the grid points) slowed down k times: t,
        s, qd, qdd, the per-sample ratios of |qd| and |qdd| to their limits, and each sample's grid interval."""
        t, s, sdot, sddot, seg = _const_accel_samples(grid, sd / k, sample_dt_s)
        d1, d2 = d1s(s), d2s(s)
        qd = d1 * sdot[:, None]
        qdd = d2 * (sdot**2)[:, None] + d1 * sddot[:, None]
        r_v = np.max(np.abs(qd) / vel, axis=1)
        r_a = np.max(np.abs(qdd) / acc, axis=1)
        if use_tcp:
            assert tcp_speed is not None and tcp_length_m is not None
            r_v = np.maximum(r_v, sdot * tcp_length_m / (knots[-1] - knots[0]) / tcp_speed)
        return t, s, qd, qdd, r_v, r_a, seg

    path = toppra.SplineInterpolator(knots, W7, bc_type="not-a-knot")
    constraints = _limit_constraints(tuple(vlim.tolist()), tuple(alim.tolist()))
    grid = _grid(knots, max(min_gridpoints, 2 * (knots.shape[0] - 1)))
    for attempt in range(refinements + 1):
        inst = algo.TOPPRA(
            constraints, path, gridpoints=grid, solver_wrapper="seidel", parametrizer="ParametrizeConstAccel"
        )
        _, sd, _, _ = inst.compute_parameterization(0.0, 0.0, return_data=True)
        if sd is None or np.any(~np.isfinite(sd)):
            raise RetimingFailed(f"TOPP-RA found no feasible parameterisation ({inst.problem_data.return_code})")
        sd = np.asarray(sd, dtype=float)
        t, s, qd, qdd, r_v, r_a, seg = _timed(grid, sd, 1.0)
        over = (r_v > 1.0) | (r_a > 1.0)
        if not over.any() or attempt == refinements or grid.shape[0] >= max_gridpoints:
            break
        bad = np.unique(seg[over])
        bad = np.unique(np.clip(np.concatenate([bad - 1, bad, bad + 1]), 0, grid.shape[0] - 2))
        grid = np.sort(np.concatenate([grid, 0.5 * (grid[bad] + grid[bad + 1])]))
    # What overshoot is left, on the samples and between them (the divided differences of q, which a motion
    # that keeps its limits cannot exceed), is removed by a uniform slow-down: TOPP-RA's path velocities sd / k
    # time the same path k times slower (qd / k, qdd / k^2), evaluated exactly at the sampling period again.
    # The samples then fall elsewhere on the motion, so the check repeats (in practice at most once more).
    k = 1.0
    for _ in range(5):
        q = spline(s)
        worst_v, worst_a = _worst_ratios(t, q, r_v, r_a, vel, acc)
        if max(worst_v, worst_a) <= 1.0 + limit_tolerance:
            break
        k *= max(1.0, worst_v, math.sqrt(worst_a)) * (1.0 + 1e-9)
        log.debug("TOPP-RA overshoot (vel x%.4f, acc x%.4f) removed by slowing down x%.4f", worst_v, worst_a, k)
        t, s, qd, qdd, r_v, r_a, _ = _timed(grid, sd, k)
    else:
        raise RetimingFailed(f"TOPP-RA's timing still exceeds the limits after slowing it down x{k:.3f}")
    q[0], q[-1] = W[0], W[-1]
    qd[0] = qd[-1] = 0.0
    return TimedSamples(t, q, qd, qdd, s)


class ToppraRetimer:
    """Time-optimal retimer (TOPP-RA, constant-acceleration parametrizer) of a spline through the path.

    Not jerk-limited (declared): TOPP-RA parameterises under velocity and acceleration constraints only;
    the acceleration is piecewise constant over its grid and jumps from rest at t = 0."""

    jerk_limited: ClassVar[bool] = False

    class Params(BaseModel):
        model_config = ConfigDict(extra="forbid")

        sample_dt_s: float = Field(0.001, gt=0, le=0.05, description="sampling period of the output")
        margin: float = Field(0.01, ge=0, lt=0.5, description="limits handed to TOPP-RA are (1 - margin) x the user's")
        limit_tolerance: float = Field(
            0.0, ge=0, le=0.1, description="overshoot of the sampled result tolerated before slowing down uniformly"
        )
        min_gridpoints: int = Field(100, ge=10, le=5000)
        max_gridpoints: int = Field(2000, ge=10, le=20000)
        refinements: int = Field(1, ge=0, le=10, description="grid refinements where samples overshoot")
        max_spacing_rad: float = Field(
            0.1, gt=0, description="straight path segments are subdivided to this joint-space spacing before fitting"
        )

    def __init__(self, params: ToppraRetimer.Params | None = None, context: Any = None):
        self.params = params or self.Params()
        self.context = context

    def retime(self, path: np.ndarray, limits: Limits) -> Trajectory:
        """Trajectory through (near) every waypoint of `path` (m, 6), from rest to rest, ends exact."""
        p = self.params
        P = dedupe_path(path)
        if P.shape[0] == 1:
            return _stationary(P[0])
        # Subdivide straight segments so the cubic spline hugs the polyline (corners are rounded within
        # about one spacing) and parameterise by joint-space arc length.
        D = densify_path(P, p.max_spacing_rad)
        knots = np.concatenate(([0.0], np.cumsum(np.linalg.norm(np.diff(D, axis=0), axis=1))))
        out = toppra_time_spline(
            knots,
            D,
            limits,
            sample_dt_s=p.sample_dt_s,
            margin=p.margin,
            min_gridpoints=p.min_gridpoints,
            max_gridpoints=p.max_gridpoints,
            limit_tolerance=p.limit_tolerance,
            refinements=p.refinements,
        )
        return out.trajectory()
