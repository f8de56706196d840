"""Config fuzzing at scale (issue 12). A plain script: prints counts, asserts nothing.

    python bench/bench_config_fuzz.py [--cases 2000] [--no-world] [--show 5]

Runs the generator of tests/test_config_fuzz.py (mutations of configs/robocup.yaml and warehouse.yaml:
dropped keys, wrong types, NaN / huge numbers, unknown keys, bad planner blocks, bad fixture URDFs, bad
object lists, deep nesting, damaged bytes) over `--cases` derandomized cases; each file goes through
load -> planning scene -> every planner -> PyBullet world, as in the test. Prints how many cases were
accepted, rejected with a one-line TwinError (by stage), and failed: another exception (a traceback), a
message over several lines, or a hang (a case still running after 30 s), with the first failures.
"""

from __future__ import annotations

import argparse
import collections
import faulthandler
import signal
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, given, settings

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))

from test_config_fuzz import Outcome, config_files, run_config  # noqa: E402 - importable once tests/ is on the path

HANG_S = 30


class _Hang(BaseException):  # not an Exception: run_config must not report it as a rejection or a crash
    pass


def _alarm(signum: int, frame: Any) -> None:
    raise _Hang()


def _gist(o: Outcome) -> str:
    """The kind of a rejection: its stage and message without the file path, quoted values and numbers."""
    import re

    msg = o.message.replace(str(Path(tempfile.gettempdir())), "")
    msg = re.sub(r"/\S*fuzz\.yaml", "<file>", msg)
    msg = re.sub(r"'[^']*'|\"[^\"]*\"|\(got .*?\)|-?\d+(\.\d+)?(e-?\d+)?", "_", msg)
    return f"{o.stage}: {msg[:110]}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", type=int, default=2000, help="number of fuzzed config files (default 2000)")
    ap.add_argument("--no-world", action="store_true", help="skip the PyBullet world build (faster)")
    ap.add_argument("--show", type=int, default=5, help="failures to print in full (default 5)")
    args = ap.parse_args()

    outcomes: list[tuple[Outcome, bytes, float]] = []
    signal.signal(signal.SIGALRM, _alarm)
    workdir = tempfile.TemporaryDirectory(prefix="twin-fuzz-")
    tmp = Path(workdir.name)

    @settings(
        max_examples=args.cases, derandomize=True, deadline=None, database=None, suppress_health_check=list(HealthCheck)
    )
    @given(config_files())
    def one(content: bytes) -> None:
        path = tmp / "fuzz.yaml"
        path.write_bytes(content)
        t0 = time.perf_counter()
        # a hang inside C code never returns to Python for the alarm: dump the stacks and exit after 3x
        faulthandler.dump_traceback_later(3 * HANG_S, exit=True)
        signal.alarm(HANG_S)
        try:
            out = run_config(path, world=not args.no_world)
        except _Hang:
            out = Outcome("failed", "hang", f"still running after {HANG_S} s")
        finally:
            signal.alarm(0)
            faulthandler.cancel_dump_traceback_later()
        outcomes.append((out, content, time.perf_counter() - t0))

    t0 = time.perf_counter()
    try:
        one()
    finally:
        workdir.cleanup()
    wall = time.perf_counter() - t0
    kinds = collections.Counter(o.kind for o, _, _ in outcomes)
    stages = collections.Counter(o.stage for o, _, _ in outcomes if o.kind == "rejected")
    times = sorted(dt for _, _, dt in outcomes)
    print(
        f"{len(outcomes)} cases in {wall:.1f} s (median {times[len(times) // 2] * 1e3:.0f} ms, "
        f"max {times[-1]:.2f} s per case)"
    )
    print(f"accepted: {kinds['accepted']}")
    print(
        "rejected with a one-line TwinError: "
        f"{kinds['rejected']} ({', '.join(f'{s} {n}' for s, n in stages.most_common())})"
    )
    print(f"failed (traceback / multi-line / hang > {HANG_S} s): {kinds['failed']}")
    errors = collections.Counter(_gist(o) for o, _, _ in outcomes if o.kind == "rejected")
    print("most common rejections:")
    for m, n in errors.most_common(12):
        print(f"  {n:5d}  {m}")
    shown = 0
    for o, content, _ in outcomes:
        if o.kind == "failed" and shown < args.show:
            shown += 1
            print(
                f"\n--- failure {shown}: stage {o.stage} ---\n{o.message[-3000:]}"
                f"\nconfig (first 600 bytes): {content[:600]!r}"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
