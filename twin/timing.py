"""Where a run's wall time goes: stages timed where the work happens, summed per stage.

    with collect_timings() as clock:        # twin.tasks.run_task does this around a run
        ...
        with stage("physics"):               # anywhere below: World.step, World.render, a planner ...
            ...
    clock.breakdown(total_s)                 # {"physics": 2.7, "perception.icp": 0.4, ..., "other": 0.3}

Why exclusive time: stages nest (a planner drives the arm, which steps the physics), and a breakdown that
should sum to the wall time must count every second once. A stage is charged only what it did itself, not
what the stages inside it did; `stage(...).seconds` is still its whole (inclusive) time, which is what the
per-frame perception timings report. Without an active `collect_timings`, `stage` only measures.
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass, field
from types import TracebackType

__all__ = ["OTHER", "StageClock", "collect_timings", "format_breakdown", "process_age_s", "stage"]

OTHER = "other"  # wall time no stage claimed (bookkeeping, the task's own logic, Python between stages)

_now = time.perf_counter  # the clock stages read (a module attribute, so tests can give a fake one)
_CLOCK: ContextVar[StageClock | None] = ContextVar("twin_stage_clock", default=None)


@dataclass
class StageClock:
    """Exclusive wall seconds per stage name, and the stack of stages open now."""

    totals: dict[str, float] = field(default_factory=dict)
    _stack: list[_Stage] = field(default_factory=list)

    def breakdown(self, total_s: float) -> dict[str, float]:
        """Seconds per stage, largest first, plus OTHER = `total_s` minus what the stages claimed (never
        negative), so the values sum to `total_s`."""
        out = dict(sorted(self.totals.items(), key=lambda kv: -kv[1]))
        out[OTHER] = max(0.0, total_s - sum(self.totals.values()))
        return out


class _Stage:
    """One timed stage; `seconds` is its inclusive time once it has ended."""

    __slots__ = ("_children", "_clock", "_start", "name", "seconds")

    def __init__(self, name: str, clock: StageClock | None):
        self.name = name
        self._clock = clock
        self._children = 0.0
        self.seconds = 0.0

    def __enter__(self) -> _Stage:
        if self._clock is not None:
            self._clock._stack.append(self)
        self._start = _now()
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        self.seconds = _now() - self._start
        clock = self._clock
        if clock is None:
            return
        clock._stack.pop()
        clock.totals[self.name] = clock.totals.get(self.name, 0.0) + self.seconds - self._children
        if clock._stack:
            clock._stack[-1]._children += self.seconds


def stage(name: str) -> _Stage:
    """A context manager timing `name` (dotted: 'perception.icp', 'planning.ruckig.movej') into the active
    collection, if any; its `.seconds` is the stage's inclusive wall time."""
    return _Stage(name, _CLOCK.get())


@contextmanager
def collect_timings() -> Iterator[StageClock]:
    """Collect the stages timed inside the block (this thread and context) into a new StageClock."""
    clock = StageClock()
    token = _CLOCK.set(clock)
    try:
        yield clock
    finally:
        _CLOCK.reset(token)


def process_age_s() -> float | None:
    """Seconds since this process started (Linux: /proc; None elsewhere): what the interpreter and the
    imports took before any code of ours could start a clock."""
    try:
        with open("/proc/self/stat", encoding="ascii") as f:
            start_ticks = float(f.read().rsplit(")", 1)[1].split()[19])  # field 22, after the command name
        with open("/proc/uptime", encoding="ascii") as f:
            uptime = float(f.read().split()[0])
        return max(0.0, uptime - start_ticks / os.sysconf("SC_CLK_TCK"))
    except (OSError, ValueError, IndexError):
        return None


def format_breakdown(timings: dict[str, float], total_s: float) -> str:
    """One line: top-level groups with their share, the largest sub-stages of each in brackets, e.g.
    'physics 2.71 s (38%), perception 1.10 s (15%: icp 0.62, render 0.21), ...'."""
    groups: dict[str, dict[str, float]] = {}
    for name, s in timings.items():
        head, _, rest = name.partition(".")
        groups.setdefault(head, {})[rest] = groups.get(head, {}).get(rest, 0.0) + s
    parts = []
    for head, subs in sorted(groups.items(), key=lambda kv: -sum(kv[1].values())):
        s = sum(subs.values())
        share = f"{100 * s / total_s:.0f}%" if total_s > 0 else "-"
        named = sorted(((k, v) for k, v in subs.items() if k), key=lambda kv: -kv[1])[:3]
        detail = ": " + ", ".join(f"{k} {v:.2f}" for k, v in named) if named else ""
        parts.append(f"{head} {s:.2f} s ({share}{detail})")
    return ", ".join(parts)
