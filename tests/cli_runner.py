"""`twin ...` as a user runs it: a subprocess from the checkout, for the tests of the command line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def twin(*args: str, extra_path: Path | None = None, timeout: float = 300) -> subprocess.CompletedProcess[str]:
    """Run `python -m twin *args` in the checkout; `extra_path` goes in front of PYTHONPATH (a test plugin)."""
    env = dict(os.environ)
    if extra_path is not None:
        env["PYTHONPATH"] = os.pathsep.join([str(extra_path), env.get("PYTHONPATH", "")])
    return subprocess.run(
        [sys.executable, "-m", "twin", *args],
        capture_output=True,
        text=True,
        env=env,
        cwd=ROOT,
        timeout=timeout,
        check=False,
    )
