"""twin's URDF of each Universal Robots arm it ships (`urdf/<model>.urdf`), written from the arm's DH
parameters (`twin.robot.ur_models`) and envelope primitives: one template for the family, so every arm has the same
links, joints and frames as urdf/ur5e.urdf (hand-written first; `tests/test_ur_urdf.py` checks this writes
it again byte for byte) and the same gripper (copied from it).

Link i's frame is DH frame i-1 turned by q_i and moved d_i along its axis, so tool0 is DH frame 6 (the flange).
The envelope cylinders: a joint housing per link, and the upper arm and forearm tubes along a2 and a3 at their
lateral offsets (the distance between the shoulder and elbow planes: ur_description's shoulder_offset and
shoulder_offset - elbow_offset). Radii, housing lengths and those offsets are scaled from the UR5e's by the
arm's size; masses are the ur_description ones; inertias those of solid cylinders of the tubes.

Regenerate after changing this: `python -m twin.robot.ur_urdf` (writes every arm's file but the UR5e's).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

from twin.robot.ur_models import UR_MODELS, URModel

__all__ = ["ARM_SIZES", "arm_urdf"]

_URDF_DIR = Path(__file__).resolve().parents[2] / "urdf"
_HALF_PI = "1.5707963267948966"
_GRIPPER_MARK = "  <!-- Robotiq 2F-85-like gripper."


@dataclass(frozen=True)
class ArmSize:
    """What the DH parameters do not say: the size of the links' envelopes relative to the UR5e's
    (`scale`), the upper arm's and forearm's lateral offsets (m) and the link masses (kg, base to wrist 3).
    The joints' efforts are the arm's torques (`twin.robot.ur_models`)."""

    scale: float
    upper_arm_offset_m: float
    forearm_offset_m: float
    masses: tuple[float, float, float, float, float, float, float]
    forearm_tube_m: float | None = None  # the forearm tube's length when not |a3| (the UR5e's, by hand: 0.392)


ARM_SIZES: dict[str, ArmSize] = {
    "ur3": ArmSize(0.75, 0.1198, 0.0273, (2.0, 2.0, 3.42, 1.26, 0.8, 0.8, 0.35)),
    "ur3e": ArmSize(0.75, 0.12, 0.027, (2.0, 1.98, 3.4445, 1.437, 0.871, 0.805, 0.261)),
    "ur5": ArmSize(1.0, 0.13585, 0.0162, (4.0, 3.7, 8.393, 2.275, 1.219, 1.219, 0.1879)),
    "ur5e": ArmSize(
        1.0,
        0.138,
        0.02,
        (4.0, 3.761, 8.058, 2.846, 1.37, 1.3, 0.365),
        forearm_tube_m=0.392,
    ),
    "ur10": ArmSize(1.3, 0.176, 0.039, (4.0, 7.1, 12.7, 4.27, 2.0, 2.0, 0.365)),
    "ur10e": ArmSize(1.3, 0.176, 0.039, (4.0, 7.369, 13.051, 3.989, 2.1, 1.98, 0.615)),
    "ur16e": ArmSize(1.3, 0.176, 0.039, (4.0, 7.369, 10.45, 4.321, 2.18, 2.033, 0.907)),
}

# the UR5e's envelope (urdf/ur5e.urdf, written by hand before this module): radius and length of each
# joint housing, the tubes' radii, and the inertias it gives (the others' are computed)
_UR5E_INERTIA = {
    "base_link": ("0.0061", "0.0061", "0.0113"),
    "shoulder_link": ("0.0103", "0.0103", "0.0067"),
    "upper_arm_link": ("0.0151", "0.1339", "0.1339"),
    "forearm_link": ("0.0025", "0.0375", "0.0375"),
    "wrist_1_link": ("0.0020", "0.0020", "0.0014"),
    "wrist_2_link": ("0.0018", "0.0018", "0.0013"),
    "wrist_3_link": ("0.0002", "0.0002", "0.0003"),
}


def _display(model: str) -> str:
    return "UR" + model[2:]  # ur5e -> UR5e


def _exact(x: float) -> str:
    """A DH length as the URDF writes it: exact (the joint frames must be the DH frames to 1e-6)."""
    return "0" if x == 0 else repr(float(x))


def _n(x: float) -> str:
    """A number as the URDF writes it: 0 as '0', else the shortest repr of x rounded to 0.1 mm."""
    x = round(float(x), 4) if abs(x) < 100 else float(x)
    return "0" if x == 0 else repr(x)


def _cylinder_inertia(mass: float, radius: float, length: float, axis: str) -> tuple[str, str, str]:
    """(ixx, iyy, izz) of a solid cylinder along `axis` ('x' or 'z'), 4 decimals."""
    along = 0.5 * mass * radius**2
    across = mass * (3 * radius**2 + length**2) / 12.0
    values = (along, across, across) if axis == "x" else (across, across, along)
    return tuple(f"{v:.4f}" for v in values)  # type: ignore[return-value]


Shape = tuple[str, str, float, float, str]  # a cylinder: origin xyz, rpy, radius, length, material


def _link(name: str, mass: float, com: str, inertia: tuple[str, str, str], shapes: list[Shape]) -> str:
    """A link: inertial at `com`, a visual and a collision cylinder per shape (xyz, rpy, radius, length, material)."""
    origin = f'<origin xyz="{com}"/>'
    head = (
        f'  <link name="{name}">\n'
        f'    <inertial>{origin}<mass value="{mass!r}"/>\n'
        f'      <inertia ixx="{inertia[0]}" ixy="0" ixz="0" iyy="{inertia[1]}" iyz="0" '
        f'izz="{inertia[2]}"/></inertial>\n'
    )

    def at(xyz: str, rpy: str) -> str:
        return f'<origin xyz="{xyz}" rpy="{rpy}"/>' if rpy else f'<origin xyz="{xyz}"/>'

    visuals = "".join(
        f'    <visual>{at(xyz, rpy)}<geometry><cylinder radius="{_n(r)}" length="{_n(h)}"/></geometry>'
        f'<material name="{mat}"/></visual>\n'
        for xyz, rpy, r, h, mat in shapes
    )
    collisions = "".join(
        f'    <collision>{at(xyz, rpy)}<geometry><cylinder radius="{_n(r)}" length="{_n(h)}"/></geometry></collision>\n'
        for xyz, rpy, r, h, _ in shapes
    )
    return head + visuals + collisions + "  </link>\n"


def _joint(name: str, parent: str, child: str, xyz: str, rpy: str, lower: float, effort: int) -> str:
    limit = f'{lower!r}" upper="{-lower!r}'
    return (
        f'  <joint name="{name}" type="revolute">\n'
        f'    <parent link="{parent}"/><child link="{child}"/>\n'
        f'    <origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="0 0 1"/>\n'
        f'    <limit lower="{limit}" effort="{effort}" velocity="{math.pi!r}"/>\n'
        "  </joint>\n"
    )


def arm_urdf(model: str) -> str:
    """The URDF text of arm `model` with twin's gripper."""
    arm: URModel = UR_MODELS[model]
    size = ARM_SIZES[model]
    d1, _, _, d4, d5, d6 = arm.d
    _, a2, a3, _, _, _ = arm.a
    s = size.scale
    m = size.masses
    e = [int(t) for t in arm.torques]
    up, fore = size.upper_arm_offset_m, size.forearm_offset_m

    def inertia(link: str, mass: float, r: float, h: float, axis: str) -> tuple[str, str, str]:
        return _UR5E_INERTIA[link] if model == "ur5e" else _cylinder_inertia(mass, r, h, axis)

    two_pi, pi = -2.0 * math.pi, -math.pi
    dh_text = ", ".join(
        [
            f"d1={_exact(d1)}",
            f"a2={_exact(a2)}",
            f"a3={_exact(a3)}",
            f"d4={_exact(d4)}",
            f"d5={_exact(d5)}",
            f"d6={_exact(d6)}",
        ]
    )
    out = [
        '<?xml version="1.0"?>\n',
        f"<!-- {_display(model)} with a Robotiq 2F-85-like parallel gripper, written for twin from the published "
        f"{_display(model)} DH\n",
        f"     parameters ({dh_text},\n",
        "     alpha=[pi/2,0,0,pi/2,-pi/2,0]) and link masses. Frames: base_link is the DH base frame (robot base\n",
        "     at the origin, z up); link i's frame is DH frame i-1 rotated by q_i and shifted by d_i along its axis,\n",
        "     so tool0 is DH frame 6 (the flange). Geometry is primitives that envelop the real links.\n",
        "     The gripper's tcp frame lies between the fingertips, 0.135 m along tool0's z axis. -->\n",
        f'<robot name="{model}">\n',
        '  <material name="ur_grey"><color rgba="0.75 0.75 0.78 1"/></material>\n',
        '  <material name="ur_blue"><color rgba="0.25 0.45 0.70 1"/></material>\n',
        '  <material name="black"><color rgba="0.12 0.12 0.12 1"/></material>\n',
        '  <material name="pad"><color rgba="0.30 0.30 0.30 1"/></material>\n',
        "\n",
    ]
    # the base and the shoulder housing stack up to d1 (a short-based UR5 keeps them above the table)
    base_r, base_h = 0.075 * s, min(0.09 * s, d1 - 0.02)
    sh_lo, sh_hi = max(d1 - 0.09 * s, 0.025), d1 + 0.035 * s
    tube_r, fore_r, w_r = 0.054 * s, 0.04 * s, 0.045 * s
    fore_len = size.forearm_tube_m or abs(a3)
    half = f"0 {_HALF_PI} 0"
    # per link: (its joint: name, origin xyz, rpy, lower limit) or None, (mass, centre of mass, inertia
    # cylinder: radius, length, axis), its cylinders: (xyz, rpy, radius, length, material)
    chain: list[tuple[tuple[str, str, str, float] | None, str, tuple[str, float, float, str], list[Shape]]] = [
        (None, "base_link", (f"0 0 {_n(base_h / 2)}", base_r, base_h, "z"),
         [(f"0 0 {_n(base_h / 2)}", "", base_r, base_h, "ur_grey")]),
        (("shoulder_pan_joint", f"0 0 {_exact(d1)}", "0 0 0", two_pi), "shoulder_link",
         ("0 0 0", 0.06 * s, sh_hi - sh_lo, "z"),
         [(f"0 0 {_n((sh_lo + sh_hi) / 2 - d1)}", "", 0.06 * s, sh_hi - sh_lo, "ur_blue")]),
        (("shoulder_lift_joint", "0 0 0", f"{_HALF_PI} 0 0", two_pi), "upper_arm_link",
         (f"{_n(a2 / 2)} 0 {_n(up)}", tube_r, abs(a2), "x"),
         [(f"0 0 {_n(0.10 * s)}", "0 0 0", 0.06 * s, 0.12 * s, "ur_grey"),
          (f"{_n(a2 / 2)} 0 {_n(up)}", half, tube_r, abs(a2), "ur_grey")]),
        (("elbow_joint", f"{_exact(a2)} 0 0", "0 0 0", pi), "forearm_link",
         (f"{_n(-fore_len / 2)} 0 {_n(fore)}", fore_r, fore_len, "x"),
         [(f"0 0 {_n(0.085 * s)}", "", 0.052 * s, 0.14 * s, "ur_blue"),
          (f"{_n(-fore_len / 2)} 0 {_n(fore)}", half, fore_r, fore_len, "ur_grey")]),
        (("wrist_1_joint", f"{_exact(a3)} 0 {_exact(d4)}", "0 0 0", two_pi), "wrist_1_link",
         ("0 0 0", w_r, 0.13 * s, "z"), [(f"0 0 {_n(-0.02 * s)}", "", w_r, 0.13 * s, "ur_grey")]),
        (("wrist_2_joint", f"0 {_exact(-d5)} 0", f"{_HALF_PI} 0 0", two_pi), "wrist_2_link",
         ("0 0 0", w_r, 0.11 * s, "z"), [(f"0 0 {_n(-0.005 * s)}", "", w_r, 0.11 * s, "ur_blue")]),
        (("wrist_3_joint", f"0 {_exact(d6)} 0", f"-{_HALF_PI} 0 0", two_pi), "wrist_3_link",
         (f"0 0 {_n(-0.02 * s)}", 0.0375 * s, 0.048 * s, "z"),
         [(f"0 0 {_n(-0.024 * s)}", "", 0.0375 * s, 0.048 * s, "ur_grey")]),
    ]  # fmt: skip
    parent = ""
    for k, (joint, link, (com, r, h, axis), shapes) in enumerate(chain):
        if joint is not None:
            name, xyz, rpy, lower = joint
            out.append("\n" + _joint(name, parent, link, xyz, rpy, lower, e[k - 1]))
        out.append(_link(link, m[k], com, inertia(link, m[k], r, h, axis), shapes))
        parent = link
    out.append(
        "\n"
        '  <joint name="flange_joint" type="fixed">\n'
        '    <parent link="wrist_3_link"/><child link="tool0"/><origin xyz="0 0 0" rpy="0 0 0"/>\n'
        "  </joint>\n"
        '  <link name="tool0">\n'
        '    <inertial><mass value="0.001"/>'
        '<inertia ixx="1e-7" ixy="0" ixz="0" iyy="1e-7" iyz="0" izz="1e-7"/></inertial>\n'
        "  </link>\n"
        "\n"
    )
    ur5e = (_URDF_DIR / "ur5e.urdf").read_text()
    out.append(ur5e[ur5e.index(_GRIPPER_MARK) :])  # the gripper: the same on every arm
    return "".join(out)


def main() -> int:
    for model in UR_MODELS:
        if model != "ur5e":
            (_URDF_DIR / f"{model}.urdf").write_text(arm_urdf(model))
            sys.stdout.write(f"wrote urdf/{model}.urdf\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
