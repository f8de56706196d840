"""A robustness campaign: one task run on hundreds of seeds under a named fault set (`twin.faults`), each
object not placed put in one class of loss, so that a failure one run in fifty makes is seen as a class
before a user meets it. `bench/bench_campaign.py` is the command; this module holds the parts a test can
reach: the comparison spec a campaign runs (`campaign_spec`: `twin compare`'s runner, so local workers,
Ray, resume and the results file come with it), the loss taxonomy (`classify_loss`) and the tables
(`summarize`, `render`).

A loss is classed by the first failure of its object, in this order of blame: a run whose camera fell back to
its configured pose loses to `calibration`; then the words and stage of the failure say the rest.
"""

from __future__ import annotations

import re
import statistics
from collections import Counter
from dataclasses import dataclass, field
from typing import Any

from twin.compare.spec import ComparePlanner, CompareSpec, TaskScenario
from twin.config import load_config
from twin.failures import FAILURES, failure_of_task
from twin.faults import fault_overrides

__all__ = [
    "LOSS_CLASSES",
    "CampaignSummary",
    "campaign_spec",
    "classify_loss",
    "render",
    "summarize",
]

LOSS_CLASSES: dict[str, str] = {
    "calibration": "the camera's calibration fell back to its configured pose (the marker not found)",
    "perception": "never seen on the table, or seen somewhere it was not",
    "grasp_width": "the fingers stopped at a width the object cannot be (on something else, or on nothing)",
    "slip": "held at the grasp, then slipped out or was dropped on the way",
    "planner": "the compared (transfer) planner's stage found no way, a colliding one, or knocked something",
    "fixed_stage": "a fixed stage (align, hover, descent, ascent, place, home, capture) found no way or collided",
    "jam": "stuck between the opened fingers after the release",
    "other": "anything else: the run's time or capture budget ran out, released outside its bin, an error",
}
# the stages the compared planner plans (twin.tasks.cell.STAGE_GROUPS' `transfer` group)
_COMPARED_STAGES = frozenset({"transfer"})
# "never seen on the table (the run stopped: <why>)" (twin.tasks.judge), and the why of a capture move that failed
_STOPPED = re.compile(r"\(the run stopped: (.*)\)$")
_NO_CAPTURE = "cannot reach the capture pose: "
# failure names (twin.failures.FAILURES) a motion's planning or execution gives
_MOTION_FAILURES = frozenset(FAILURES) - {"grasp_lost", "dependency_missing", "error"}


def campaign_spec(
    config: str,
    *,
    faults: str,
    seeds: list[int],
    planners: list[dict[str, Any]] | None = None,
    name: str | None = None,
) -> CompareSpec:
    """The comparison that runs task `config` on `seeds` under fault set `faults` with each planner block
    as its transfer planner (None: the config's own transfer planner). UnknownNameError for an unknown
    fault set; the spec's own validation for bad planner blocks."""
    overrides = list(fault_overrides(faults))
    if planners is None:
        block = load_config(config).planners.get("transfer")
        planners = [{"name": block.name, "params": block.params} if block else {"name": "ruckig.movej"}]
    stem = config.rsplit("/", 1)[-1].removesuffix(".yaml")
    return CompareSpec(
        name=name or f"campaign-{stem}-{faults}",
        planners=[ComparePlanner(**p) for p in planners],
        scenarios=[TaskScenario(name=f"{stem}-{faults}", task=config, overrides=overrides)],
        seeds=seeds,
    )


def classify_loss(obj: dict[str, Any], run: dict[str, Any] | None = None) -> str:
    """The LOSS_CLASSES key of one object not placed: `obj` an outcome of a run's --json file (`objects`),
    `run` that file (its `calibration`, where the run reports one)."""
    calibration = (run or {}).get("calibration") or {}
    first = str(obj.get("error") or "").split("; then: ")[0]
    # no marker in a view perception used (twin.types.CalibrationOutcome), or a run that ended for want of one
    if calibration.get("status") == "fallback" or first.startswith("calibration:"):
        return "calibration"
    stage = obj.get("stage") or first.partition(":")[0]
    failure = obj.get("failure")
    stopped = _STOPPED.search(first)
    if stopped:  # never seen because the run ended early: the loss is what ended it
        why = stopped.group(1).removeprefix(_NO_CAPTURE)
        if failure_of_task([why]) in _MOTION_FAILURES:
            return "planner" if why.partition(":")[0] in _COMPARED_STAGES else "fixed_stage"
        return "other"
    if stage == "perception" or "never seen" in first:
        return "perception"
    if "stuck between the opened fingers" in first:
        return "jam"
    if "the fingers stopped at" in first or "nothing between the fingers" in first:
        return "grasp_width"
    if "slipped" in first or "dropped" in first or "the fingers closed from" in first:
        return "slip"
    if failure in _MOTION_FAILURES:
        return "planner" if stage in _COMPARED_STAGES else "fixed_stage"
    return "other"


