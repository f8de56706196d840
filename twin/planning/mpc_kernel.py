"""The compiled loops of the MPCs' sphere model: every proxy sphere's centre for a batch of configurations
(`twin.planning.proxy_spheres.sphere_centres`) and the gaps of sphere pairs (`twin.planning.selfrows.pair_gaps`).
A module of its own so that numba is loaded only by a process that plans with an MPC. Both MPCs place their
spheres on the plan a solve starts from, on every round's iterate and in every plan check; numpy's per-frame
batched products took ~0.1 ms for the 7 seed spheres and ~0.14 ms for the whole arm's 38 over a 31-knot
horizon, this loop a few microseconds.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

__all__ = ["pair_gaps_into", "sphere_centres_into"]


@njit(cache=True, nogil=True)
def sphere_centres_into(
    frames: np.ndarray, tool: np.ndarray, frame: np.ndarray, offset: np.ndarray, out: np.ndarray
) -> None:
    """out[m, n] = the centre of sphere n (its DH frame `frame[n]` 0..6, or 7: the flange times `tool`, and its
    `offset[n]` (3,) in that frame) at configuration m, from DH frames (M, 7, 4, 4)."""
    for m in range(frames.shape[0]):
        for n in range(frame.shape[0]):
            f = frame[n]
            x, y, z = offset[n, 0], offset[n, 1], offset[n, 2]
            if f == 7:  # the tcp: the flange frame, moved along the tool
                for i in range(3):
                    out[m, n, i] = (
                        frames[m, 6, i, 0] * (tool[0, 0] * x + tool[0, 1] * y + tool[0, 2] * z + tool[0, 3])
                        + frames[m, 6, i, 1] * (tool[1, 0] * x + tool[1, 1] * y + tool[1, 2] * z + tool[1, 3])
                        + frames[m, 6, i, 2] * (tool[2, 0] * x + tool[2, 1] * y + tool[2, 2] * z + tool[2, 3])
                        + frames[m, 6, i, 3]
                    )
            else:
                for i in range(3):
                    out[m, n, i] = (
                        frames[m, f, i, 0] * x + frames[m, f, i, 1] * y + frames[m, f, i, 2] * z + frames[m, f, i, 3]
                    )


@njit(cache=True, nogil=True)
def pair_gaps_into(centres: np.ndarray, radii: np.ndarray, pairs: np.ndarray, out: np.ndarray) -> None:
    """out[k, p] = how far apart the spheres of pair p are at knot k (negative: overlapping); compiled, since it
    runs at every solve (numpy's gathers cost ~0.4 ms for the whole arm's ~380 pairs over 31 knots)."""
    for k in range(centres.shape[0]):
        for p in range(pairs.shape[0]):
            i, j = pairs[p, 0], pairs[p, 1]
            dx = centres[k, i, 0] - centres[k, j, 0]
            dy = centres[k, i, 1] - centres[k, j, 1]
            dz = centres[k, i, 2] - centres[k, j, 2]
            out[k, p] = math.sqrt(dx * dx + dy * dy + dz * dz) - radii[i] - radii[j]
