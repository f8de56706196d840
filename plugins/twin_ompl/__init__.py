"""Built-in OMPL sampling planners, registered lazily through the entry-point group `twin`.

Every planner is a one-shot planner `ompl.<name>` (`twin_ompl.planner`): FCL state validity and batched
motion validation from the planning scene, joint goals or pose goals (a goal set of every collision-free
IK solution), OMPL shortcutting, then a retimer plugin (default `toppra`). Importing this package does
not import OMPL; a planner's module is imported when the planner is first created, and a missing OMPL
raises DependencyMissing naming the `ompl` extra.

The optimising planners (RRT*, Informed RRT*, PRM*, BIT*, AORRTC) improve their path until a work budget
is spent (`max_state_checks`, `max_iterations`; `twin_ompl.budget`), not for the whole time limit, so a
seeded run repeats on any machine; the time limit stays a hard cap.

The straight-motion shortcut (`try_direct`) is off by default, so what a comparison measures is the named
planner's search; a planner block can turn it on (`params: {try_direct: true}`) for task stages.

`ompl.lazyprmstar` and `ompl.bitrrt` are registered because the issue names them, but OMPL 2.0.1's
Python bindings do not expose LazyPRMstar or BiTRRT (ompl/ompl#1419): `twin planners` lists them as
unavailable with that reason (asked of the class, no planner built), and creating them raises
DependencyMissing until an OMPL build whose bindings include them is installed.
`ompl.fmt` and `ompl.bfmt` (FMT*, BFMT*) use 100 samples and a connection multiplier of 0.6 instead of
OMPL's 1000 and 1.1 / 1.0: with OMPL's values every sample connects to nearly the whole batch, and with a
Python-side FCL check no blocked table-to-bin query was solved within 1 s (see `twin_ompl.params`).
"""

from __future__ import annotations

from twin.plugin import Registry, hookimpl

__all__ = ["PLANNERS", "twin_register_planners"]

# name -> (target, description); the classes are generated in twin_ompl.planner from one table
PLANNERS: dict[str, tuple[str, str]] = {
    "ompl.rrtconnect": (
        "twin_ompl.planner:RRTConnect",
        "OMPL RRT-Connect (bidirectional RRT); stops at the first path",
    ),
    "ompl.rrt": ("twin_ompl.planner:RRT", "OMPL RRT with goal bias; stops at the first path"),
    "ompl.rrtstar": (
        "twin_ompl.planner:RRTstar",
        "OMPL RRT* (asymptotically optimal path length); optimises until its work budget is spent",
    ),
    "ompl.informedrrtstar": (
        "twin_ompl.planner:InformedRRTstar",
        "OMPL Informed RRT*; optimises until its work budget is spent",
    ),
    "ompl.sorrtstar": (
        "twin_ompl.planner:SORRTstar",
        "OMPL Sorting RRT*; disabled: hangs in OMPL 2.0.1 (see twin planners)",
    ),
    "ompl.prm": ("twin_ompl.planner:PRM", "OMPL PRM (roadmap); stops at the first path"),
    "ompl.prmstar": (
        "twin_ompl.planner:PRMstar",
        "OMPL PRM* (asymptotically optimal roadmap); optimises until its work budget is spent",
    ),
    "ompl.lazyprmstar": (
        "twin_ompl.planner:LazyPRMstar",
        "OMPL LazyPRM* (needs bindings that expose it; not in ompl 2.0.1)",
    ),
    "ompl.bitstar": (
        "twin_ompl.planner:BITstar",
        "OMPL BIT* (batch informed trees); optimises until its work budget is spent",
    ),
    "ompl.aorrtc": (
        "twin_ompl.planner:AORRTC",
        "OMPL AORRTC (asymptotically optimal RRT-Connect); optimises until its work budget is spent",
    ),
    "ompl.kpiece1": (
        "twin_ompl.planner:KPIECE1",
        "OMPL KPIECE1 (projection-grid exploration); stops at the first path",
    ),
    "ompl.bkpiece1": ("twin_ompl.planner:BKPIECE1", "OMPL bidirectional KPIECE1; stops at the first path"),
    "ompl.lbkpiece1": ("twin_ompl.planner:LBKPIECE1", "OMPL lazy bidirectional KPIECE1; stops at the first path"),
    "ompl.bitrrt": ("twin_ompl.planner:BiTRRT", "OMPL BiTRRT (needs bindings that expose it; not in ompl 2.0.1)"),
    "ompl.fmt": (
        "twin_ompl.planner:FMT",
        "OMPL FMT* (fast marching tree over one batch of samples); stops at the first path",
    ),
    "ompl.bfmt": ("twin_ompl.planner:BFMT", "OMPL BFMT* (bidirectional FMT*); stops at the first path"),
}


@hookimpl
def twin_register_planners(registry: Registry) -> None:
    """Register every OMPL planner of this plugin (lazily: OMPL is imported on first use)."""
    for name, (target, description) in PLANNERS.items():
        registry.add_planner(name, target, description=description, extra="ompl")
