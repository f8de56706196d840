"""`twin replay RESULTS.jsonl RUN_ID --rerun OUT.rrd`: one comparison row run again, from the spec its sweep saved
beside its results (`compare.json`) and the row's seed, with a Rerun recording of it, and what differs from the
stored row.

Runs are deterministic on one machine (the same config and seed give the same result), so a replayed row equals
the stored one in every field that is not a time; a difference says the code or the machine changed since.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from twin.compare.runner import SPEC_FILE, latest_rows, read_results
from twin.compare.spec import CompareSpec, expand_runs
from twin.compare.worker import execute_run
from twin.errors import ConfigError

__all__ = ["Replay", "differences", "replay_row"]

# fields that are measurements of time (or of the machine), not results: a replay is not asked to repeat them
_TIMING_WORDS = ("time", "wall", "timing", "environment")


@dataclass(frozen=True)
class Replay:
    """The stored row, the replayed one, the differences in fields that are not times, and the recording."""

    stored: dict[str, Any]
    replayed: dict[str, Any]
    differences: tuple[str, ...]
    recording: Path


def differences(a: Any, b: Any, where: str = "") -> list[str]:
    """Where two rows differ, field by field (dotted paths), leaving out fields about time."""
    if isinstance(a, dict) and isinstance(b, dict):
        out: list[str] = []
        for k in sorted(set(a) | set(b)):
            if any(w in k for w in _TIMING_WORDS):
                continue
            out += differences(a.get(k), b.get(k), f"{where}.{k}" if where else k)
        return out
    if isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        return [d for i, (x, y) in enumerate(zip(a, b, strict=True)) for d in differences(x, y, f"{where}[{i}]")]
    if isinstance(a, float) and isinstance(b, float) and (a == b or (a != a and b != b)):  # NaN == NaN here
        return []
    return [] if a == b else [f"{where}: {a!r} -> {b!r}"]


def replay_row(results: str | Path, run_id: str, rerun: str | Path) -> Replay:
    """Run the row `run_id` of the results file `results` again, with a recording written to `rerun`."""
    path = Path(results)
    if path.is_dir():
        path = path / "results.jsonl"
    if not path.is_file():
        raise ConfigError(f"no results file at {path}")
    rows = {r["run_id"]: r for r in latest_rows(read_results(path))}
    if run_id not in rows:
        some = ", ".join(list(rows)[:5])
        raise ConfigError(f"{path}: no row {run_id!r}; its rows are e.g. {some} ({len(rows)} in all)")
    spec_file = path.parent / SPEC_FILE
    try:
        saved = json.loads(spec_file.read_text())
        spec = CompareSpec.model_validate(saved["spec"])
    except (OSError, ValueError, KeyError) as e:
        raise ConfigError(f"{spec_file}: the sweep's saved spec is needed to replay a row ({e})") from None
    tasks = {t.run_id: t for t in expand_runs(spec, saved.get("definitions"))}
    if run_id not in tasks:
        raise ConfigError(f"{spec_file}: the saved spec has no run {run_id!r} (the results come from another spec)")
    replayed = execute_run(tasks[run_id], rerun=str(rerun))
    stored = rows[run_id]
    return Replay(stored, replayed, tuple(differences(stored, replayed)), Path(rerun))
