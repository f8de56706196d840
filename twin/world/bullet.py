"""PyBullet, imported once for the whole `twin.world` package with its banner silenced.

Every module of the package takes `pb` from here, so the import (and its "pybullet build time" line on
stderr) happens in one place, and C-level prints of PyBullet and its EGL plugin are silenced the same way
everywhere (`quiet_fds`, `quiet_stdout`).
"""

from __future__ import annotations

import os
import sys
from collections.abc import Iterator
from contextlib import contextmanager

__all__ = ["URDF_FLAGS", "pb", "quiet_fds", "quiet_stdout"]


def _flush_c_stdout() -> None:
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except Exception:  # noqa: BLE001 - not on every platform; then some noise may get through
        pass


@contextmanager
def quiet_fds(*fds: int) -> Iterator[None]:
    """Silence C-level writes to these file descriptors (1: stdout, 2: stderr) while the block runs: PyBullet
    and its EGL plugin print banners from C (`printf`), which `sys.stdout`/`sys.stderr` never see. Keep the
    block short: Python's own writes to a silenced fd (a log line) are lost too."""
    saved: list[tuple[int, int]] = []  # (fd, a copy of what it was)
    try:
        for stream in (sys.stdout, sys.stderr):
            stream.flush()
        with open(os.devnull, "wb") as devnull:
            for fd in fds:
                saved.append((fd, os.dup(fd)))
                os.dup2(devnull.fileno(), fd)
    except (OSError, ValueError, AttributeError):  # no such fd, or a closed stream: what it printed shows
        pass
    try:
        yield
    finally:
        _flush_c_stdout()
        for fd, copy in saved:
            os.dup2(copy, fd)
            os.close(copy)


with quiet_fds(2):  # "pybullet build time: ..." on stderr, at every import: no output of twin's
    import pybullet as pb


# Implicit cylinders: PyBullet otherwise meshes every cylinder into a polygon, and its geometry then
# differs from the FCL planning scene's exact cylinders by up to 2 mm.
URDF_FLAGS = pb.URDF_USE_INERTIA_FROM_FILE | pb.URDF_USE_IMPLICIT_CYLINDER


@contextmanager
def quiet_stdout(active: bool = True) -> Iterator[None]:
    """Silence C-level writes to stdout (fd 1) from PyBullet plugins; library code prints nothing."""
    if not active:
        yield
        return
    with quiet_fds(1):
        yield
