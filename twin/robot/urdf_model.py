"""A small URDF reader: kinematic tree, collision primitives and vectorised forward kinematics.

Why it exists: the FCL planning scene must collide exactly the geometry PyBullet simulates, so both read
the same URDF files (one source of truth). This module is pybullet-free and only needs numpy.

Conventions (URDF): a joint's `origin` places the child link frame in the parent link frame at zero
joint value; `rpy` is fixed-axis roll-pitch-yaw, R = Rz(yaw) @ Ry(pitch) @ Rx(roll); revolute and
continuous joints rotate about `axis`, prismatic joints translate along it, both in the child frame.
Each collision element's `origin` places the shape in its link frame. Cylinders and capsules lie along
their local z axis (`length` excludes a capsule's hemispherical caps, as in PyBullet).

Visual geometry is not modelled; only the visual colours are read (`urdf_rgba`, `urdf_link_rgba`), so a
detector can know an object's colour from the same file PyBullet renders. Rotation helpers live in
`twin.transforms` (re-exported here under their old names).
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from twin.errors import ConfigError, InvalidRequestError
from twin.transforms import pose_from_xyz_rpy, rpy_to_matrix  # re-exported: importers use these names from here

__all__ = [
    "RGBA",
    "FixtureShape",
    "Joint",
    "Link",
    "RobotModel",
    "Shape",
    "pose_from_xyz_rpy",
    "primitive_half_extents",
    "read_fixture_shapes",
    "rpy_to_matrix",
    "urdf_link_rgba",
    "urdf_rgba",
]

_MOVABLE = ("revolute", "continuous", "prismatic")
_KNOWN_JOINT_TYPES = ("revolute", "continuous", "prismatic", "fixed", "floating", "planar")


@dataclass(frozen=True, eq=False)
class Shape:
    """One collision primitive of a link.

    kind: 'box' (size = (x, y, z) full extents), 'cylinder' (size = (radius, length)),
    'sphere' (size = (radius,)), 'capsule' (size = (radius, length)) or 'mesh' (size = scale, `mesh`
    = filename; the planning scene rejects meshes). origin: (4, 4) pose in the link frame.
    """

    kind: str
    size: tuple[float, ...]
    origin: np.ndarray
    link: str
    index: int = 0
    mesh: str | None = None

    @property
    def name(self) -> str:
        """'link' for a link's only/first shape, 'link#i' for the others."""
        return self.link if self.index == 0 else f"{self.link}#{self.index}"


def primitive_half_extents(kind: str, size: Sequence[float]) -> np.ndarray:
    """(3,) half extents along its own axes of a primitive (`Shape` kinds and sizes; a cylinder's and a
    capsule's axis is z). ValueError for a mesh or an unknown kind."""
    if kind == "box":
        return np.asarray(size, dtype=float) / 2.0
    if kind in ("cylinder", "capsule"):
        r, length = float(size[0]), float(size[1]) + (2.0 * float(size[0]) if kind == "capsule" else 0.0)
        return np.array([r, r, length / 2.0])
    if kind == "sphere":
        return np.full(3, float(size[0]))
    raise ValueError(f"no half extents for a {kind!r}: primitives only (box, cylinder, capsule, sphere)")


@dataclass(frozen=True, eq=False)
class Joint:
    """A URDF joint. origin: (4, 4) child frame in the parent frame at zero; axis: (3,) unit vector."""

    name: str
    type: str
    parent: str
    child: str
    origin: np.ndarray
    axis: np.ndarray
    lower: float = -math.inf
    upper: float = math.inf
    effort: float = math.inf
    velocity: float = math.inf
    mimic: tuple[str, float, float] | None = None  # (joint, multiplier, offset)

    @property
    def movable(self) -> bool:
        return self.type in _MOVABLE


@dataclass(frozen=True, eq=False)
class Link:
    """A URDF link and its collision shapes (visual geometry is ignored)."""

    name: str
    shapes: tuple[Shape, ...] = field(default_factory=tuple)