@dataclass
class CampaignSummary:
    """One planner's campaign: the runs, the objects, and where the lost ones went."""

    planner: str
    scenario: str
    runs: int = 0
    errors: int = 0  # runs that raised or were stopped (no outcomes)
    objects: int = 0
    placed: int = 0
    per_seed: dict[int, tuple[int, int]] = field(default_factory=dict)  # seed: (placed, objects)
    losses: Counter[str] = field(default_factory=Counter)
    examples: dict[str, tuple[int, str, str]] = field(default_factory=dict)  # class: (seed, object, error)
    worst: list[tuple[int, int, int, str]] = field(default_factory=list)  # (placed, objects, seed, first failure)
    wall_s: list[float] = field(default_factory=list)

    @property
    def placed_share(self) -> float:
        return self.placed / self.objects if self.objects else 0.0

    def seeds_below(self, least: int) -> int:
        return sum(p < least for p, _ in self.per_seed.values())

    def to_json(self) -> dict[str, Any]:
        return {
            "planner": self.planner,
            "scenario": self.scenario,
            "runs": self.runs,
            "errors": self.errors,
            "objects": self.objects,
            "placed": self.placed,
            "placed_share": self.placed_share,
            "per_seed": {str(s): list(v) for s, v in sorted(self.per_seed.items())},
            "losses": dict(self.losses),
            "examples": {k: list(v) for k, v in self.examples.items()},
            "worst": [list(w) for w in self.worst],
            "median_wall_s": statistics.median(self.wall_s) if self.wall_s else None,
        }


def summarize(rows: list[dict[str, Any]], *, worst: int = 5) -> list[CampaignSummary]:
    """Per planner and scenario, from a campaign's results rows (`twin.compare.runner.read_results`)."""
    out: dict[tuple[str, str], CampaignSummary] = {}
    for row in sorted(rows, key=lambda r: (r["planner"], r["scenario"], r["seed"])):
        key = (row["planner"], row["scenario"])
        s = out.setdefault(key, CampaignSummary(planner=row["planner"], scenario=row["scenario"]))
        s.runs += 1
        run = row.get("task")
        wall = (row.get("timing") or {}).get("wall_time_s")
        if wall is not None:
            s.wall_s.append(float(wall))
        if not run:
            s.errors += 1
            s.worst.append((0, 0, int(row["seed"]), f"error: {row.get('reason', '')}"))
            continue
        objs = run.get("objects") or []
        placed = sum(bool(o.get("placed")) for o in objs)
        s.objects += len(objs)
        s.placed += placed
        s.per_seed[int(row["seed"])] = (placed, len(objs))
        lost = [o for o in objs if not o.get("placed")]
        for o in lost:
            cls = classify_loss(o, run)
            s.losses[cls] += 1
            s.examples.setdefault(cls, (int(row["seed"]), str(o.get("id")), str(o.get("error"))))
        if lost:
            s.worst.append((placed, len(objs), int(row["seed"]), f"{lost[0].get('id')}: {lost[0].get('error')}"))
    for s in out.values():
        s.worst = sorted(s.worst)[:worst]
    return list(out.values())


def _pct(x: float) -> str:
    return f"{100.0 * x:.1f} %"


def render(summaries: list[CampaignSummary], *, least: int | None = None, width: int = 160) -> str:
    """The campaign's tables as text: placed share, seeds below `least` objects placed (None: all of a
    seed's objects), the loss taxonomy with one example each, the worst seeds and their first failure."""
    lines: list[str] = []
    for s in summaries:
        full = max((n for _, n in s.per_seed.values()), default=0)
        floor = full if least is None else least
        complete = sum(p == n for p, n in s.per_seed.values())
        med = statistics.median(s.wall_s) if s.wall_s else float("nan")
        lines.append(
            f"{s.scenario} x {s.planner}: {s.runs} runs ({s.errors} errors), objects placed {s.placed}/{s.objects}"
            f" ({_pct(s.placed_share)}), every object placed on {complete}/{len(s.per_seed)} seeds,"
            f" seeds below {floor}/{full}: {s.seeds_below(floor)}, run wall median {med:.1f} s"
        )
        if s.losses:
            lines.append(f"  {'loss':<12} {'objects':>7}  first example (seed, object: failure)")
            for cls in LOSS_CLASSES:
                if s.losses.get(cls):
                    seed, oid, err = s.examples[cls]
                    lines.append(_clip(f"  {cls:<12} {s.losses[cls]:>7}  {seed}, {oid}: {err}", width))
            lines.append("  worst seeds (placed/objects, seed: first failure):")
            for placed, n, seed, first in s.worst:
                lines.append(_clip(f"    {placed}/{n}  {seed}: {first}", width))
        lines.append("")
    return "\n".join(lines)


def _clip(text: str, width: int) -> str:
    return text if len(text) <= width else text[: width - 3] + "..."
