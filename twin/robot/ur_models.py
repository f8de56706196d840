"""The Universal Robots arms twin can simulate, one table: their DH parameters and datasheet joint limits.

DH (standard convention, d and a in m, alpha in rad): Universal Robots, "DH parameters for calculations of
kinematics and dynamics" (universal-robots.com/articles/ur/application-installation/dh-parameters-for-
calculations-of-kinematics-and-dynamics/), the same numbers `ur_analytic_ik` compiles its closed-form IK from
(its `dh_parameters.hh`; tests/test_ur_models.py checks the two agree). Every arm of the family has alpha =
(pi/2, 0, 0, pi/2, -pi/2, 0) and a1 = a4 = a5 = a6 = d2 = d3 = 0.

Joint limits: the arms' datasheets ("Technical specifications", UR3/UR5/UR10 CB3 and UR3e/UR5e/UR10e/UR16e
e-Series): every joint turns +-360 degrees; the largest joint speeds are 180 deg/s for each UR5/UR5e joint;
120 deg/s for the base and shoulder of the UR10, UR10e and UR16e (180 deg/s for their other joints); 360 deg/s
for the wrists of the UR3 and UR3e (180 deg/s for their other joints).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from twin.errors import ConfigError

__all__ = ["ALPHA", "UR_MODELS", "URModel", "ur_model"]

ALPHA = (math.pi / 2, 0.0, 0.0, math.pi / 2, -math.pi / 2, 0.0)
_DEG = math.pi / 180.0


@dataclass(frozen=True)
class URModel:
    """One arm: its name (the `ur_analytic_ik` submodule and `robot.model`), DH d and a (6,), and the
    datasheet's position range and largest speed per joint (rad, rad/s)."""

    name: str
    d: tuple[float, float, float, float, float, float]
    a: tuple[float, float, float, float, float, float]
    max_speed: tuple[float, float, float, float, float, float]
    torques: tuple[float, float, float, float, float, float]  # N m the joint motors hold (the simulator's force limit)
    position_range: float = 2.0 * math.pi  # +- this, every joint

    @property
    def alpha(self) -> tuple[float, ...]:
        return ALPHA

    @property
    def reach_m(self) -> float:
        """The flange's furthest distance from the shoulder axis, arm stretched: |a2| + |a3| + d5 (roughly
        the datasheet's reach, which is measured to the flange)."""
        return abs(self.a[1]) + abs(self.a[2]) + self.d[4]

    def speed_limits(self) -> np.ndarray:
        """(6,) the datasheet's largest joint speeds, rad/s."""
        return np.array(self.max_speed, dtype=float)


# name, DH d1 d4 d5 d6, a2 a3 (m); largest speed of the base and shoulder, the elbow, the wrists (deg/s);
# joint torques (N m), as the datasheets and ur_analytic_ik's dh_parameters.hh list them
_TABLE = (
    ("ur3", (0.1519, 0.11235, 0.08535, 0.0819), (-0.24365, -0.21325), (180, 180, 360), (56, 56, 28, 12, 12, 12)),
    ("ur3e", (0.15185, 0.13105, 0.08535, 0.0921), (-0.24355, -0.2132), (180, 180, 360), (56, 56, 28, 12, 12, 12)),
    ("ur5", (0.089159, 0.10915, 0.09465, 0.0823), (-0.425, -0.39225), (180, 180, 180), (150, 150, 150, 28, 28, 28)),
    ("ur5e", (0.1625, 0.1333, 0.0997, 0.0996), (-0.425, -0.3922), (180, 180, 180), (150, 150, 150, 28, 28, 28)),
    ("ur10", (0.1273, 0.163941, 0.1157, 0.0922), (-0.612, -0.5723), (120, 180, 180), (330, 330, 150, 56, 56, 56)),
    ("ur10e", (0.1807, 0.17415, 0.11985, 0.11655), (-0.6127, -0.57155), (120, 180, 180), (330, 330, 150, 56, 56, 56)),
    ("ur16e", (0.1807, 0.17415, 0.11985, 0.11655), (-0.4784, -0.36), (120, 180, 180), (330, 330, 150, 56, 56, 56)),
)


def _model(
    name: str,
    d: tuple[float, float, float, float],
    a: tuple[float, float],
    speeds: tuple[int, int, int],
    torques: tuple[int, ...],
) -> URModel:
    b, e, w = (v * _DEG for v in speeds)
    t = tuple(float(x) for x in torques)
    return URModel(
        name,
        d=(d[0], 0.0, 0.0, d[1], d[2], d[3]),
        a=(0.0, a[0], a[1], 0.0, 0.0, 0.0),
        max_speed=(b, b, e, w, w, w),
        torques=(t[0], t[1], t[2], t[3], t[4], t[5]),
    )


UR_MODELS: dict[str, URModel] = {row[0]: _model(*row) for row in _TABLE}


def ur_model(name: str) -> URModel:
    """The arm called `name`; ConfigError naming the arms there are."""
    try:
        return UR_MODELS[name]
    except KeyError:
        raise ConfigError(f"robot.model: unknown arm {name!r}; allowed: {', '.join(UR_MODELS)}") from None