def _floats(text: str | None, n: int, default: Sequence[float], where: str) -> tuple[float, ...]:
    if text is None:
        return tuple(float(v) for v in default)
    try:
        vals = tuple(float(v) for v in text.split())
    except ValueError:
        raise ConfigError(f"{where}: expected {n} numbers, got {text!r}") from None
    if len(vals) != n:
        raise ConfigError(f"{where}: expected {n} numbers, got {text!r}")
    return vals


def _origin(el: ET.Element | None, where: str) -> np.ndarray:
    if el is None:
        return np.eye(4)
    xyz = _floats(el.get("xyz"), 3, (0, 0, 0), f"{where} origin xyz")
    rpy = _floats(el.get("rpy"), 3, (0, 0, 0), f"{where} origin rpy")
    return pose_from_xyz_rpy(xyz, rpy)


def _attr(el: ET.Element, name: str, where: str) -> float:
    v = el.get(name)
    if v is None:
        raise ConfigError(f"{where}: <{el.tag}> needs attribute {name!r}")
    try:
        return float(v)
    except ValueError:
        raise ConfigError(f"{where}: <{el.tag} {name}={v!r}> is not a number") from None


def _shape(col: ET.Element, link: str, index: int, where: str) -> Shape | None:
    geom = col.find("geometry")
    if geom is None or len(geom) == 0:
        raise ConfigError(f"{where}: link {link!r} has a <collision> without <geometry>")
    g = geom[0]
    origin = _origin(col.find("origin"), f"{where} link {link!r}")
    w = f"{where} link {link!r}"
    if g.tag == "box":
        size = _floats(g.get("size"), 3, (), f"{w} box size")
        return Shape("box", size, origin, link, index)
    if g.tag == "cylinder":
        return Shape("cylinder", (_attr(g, "radius", w), _attr(g, "length", w)), origin, link, index)
    if g.tag == "capsule":
        return Shape("capsule", (_attr(g, "radius", w), _attr(g, "length", w)), origin, link, index)
    if g.tag == "sphere":
        return Shape("sphere", (_attr(g, "radius", w),), origin, link, index)
    if g.tag == "mesh":
        scale = _floats(g.get("scale"), 3, (1, 1, 1), f"{w} mesh scale")
        return Shape("mesh", scale, origin, link, index, mesh=g.get("filename"))
    raise ConfigError(f"{where}: link {link!r} has unsupported collision geometry <{g.tag}>")


def _read_root(source: str | Path, text: str | None = None) -> ET.Element:
    """The <robot> element of a URDF file (or of `text`); ConfigError when missing or malformed."""
    where = str(source)
    if text is None and not Path(source).is_file():  # a directory or a device would not parse (or block)
        raise ConfigError(f"URDF file not found: {where} (not a regular file)")
    try:
        root = ET.fromstring(text) if text is not None else ET.parse(str(source)).getroot()
    except FileNotFoundError:
        raise ConfigError(f"URDF file not found: {where}") from None
    except OSError as e:
        raise ConfigError(f"cannot read URDF {where}: {e.strerror or e}") from None
    except ET.ParseError as e:
        raise ConfigError(f"{where}: not valid XML ({e})") from None
    if root.tag != "robot":
        raise ConfigError(f"{where}: the root element must be <robot>, got <{root.tag}>")
    return root


