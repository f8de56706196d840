"""What a Rerun recording costs (issue 29): `twin run CONFIG --seed N` with and without `--rerun OUT.rrd`, in turn,
each in a fresh process, the same seeds; prints the wall time of each, the ratio, and the recording's size.
A plain script: prints numbers, asserts nothing.

    python bench/bench_recording.py [--config robocup] [--seeds 3] [--first-seed 0]

The issue's budget: recording adds at most 25 % to a RoboCup run's wall time, the file stays under 30 MB.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def run(config: str, seed: int, rrd: Path | None) -> float:
    """Wall seconds of one `twin run` (process start to exit)."""
    cmd = [sys.executable, "-m", "twin", "run", config, "--seed", str(seed)]
    if rrd is not None:
        cmd += ["--rerun", str(rrd)]
    t0 = time.perf_counter()
    r = subprocess.run(cmd, cwd=ROOT, capture_output=True, text=True, check=False)
    wall = time.perf_counter() - t0
    if r.returncode not in (0, 1):
        raise SystemExit(f"{' '.join(cmd)} failed: {r.stderr.strip().splitlines()[-3:]}")
    return wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--config", default="robocup")
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--first-seed", type=int, default=0)
    args = ap.parse_args()
    plain, recorded, sizes = [], [], []
    with tempfile.TemporaryDirectory() as d:
        for seed in range(args.first_seed, args.first_seed + args.seeds):
            rrd = Path(d) / f"{args.config}-{seed}.rrd"
            a = run(args.config, seed, None)
            b = run(args.config, seed, rrd)
            size = rrd.stat().st_size / 1e6
            plain.append(a)
            recorded.append(b)
            sizes.append(size)
            print(f"{args.config} seed {seed}: plain {a:6.2f} s   --rerun {b:6.2f} s   x{b / a:.2f}   {size:5.1f} MB")
    a, b = statistics.median(plain), statistics.median(recorded)
    print(
        f"\n{args.config}, {args.seeds} seeds: median wall plain {a:.2f} s, with --rerun {b:.2f} s "
        f"(+{100 * (b / a - 1):.0f} %, budget +25 %); recording median {statistics.median(sizes):.1f} MB, "
        f"largest {max(sizes):.1f} MB (budget 30 MB)"
    )


if __name__ == "__main__":
    main()
