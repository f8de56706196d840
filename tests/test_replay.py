"""`twin replay`: a failed row of a small sweep (the compare-smoke warehouse queries, whose straight motions hit the
wall) run again from the spec saved beside its results: the same row in every field but times, and a recording
of the query (the robot at its start, the start and goal, the verdict line); an unknown run id or a folder
without the saved spec is a one-line error (exit 2 from the CLI)."""

from __future__ import annotations

import json
import shlex
import shutil
import subprocess
import sys

import pytest

pytest.importorskip("rerun")

import rerun as rr

from twin.compare.replay import differences, replay_row
from twin.compare.runner import run_comparison
from twin.errors import ConfigError

SPEC = """name: replay-smoke
seeds: [0]
time_limit_s: 1.0
planners: [ruckig.movej, {name: ompl.rrtconnect, retimer: toppra}]
scenarios:
  - name: warehouse-blocked
    scene: warehouse.yaml
    random: {count: 1, goal: position, straight: blocked}
"""


@pytest.fixture(scope="module")
def sweep(tmp_path_factory):
    """compare-smoke's warehouse scenario, one query, a straight-line planner and a path planner."""
    out = tmp_path_factory.mktemp("sweep")
    spec = out / "replay-smoke.yaml"
    spec.write_text(SPEC)
    result = run_comparison(str(spec), out_dir=out / "out", workers=0, plots=False)
    out = out / "out"
    rows = [json.loads(line) for line in result.results_path.read_text().splitlines()]
    return out, rows


def test_a_failed_row_replays_to_the_same_row_with_a_recording_of_its_query(sweep, tmp_path):
    out, rows = sweep
    failed = [r for r in rows if r["status"] == "collision"]
    assert failed, [r["status"] for r in rows]  # ruckig's straight joint motion runs into the wall
    row = failed[0]
    replay = replay_row(out / "results.jsonl", row["run_id"], tmp_path / "row.rrd")
    assert replay.differences == ()
    assert replay.replayed["status"] == row["status"] and replay.replayed["reason"] == row["reason"]
    chunks = list(rr.chunk.RrdReader(str(tmp_path / "row.rrd")).store().stream())
    ents = {c.entity_path for c in chunks}
    assert {"/world/query/start_goal", "/events", "/world/robot/base_link", "/world/fixtures/obstacle/shape0"} <= ents
    # the refused motion, and where it first collides: the pair the row's reason names
    assert {"/world/query/refused", "/world/query/first_collision"} <= ents
    texts = [
        t[0]
        for c in chunks
        if c.entity_path == "/events"
        for t in c.to_record_batch().column("TextLog:text").to_pylist()
    ]
    pair = row["reason"].split("collides (", 1)[1].split(",")[0]  # "the trajectory collides (A with B, densified ...)"
    assert f"first collision: {pair}" in texts
    assert any(t.startswith(f"query: {row['planner']}: collision") for t in texts)


def test_differences_leave_out_times_and_name_every_other_field():
    a = {"status": "success", "timing": {"planning_time_s": 0.1}, "metrics": {"path_length_rad": 1.0, "wall_s": 1}}
    b = {"status": "collision", "timing": {"planning_time_s": 0.2}, "metrics": {"path_length_rad": 1.5, "wall_s": 2}}
    assert differences(a, b) == ["metrics.path_length_rad: 1.0 -> 1.5", "status: 'success' -> 'collision'"]
    assert differences(a, dict(a, timing={"planning_time_s": 9.0})) == []


def test_an_unknown_row_or_a_folder_without_its_spec_is_a_one_line_error(sweep, tmp_path):
    out, rows = sweep
    with pytest.raises(ConfigError, match="no row 'nope'"):
        replay_row(out / "results.jsonl", "nope", tmp_path / "x.rrd")
    lonely = tmp_path / "lonely"
    lonely.mkdir()
    shutil.copy(out / "results.jsonl", lonely / "results.jsonl")
    with pytest.raises(ConfigError, match="saved spec"):
        replay_row(lonely / "results.jsonl", rows[0]["run_id"], tmp_path / "x.rrd")
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "twin",
            "replay",
            str(out / "results.jsonl"),
            "nope",
            "--rerun",
            str(tmp_path / "x.rrd"),
        ],
        capture_output=True,
        text=True,
        check=False,
    )
    assert r.returncode == 2 and "no row 'nope'" in r.stderr and "Traceback" not in r.stderr


def test_the_summary_lists_the_replay_command_of_each_planners_failed_rows_and_it_runs(sweep, tmp_path):
    out, rows = sweep
    text = (out / "summary.md").read_text()
    failed = [r for r in rows if not r["success"] and r["status"] != "skipped"]
    commands = [line for line in text.splitlines() if line.startswith("- ") and "twin replay" in line]
    assert len(commands) == len(failed)  # (fewer than three per planner here)
    for r in failed:
        assert any(f"'{r['run_id']}'" in c and c.startswith(f"- {r['planner']}: ") for c in commands)
    command = shlex.split(commands[0].split("`")[1])  # as a shell would read it
    done = subprocess.run(
        [sys.executable, "-m", "twin", *command[1:]], cwd=out, capture_output=True, text=True, check=False
    )
    assert done.returncode == 0, done.stderr
    assert "equals the stored one" in done.stdout


def test_a_task_row_replays_to_the_same_row_with_the_runs_recording(tmp_path):
    pytest.importorskip("crocoddyl")  # a short warehouse run
    spec = tmp_path / "task.yaml"
    spec.write_text(
        "name: replay-task\nseeds: [0]\nplanners: [croc]\nscenarios:\n  - {name: wh, task: warehouse.yaml}\n"
    )
    result = run_comparison(str(spec), out_dir=tmp_path / "out", workers=0, plots=False)
    (row,) = [json.loads(line) for line in result.results_path.read_text().splitlines()]
    croc = row["task"]["metrics"]["croc"]  # the compared planner's planning time per motion it planned
    assert row["timing"]["task_planning_time_s"] == pytest.approx(croc["planning_time_s"] / croc["motions"])
    replay = replay_row(result.results_path, row["run_id"], tmp_path / "task.rrd")
    assert replay.differences == ()
    chunks = list(rr.chunk.RrdReader(str(tmp_path / "task.rrd")).store().stream())
    texts = [
        t[0]
        for c in chunks
        if c.entity_path == "/events"
        for t in c.to_record_batch().column("TextLog:text").to_pylist()
    ]
    placed = [o for o in row["task"]["objects"] if o["placed"]]
    assert len([t for t in texts if t.startswith("verdict") and ": placed" in t]) == len(placed)
