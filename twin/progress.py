"""Elapsed time and an estimate of the time left, for the long commands (`twin run`, `twin compare`, the benches).

    watch = ProgressClock()                  # the clock starts now (`clock=` a fake one in tests)
    ...
    watch.stamp(done, total)                 # '3/26 00:41 eta 05:12'

    with RunDisplay("robocup seed 0") as shown:   # `twin run`'s line on stderr, while the run goes
        run_task(..., on_stage=shown.stage, on_objects=shown.objects)

The estimate is the plain rate of what finished so far: `elapsed / done` per item, times the items left. Items
that take different times (a sweep's planners, a task's objects) make it rough, and it says nothing until the
first item has finished ('eta --:--'). Counted from the last item that finished, it counts down between
items instead of growing with the time spent on the current one.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from types import TracebackType

from rich.console import Console
from rich.progress import Progress, ProgressColumn, SpinnerColumn, Task, TextColumn
from rich.text import Text

__all__ = ["ProgressClock", "RunDisplay", "clock_text", "eta_s"]


def clock_text(seconds: float | None) -> str:
    """'05:12' (minutes:seconds), '1:05:12' from an hour on; '--:--' for None or a value that is not finite."""
    if seconds is None or not math.isfinite(seconds):
        return "--:--"
    s = max(0, int(round(seconds)))
    h, rest = divmod(s, 3600)
    m, sec = divmod(rest, 60)
    return f"{h}:{m:02d}:{sec:02d}" if h else f"{m:02d}:{sec:02d}"


def eta_s(elapsed_s: float, done: int, total: int, *, last_done_s: float | None = None) -> float | None:
    """Seconds left for `total - done` items at the rate of the `done` items that finished, the last of them
    at `last_done_s` (default: now, `elapsed_s`); None before the first has finished. Never negative."""
    if done <= 0:
        return None
    if done >= total:
        return 0.0
    at = elapsed_s if last_done_s is None else last_done_s
    return max(0.0, at / done * (total - done) - (elapsed_s - at))


class ProgressClock:
    """Elapsed time since it was made and the estimate of `eta_s` from the counts it is given."""

    def __init__(self, *, clock: Callable[[], float] = time.monotonic):
        self._clock = clock
        self._t0 = clock()
        self._done = 0
        self._last_done_s: float | None = None

    def elapsed_s(self) -> float:
        return self._clock() - self._t0

    def eta_s(self, done: int, total: int) -> float | None:
        """Seconds left; a change of `done` since the last call marks the time an item finished."""
        elapsed = self.elapsed_s()
        if done != self._done:
            self._done, self._last_done_s = done, elapsed
        return eta_s(elapsed, done, total, last_done_s=self._last_done_s)

    def stamp(self, done: int, total: int) -> str:
        """'3/26 00:41 eta 05:12': the counts, the elapsed time and the estimate of the time left."""
        eta = self.eta_s(done, total)
        return f"{done}/{total} {clock_text(self.elapsed_s())} eta {clock_text(eta)}"


class _Computed(ProgressColumn):
    """A column whose text is computed at each refresh (an elapsed time that runs, an estimate that counts down)."""

    def __init__(self, text: Callable[[], str]):
        super().__init__()
        self._text = text

    def render(self, task: Task) -> Text:
        return Text(self._text(), style="progress.elapsed")


class RunDisplay:
    """`twin run`'s progress display: one line on stderr, 'robocup seed 0: cube_red: descent' (the stage the task
    is in), 'objects 2/8 00:41 eta 01:12' (the objects done of those the task knows of, the elapsed time, an
    estimate of the time left from the objects done so far). Transient (gone when the run ends), shown only
    where stderr is a terminal (rich's Live draws nothing elsewhere), never on stdout; `enabled=False` (-q)
    shows nothing anywhere. `status()` is the line as text."""

    def __init__(
        self,
        label: str,
        *,
        enabled: bool = True,
        console: Console | None = None,
        clock: Callable[[], float] = time.monotonic,
    ):
        self._label = label
        self._stage = "starting"
        self._counts: tuple[int, int] | None = None
        self._clock = clock
        self._watch = ProgressClock(clock=clock)  # the whole run
        self._objects: ProgressClock | None = None  # from the first count on: the objects' own rate
        self._progress = Progress(
            SpinnerColumn(),
            TextColumn("{task.description}"),
            _Computed(self.counts_text),
            console=console or Console(stderr=True),
            transient=True,
            redirect_stdout=False,  # stdout is the command's output: nothing of the display goes there
            disable=not enabled,
            get_time=clock,
        )
        self._task = self._progress.add_task(self.stage_text(), total=None)

    def stage(self, text: str) -> None:
        """The task started a stage ('cube_red: descent')."""
        self._stage = text
        self._progress.update(self._task, description=self.stage_text())

    def objects(self, done: int, total: int) -> None:
        """The task is done with `done` of the `total` objects it knows of."""
        if self._objects is None:
            self._objects = ProgressClock(clock=self._clock)
        self._counts = (done, total)
        self._objects.eta_s(done, total)  # marks when the count changed
        self._progress.refresh()

    def stage_text(self) -> str:
        return f"{self._label}: {self._stage}"

    def counts_text(self) -> str:
        """'objects 2/8 00:41 eta 01:12'; before the task has counted its objects, the elapsed time alone."""
        elapsed = clock_text(self._watch.elapsed_s())
        if self._counts is None or self._objects is None:
            return elapsed
        done, total = self._counts
        return f"objects {done}/{total} {elapsed} eta {clock_text(self._objects.eta_s(done, total))}"

    def status(self) -> str:
        return f"{self.stage_text()} {self.counts_text()}"

    def __enter__(self) -> RunDisplay:
        self._progress.start()
        return self

    def __exit__(self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None) -> None:
        self._progress.stop()