def _parse(source: str | Path, text: str | None = None) -> tuple[str, dict[str, Link], dict[str, Joint]]:
    where = str(source)
    root = _read_root(source, text)
    links: dict[str, Link] = {}
    for le in root.findall("link"):
        name = le.get("name")
        if not name:
            raise ConfigError(f"{where}: a <link> has no name")
        if name in links:
            raise ConfigError(f"{where}: link {name!r} is defined twice")
        shapes = [_shape(c, name, i, where) for i, c in enumerate(le.findall("collision"))]
        links[name] = Link(name, tuple(s for s in shapes if s is not None))
    joints: dict[str, Joint] = {}
    for je in root.findall("joint"):
        name = je.get("name") or ""
        jtype = je.get("type") or ""
        w = f"{where} joint {name!r}"
        if not name or jtype not in _KNOWN_JOINT_TYPES:
            raise ConfigError(f"{w}: needs a name and a type in {_KNOWN_JOINT_TYPES}, got type {jtype!r}")
        if jtype in ("floating", "planar"):
            raise ConfigError(f"{w}: {jtype} joints are not supported")
        pe, ce = je.find("parent"), je.find("child")
        if pe is None or ce is None or pe.get("link") not in links or ce.get("link") not in links:
            raise ConfigError(f"{w}: parent/child must name defined links")
        axis_el = je.find("axis")
        axis = np.array(_floats(axis_el.get("xyz") if axis_el is not None else None, 3, (1, 0, 0), f"{w} axis"))
        nrm = float(np.linalg.norm(axis))
        if jtype != "fixed" and nrm < 1e-12:
            raise ConfigError(f"{w}: axis must be non-zero")
        axis = axis / nrm if nrm > 0 else axis
        lower, upper, effort, velocity = -math.inf, math.inf, math.inf, math.inf
        lim = je.find("limit")
        if lim is not None:
            effort = float(lim.get("effort", "inf"))
            velocity = float(lim.get("velocity", "inf"))
            if jtype != "continuous":
                lower = float(lim.get("lower", "0"))
                upper = float(lim.get("upper", "0"))
        elif jtype in ("revolute", "prismatic"):
            raise ConfigError(f"{w}: a {jtype} joint needs <limit>")
        mim = je.find("mimic")
        mimic = None
        if mim is not None:
            mimic = (mim.get("joint") or "", float(mim.get("multiplier", "1")), float(mim.get("offset", "0")))
        if name in joints:
            raise ConfigError(f"{where}: joint {name!r} is defined twice")
        joints[name] = Joint(
            name,
            jtype,
            pe.get("link") or "",
            ce.get("link") or "",
            _origin(je.find("origin"), w),
            axis,
            lower,
            upper,
            effort,
            velocity,
            mimic,
        )
    robot_name = root.get("name") or Path(str(source)).stem
    return robot_name, links, joints


