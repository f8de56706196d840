"""The run's time breakdown (twin.timing): each second counted once, in the innermost stage that spent it."""

from __future__ import annotations

import pytest

import twin.timing
from twin.timing import OTHER, collect_timings, format_breakdown, process_age_s, stage


class FakeClock:
    """perf_counter for twin.timing that only moves when told to: the accounting, not the machine, is tested."""

    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


@pytest.fixture
def clock(monkeypatch: pytest.MonkeyPatch) -> FakeClock:
    fake = FakeClock()
    monkeypatch.setattr(twin.timing, "_now", fake)
    return fake


def test_nested_stages_are_charged_their_own_time_only(clock: FakeClock) -> None:
    t0 = clock()
    with collect_timings() as timings:
        with stage("planning.x") as outer:
            clock.advance(0.02)
            with stage("physics") as inner:
                clock.advance(0.03)
            with stage("physics"):
                clock.advance(0.01)
        clock.advance(0.01)
    wall = clock() - t0
    t = timings.breakdown(wall)
    assert t["physics"] == pytest.approx(0.04)
    assert t["planning.x"] == pytest.approx(0.02)  # less the physics inside it
    assert outer.seconds == pytest.approx(0.06) and inner.seconds == pytest.approx(0.03)
    assert t[OTHER] == pytest.approx(0.01)
    assert sum(t.values()) == pytest.approx(wall)


def test_without_a_collection_a_stage_only_measures(clock: FakeClock) -> None:
    with stage("physics") as s:
        clock.advance(0.005)
    assert s.seconds == pytest.approx(0.005)
    with collect_timings() as timings:
        pass
    assert timings.totals == {}


def test_the_one_line_groups_by_the_first_name() -> None:
    line = format_breakdown({"physics": 2.0, "perception.icp": 0.6, "perception.render": 0.4, OTHER: 1.0}, 4.0)
    assert line.startswith("physics 2.00 s (50%)")
    assert "perception 1.00 s (25%: icp 0.60, render 0.40)" in line and line.endswith("other 1.00 s (25%)")


def test_process_age_is_how_long_this_process_has_run() -> None:
    age = process_age_s()
    assert age is None or 0.0 < age < 24 * 3600
