"""Colour labels from a cluster's mean RGB, robust to the renderer's shading.

Lit surfaces come out at ~0.8-0.95 of their material colour, so colours are compared by direction
(chromaticity, which shading keeps) plus a weak term on brightness (log ratio), which separates black
from grey and navy from bright blue.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from twin.scene_layout import color_rgba

__all__ = ["classify_color", "color_distance", "palette"]

_BRIGHTNESS_WEIGHT = 0.5
_FLOOR = 0.02  # keeps the log ratio finite for black


def palette(names: Sequence[str]) -> dict[str, np.ndarray]:
    """RGB (3,) in [0, 1] of colour names from `twin.scene_layout.COLORS` (ConfigError when unknown)."""
    return {n: np.array(color_rgba(n)[:3], dtype=float) for n in names}


def color_distance(rgb: np.ndarray, ref: np.ndarray) -> float:
    """Chromaticity distance plus a brightness log-ratio term; 0 for the same colour."""
    a, b = np.asarray(rgb, dtype=float), np.asarray(ref, dtype=float)
    na, nb = np.linalg.norm(a), np.linalg.norm(b)
    chroma = float(np.linalg.norm(a / max(na, 1e-9) - b / max(nb, 1e-9)))
    return chroma + _BRIGHTNESS_WEIGHT * abs(float(np.log((na + _FLOOR) / (nb + _FLOOR))))


def classify_color(rgb: np.ndarray, labels: Sequence[str] | Mapping[str, np.ndarray]) -> str:
    """The nearest label by `color_distance`; `labels` are colour names or a name -> RGB mapping."""
    refs = labels if isinstance(labels, Mapping) else palette(list(labels))
    return min(refs, key=lambda k: color_distance(rgb, refs[k]))