class RobotModel:
    """A URDF kinematic tree with collision primitives and vectorised forward kinematics.

    `arm_joints` are the joints driven by `q_arm` (default: the revolute/continuous joints in tree
    order, i.e. shoulder_pan .. wrist_3 for urdf/ur5e.urdf). `gripper_joints` (default: every prismatic
    joint) are set from `finger_opening`, the total width between the fingers in m, each finger moving
    half of it along its axis (clipped to its limits). Every other movable joint sits at 0 unless given
    in `joint_values`; mimic joints follow their leader.

    Poses are in the model's base frame, where the root link sits at `root_pose` (identity unless the
    model was `rebased`: a URDF whose root is not the arm's base, e.g. a world link above it).
    """

    def __init__(
        self,
        name: str,
        links: Mapping[str, Link],
        joints: Mapping[str, Joint],
        *,
        arm_joints: Sequence[str] | None = None,
        gripper_joints: Sequence[str] | None = None,
        source: str = "<urdf>",
    ):
        self.name = name
        self.source = source
        self.links: dict[str, Link] = dict(links)
        self.joints: dict[str, Joint] = dict(joints)
        children = {j.child for j in self.joints.values()}
        roots = [n for n in self.links if n not in children]
        if len(roots) != 1:
            raise ConfigError(f"{source}: a URDF tree needs exactly one root link, found {roots}")
        self.root = roots[0]
        by_parent: dict[str, list[Joint]] = {}
        for j in self.joints.values():
            by_parent.setdefault(j.parent, []).append(j)
        self.parent_joint: dict[str, Joint] = {j.child: j for j in self.joints.values()}
        self.joint_order: tuple[Joint, ...] = tuple(self._topo(by_parent))
        if len(self.joint_order) != len(self.joints):
            raise ConfigError(f"{source}: the joints do not form a tree rooted at {self.root!r}")
        self._joint_index = {j.name: i for i, j in enumerate(self.joint_order)}
        self.link_names: tuple[str, ...] = (self.root,) + tuple(j.child for j in self.joint_order)
        self.link_index = {n: i for i, n in enumerate(self.link_names)}
        if arm_joints is None:
            arm_joints = [j.name for j in self.joint_order if j.type in ("revolute", "continuous") and j.mimic is None]
        if gripper_joints is None:
            gripper_joints = [j.name for j in self.joint_order if j.type == "prismatic" and j.mimic is None]
        for n in list(arm_joints) + list(gripper_joints):
            if n not in self.joints or not self.joints[n].movable:
                raise ConfigError(f"{source}: {n!r} is not a movable joint of {self.name!r}")
        self.arm_joints: tuple[str, ...] = tuple(arm_joints)
        self.gripper_joints: tuple[str, ...] = tuple(gripper_joints)
        self.root_pose: np.ndarray = np.eye(4)

    def _topo(self, by_parent: dict[str, list[Joint]]) -> list[Joint]:
        out: list[Joint] = []
        frontier = [self.root]
        while frontier:  # breadth-first: every joint after its parent link's joint
            nxt = []
            for link in frontier:
                for j in by_parent.get(link, []):
                    out.append(j)
                    nxt.append(j.child)
            frontier = nxt
        return out

    # ---- construction -------------------------------------------------------------------------
    @classmethod
    def from_urdf(cls, path: str | Path, **kwargs: object) -> RobotModel:
        """Read a URDF file; raises ConfigError for a missing file or malformed content."""
        name, links, joints = _parse(path)
        return cls(name, links, joints, source=str(path), **kwargs)  # type: ignore[arg-type]

    @classmethod
    def from_string(cls, text: str, **kwargs: object) -> RobotModel:
        """Read URDF XML text."""
        name, links, joints = _parse("<string>", text)
        return cls(name, links, joints, **kwargs)  # type: ignore[arg-type]

    def rebased(self, root_pose: np.ndarray) -> RobotModel:
        """A copy whose poses are in another base frame, where the root link sits at `root_pose` (4, 4)."""
        new = self._copy(self.links, self.joints)
        new.root_pose = np.array(root_pose, dtype=float)
        return new

    def with_frame(self, name: str, parent: str, origin: np.ndarray) -> RobotModel:
        """A copy with one more link `name` without shapes, fixed at `origin` (4, 4) in link `parent` (a
        frame the URDF lacks, such as a tool centre point). ConfigError when `name` exists or `parent` does
        not."""
        if name in self.links or parent not in self.links:
            raise ConfigError(f"{self.source}: cannot add frame {name!r} on {parent!r} (exists, or no such parent)")
        joint = Joint(f"{name}_frame_joint", "fixed", parent, name, np.array(origin, dtype=float), np.zeros(3))
        new = self._copy({**self.links, name: Link(name)}, {**self.joints, joint.name: joint})
        new.root_pose = self.root_pose.copy()
        return new

    def _copy(self, links: Mapping[str, Link], joints: Mapping[str, Joint]) -> RobotModel:
        return RobotModel(
            self.name, links, joints, arm_joints=self.arm_joints, gripper_joints=self.gripper_joints, source=self.source
        )

    # ---- structure ----------------------------------------------------------------------------
    def parent_link(self, link: str) -> str | None:
        j = self.parent_joint.get(link)
        return j.parent if j is not None else None

    def joined_pairs(self) -> list[tuple[str, str]]:
        """(parent, child) link pairs joined directly by a joint."""
        return [(j.parent, j.child) for j in self.joint_order]

    def rigid_parent(self, link: str, *, movable: Sequence[str] | None = None) -> str:
        """The nearest ancestor-or-self whose parent joint is in `movable` (default: every movable
        joint), or the root: links with the same rigid parent never move relative to each other."""
        mov = set(movable) if movable is not None else {j.name for j in self.joints.values() if j.movable}
        while True:
            j = self.parent_joint.get(link)
            if j is None or j.name in mov:
                return link
            link = j.parent

    def joint_values(
        self, q_arm: np.ndarray, *, finger_opening: float | None = None, joint_values: Mapping[str, float] | None = None
    ) -> np.ndarray:
        """(n, J) values of every joint in `joint_order` for (n, 6) arm configurations."""
        q = np.asarray(q_arm, dtype=float)
        if q.ndim == 1:
            q = q[None]
        if q.ndim != 2 or q.shape[1] != len(self.arm_joints):
            raise InvalidRequestError(f"q_arm must have shape (n, {len(self.arm_joints)}), got {np.shape(q_arm)}")
        idx = self._joint_index
        vals = np.zeros((q.shape[0], len(self.joint_order)))
        for k, name in enumerate(self.arm_joints):
            vals[:, idx[name]] = q[:, k]
        for name in self.gripper_joints:
            j = self.joints[name]
            half = j.upper if finger_opening is None else 0.5 * float(finger_opening)
            vals[:, idx[name]] = min(max(half, j.lower), j.upper)
        for name, v in (joint_values or {}).items():
            if name not in idx:
                raise InvalidRequestError(f"unknown joint {name!r}")
            vals[:, idx[name]] = float(v)
        for j in self.joint_order:
            if j.mimic is not None and j.mimic[0] in idx:
                vals[:, idx[j.name]] = j.mimic[1] * vals[:, idx[j.mimic[0]]] + j.mimic[2]
        return vals

    # ---- forward kinematics -------------------------------------------------------------------
    def link_pose_array(
        self, q_arm: np.ndarray, *, finger_opening: float | None = None, joint_values: Mapping[str, float] | None = None
    ) -> np.ndarray:
        """(n, L, 4, 4) pose of every link (order `link_names`) in the base frame for (n, 6) q_arm."""
        vals = self.joint_values(q_arm, finger_opening=finger_opening, joint_values=joint_values)
        n = vals.shape[0]
        out = np.empty((n, len(self.link_names), 4, 4))
        out[:, 0] = self.root_pose
        for k, j in enumerate(self.joint_order):
            parent = out[:, self.link_index[j.parent]]
            T = parent @ j.origin
            if j.type in ("revolute", "continuous"):
                T = T @ _rotations(j.axis, vals[:, k])
            elif j.type == "prismatic":
                T = T.copy()
                T[:, :3, 3] += (T[:, :3, :3] @ j.axis) * vals[:, k, None]
            out[:, k + 1] = T
        return out

    def link_poses(
        self, q_arm: np.ndarray, *, finger_opening: float | None = None, joint_values: Mapping[str, float] | None = None
    ) -> dict[str, np.ndarray]:
        """{link: (n, 4, 4)} pose of every link in the base frame for (n, 6) q_arm."""
        arr = self.link_pose_array(q_arm, finger_opening=finger_opening, joint_values=joint_values)
        return {name: arr[:, i] for i, name in enumerate(self.link_names)}

    def shapes(self) -> list[Shape]:
        """Every collision shape, links in `link_names` order."""
        return [s for n in self.link_names for s in self.links[n].shapes]


