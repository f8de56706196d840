"""The compiled half of `twin_nmpc.model.sphere_centres`: every proxy sphere's centre for a batch of
configurations in one numba loop. Both MPCs place their spheres on the plan a solve starts from, on every round's
iterate and in every plan check; numpy's per-frame batched products took ~0.1 ms for the 7 seed spheres and
~0.14 ms for the whole arm's 38 over a 31-knot horizon, this loop a few microseconds.
"""

from __future__ import annotations

import numpy as np
from numba import njit

__all__ = ["sphere_centres_into"]


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
