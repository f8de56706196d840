"""The run's time breakdown (twin.timing): each second counted once, in the innermost stage that spent it."""

from __future__ import annotations

import time

import pytest

from twin.timing import OTHER, collect_timings, format_breakdown, process_age_s, stage


def _busy(seconds: float) -> None:
    end = time.perf_counter() + seconds
    while time.perf_counter() < end:
        pass


def test_nested_stages_are_charged_their_own_time_only() -> None:
    t0 = time.perf_counter()
    with collect_timings() as clock:
        with stage("planning.x") as outer:
            _busy(0.02)
            with stage("physics") as inner:
                _busy(0.03)
            with stage("physics"):
                _busy(0.01)
        _busy(0.01)
    wall = time.perf_counter() - t0
    t = clock.breakdown(wall)
    assert t["physics"] == pytest.approx(0.04, abs=0.01)
    assert t["planning.x"] == pytest.approx(0.02, abs=0.01)  # less the physics inside it
    assert outer.seconds == pytest.approx(0.06, abs=0.01) and inner.seconds == pytest.approx(0.03, abs=0.01)
    assert t[OTHER] == pytest.approx(0.01, abs=0.01)
    assert sum(t.values()) == pytest.approx(wall, rel=1e-12)


def test_without_a_collection_a_stage_only_measures() -> None:
    with stage("physics") as s:
        _busy(0.005)
    assert s.seconds >= 0.005
    with collect_timings() as clock:
        pass
    assert clock.totals == {}


def test_the_one_line_groups_by_the_first_name() -> None:
    line = format_breakdown({"physics": 2.0, "perception.icp": 0.6, "perception.render": 0.4, OTHER: 1.0}, 4.0)
    assert line.startswith("physics 2.00 s (50%)")
    assert "perception 1.00 s (25%: icp 0.60, render 0.40)" in line and line.endswith("other 1.00 s (25%)")


def test_process_age_is_how_long_this_process_has_run() -> None:
    age = process_age_s()
    assert age is None or 0.0 < age < 24 * 3600