def _rotations(axis: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """(n, 4, 4) rotations by `theta` (n,) about the unit `axis` (Rodrigues)."""
    K = np.array([[0.0, -axis[2], axis[1]], [axis[2], 0.0, -axis[0]], [-axis[1], axis[0], 0.0]])
    s, c = np.sin(theta)[:, None, None], np.cos(theta)[:, None, None]
    out = np.zeros((theta.shape[0], 4, 4))
    out[:, :3, :3] = np.eye(3) + s * K + (1.0 - c) * (K @ K)
    out[:, 3, 3] = 1.0
    return out


@dataclass(frozen=True, eq=False)
class FixtureShape:
    """A collision primitive of a static body. pose: (4, 4) in the frame the caller asked for."""

    kind: str
    size: tuple[float, ...]
    pose: np.ndarray
    link: str
    index: int


def read_fixture_shapes(path: str | Path, pose: np.ndarray | None = None) -> list[FixtureShape]:
    """Collision primitives of a static URDF body (one link or several joined ones, movable joints at 0),
    placed at `pose` (4, 4; default identity = the body's own frame). Raises ConfigError on meshes."""
    model = RobotModel.from_urdf(path, arm_joints=(), gripper_joints=())
    T0 = np.eye(4) if pose is None else np.asarray(pose, dtype=float)
    links = model.link_pose_array(np.zeros((1, 0)))[0]
    out = []
    for i, name in enumerate(model.link_names):
        for s in model.links[name].shapes:
            if s.kind == "mesh":
                raise ConfigError(f"{path}: link {name!r} uses a mesh; the planning scene needs primitives")
            out.append(FixtureShape(s.kind, s.size, T0 @ links[i] @ s.origin, name, s.index))
    return out


# ---- visual colours ---------------------------------------------------------------------------------
RGBA = tuple[float, float, float, float]


def _rgba(color: ET.Element, where: str) -> RGBA:
    text = color.get("rgba") or ""
    try:
        vals = [float(v) for v in text.split()]
    except ValueError:
        vals = []
    if len(vals) == 3:  # tolerated (the URDF spec asks for 4): opaque
        vals.append(1.0)
    if len(vals) != 4:
        raise ConfigError(f"{where}: <color rgba> needs 4 numbers, got {text!r}")
    return (vals[0], vals[1], vals[2], vals[3])


def _link_colors(root: ET.Element, where: str) -> dict[str, RGBA]:
    # named materials: those defined at robot level, then named ones defined inline in a visual (URDF
    # lets a later visual refer to them by name; a robot-level definition wins, as in urdfdom)
    named: dict[str, RGBA] = {}
    for mat in root.findall("material"):
        color = mat.find("color")
        if mat.get("name") and color is not None:
            named[mat.get("name") or ""] = _rgba(color, f"{where} material {mat.get('name')!r}")
    for mat in root.iterfind("link/visual/material"):
        color = mat.find("color")
        if mat.get("name") and color is not None:
            named.setdefault(mat.get("name") or "", _rgba(color, f"{where} material {mat.get('name')!r}"))
    out: dict[str, RGBA] = {}
    for le in root.findall("link"):
        for vis in le.findall("visual"):
            vmat = vis.find("material")
            if vmat is None:
                continue
            vcolor = vmat.find("color")
            if vcolor is not None:
                rgba: RGBA | None = _rgba(vcolor, f"{where} link {le.get('name')!r}")
            else:
                rgba = named.get(vmat.get("name") or "")
            if rgba is not None:
                out[le.get("name") or ""] = rgba
                break
    return out


def urdf_link_rgba(path: str | Path) -> dict[str, RGBA]:
    """{link: (r, g, b, a)} in 0..1: the colour of each link's first visual whose material has one (an
    inline <color>, or a named material defined at robot level or in an earlier visual), in file order;
    links without a coloured visual are left out (textures are ignored). Raises ConfigError for a missing
    or malformed file or colour."""
    return _link_colors(_read_root(path), str(path))


def urdf_rgba(path: str | Path, *, link: str | None = None) -> RGBA | None:
    """(r, g, b, a) in 0..1 of `link` (default: the first link, in file order, that has a coloured visual),
    e.g. an object model's colour; None when there is none. Raises ConfigError as `urdf_link_rgba`, and
    for a `link` the file does not define."""
    root = _read_root(path)
    colors = _link_colors(root, str(path))
    if link is None:
        return next(iter(colors.values()), None)
    if link not in {le.get("name") for le in root.findall("link")}:
        raise ConfigError(f"{path}: no link named {link!r}")
    return colors.get(link)
