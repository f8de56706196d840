"""Built-in MoveJ/MoveL planners and retimers (Ruckig, TOPP-RA, the seed-002 baselines).

Registered lazily through the entry-point group `twin`, exactly as a third-party plugin would be:

- planners `ruckig.movej`, `seed.quintic_movej` (`twin_motion.movej`), `toppra.movel`,
  `seed.slerp_movel` (`twin_motion.movel`);
- retimers `toppra`, `ruckig` (`twin_motion.retimers`).

The defensive IK they share is `twin_motion.ik.DefensiveIK`.
"""

from __future__ import annotations

from twin.plugin import Registry, hookimpl

__all__ = ["PLANNERS", "RETIMERS", "twin_register_planners", "twin_register_retimers"]

PLANNERS: dict[str, tuple[str, str]] = {
    "ruckig.movej": (
        "twin_motion.movej:RuckigMoveJ",
        "time-optimal jerk-limited point-to-point motion (Ruckig); joint or pose goals via defensive IK",
    ),
    "seed.quintic_movej": (
        "twin_motion.movej:QuinticMoveJ",
        "seed 002 MoveJ: quintic time scaling, T from the peak velocity 1.875*dq/T (and acc/jerk)",
    ),
    "toppra.movel": (
        "twin_motion.movel:ToppraMoveL",
        "straight TCP line + SLERP, continuity-seeded IK, timed by TOPP-RA (joint and TCP speed limits)",
    ),
    "seed.slerp_movel": (
        "twin_motion.movel:SeedSlerpMoveL",
        "seed 002 MoveL: 0.02 m steps, IK seeded by the previous waypoint, 0.12 m/s, at least 1.5 s",
    ),
}

RETIMERS: dict[str, tuple[str, str]] = {
    "toppra": (
        "twin_motion.retimers:ToppraRetimer",
        "time-optimal path parameterisation (TOPP-RA, constant-acceleration parametrizer) under vel/acc limits",
    ),
    "ruckig": (
        "twin_motion.retimers:RuckigRetimer",
        "jerk-limited chain of Ruckig segments through every waypoint, passing through where it stays smooth",
    ),
}


@hookimpl
def twin_register_planners(registry: Registry) -> None:
    """Register the MoveJ/MoveL planners of this plugin."""
    for name, (target, description) in PLANNERS.items():
        registry.add_planner(name, target, description=description)


@hookimpl
def twin_register_retimers(registry: Registry) -> None:
    """Register the TOPP-RA and Ruckig retimers of this plugin."""
    for name, (target, description) in RETIMERS.items():
        registry.add_retimer(name, target, description=description)
