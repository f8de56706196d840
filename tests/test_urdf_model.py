"""URDF visual colours (twin.robot.urdf_model.urdf_rgba / urdf_link_rgba): the shipped models against PyBullet,
which renders them, and the material rules (robot-level named materials, inline colours) on small files."""

from __future__ import annotations

from pathlib import Path

import pybullet as pb
import pytest

from twin.errors import ConfigError
from twin.robot.urdf_model import urdf_link_rgba, urdf_rgba

ROOT = Path(__file__).resolve().parent.parent  # the checkout: urdf/ holds the shipped models
SHIPPED = sorted((ROOT / "urdf").glob("*.urdf")) + sorted((ROOT / "urdf" / "objects").glob("*.urdf"))
OBJECTS = sorted((ROOT / "urdf" / "objects").glob("*.urdf"))


@pytest.fixture(scope="module")
def bullet():
    cid = pb.connect(pb.DIRECT)
    yield cid
    pb.disconnect(cid)


def _bullet_link_colors(cid: int, path: Path) -> dict[str, tuple[float, ...]]:
    body = pb.loadURDF(str(path), useFixedBase=True, physicsClientId=cid)
    names = {-1: pb.getBodyInfo(body, physicsClientId=cid)[0].decode()}
    for j in range(pb.getNumJoints(body, physicsClientId=cid)):
        names[j] = pb.getJointInfo(body, j, physicsClientId=cid)[12].decode()
    out: dict[str, tuple[float, ...]] = {}
    for v in pb.getVisualShapeData(body, physicsClientId=cid):
        out.setdefault(names[v[1]], tuple(v[7]))
    pb.removeBody(body, physicsClientId=cid)
    return out


def test_there_are_object_models_to_check():
    assert len(OBJECTS) >= 6


@pytest.mark.parametrize("path", SHIPPED, ids=lambda p: p.name)
def test_link_colours_equal_what_pybullet_renders(bullet, path):
    ours = urdf_link_rgba(path)
    ref = _bullet_link_colors(bullet, path)
    assert ours.keys() == ref.keys()
    for link, rgba in ours.items():
        assert rgba == pytest.approx(ref[link], abs=1e-6)  # PyBullet keeps float32


@pytest.mark.parametrize("path", OBJECTS, ids=lambda p: p.name)
def test_an_object_model_has_one_opaque_colour(path):
    rgba = urdf_rgba(path)
    assert rgba is not None and len(rgba) == 4 and rgba[3] == 1.0
    assert all(0.0 <= c <= 1.0 for c in rgba)


def test_known_object_colours():
    assert urdf_rgba(ROOT / "urdf/objects/can.urdf") == (0.80, 0.12, 0.12, 1.0)
    assert urdf_rgba(ROOT / "urdf/objects/bottle.urdf") == (0.55, 0.78, 0.92, 1.0)
    assert urdf_rgba(ROOT / "urdf/ur5e.urdf", link="shoulder_link") == (0.25, 0.45, 0.70, 1.0)


def _write(tmp_path: Path, body: str) -> Path:
    p = tmp_path / "m.urdf"
    p.write_text(f'<?xml version="1.0"?>\n<robot name="m">{body}</robot>\n')
    return p


def test_material_rules(tmp_path):
    p = _write(
        tmp_path,
        """
        <material name="red"><color rgba="1 0 0 1"/></material>
        <link name="bare"/>
        <link name="textured"><visual><geometry><box size="1 1 1"/></geometry>
          <material name="tex"><texture filename="t.png"/></material></visual></link>
        <link name="named"><visual><geometry><box size="1 1 1"/></geometry><material name="red"/></visual></link>
        <link name="inline"><visual><geometry><box size="1 1 1"/></geometry>
          <material name="green"><color rgba="0 1 0 0.5"/></material></visual></link>
        <link name="reuse"><visual><geometry><box size="1 1 1"/></geometry><material name="green"/></visual>
          <visual><geometry><box size="1 1 1"/></geometry><material name="red"/></visual></link>
        <link name="rgb"><visual><geometry><box size="1 1 1"/></geometry>
          <material name=""><color rgba="0 0 1"/></material></visual></link>
        """,
    )
    colors = urdf_link_rgba(p)
    assert colors == {
        "named": (1.0, 0.0, 0.0, 1.0),
        "inline": (0.0, 1.0, 0.0, 0.5),
        "reuse": (0.0, 1.0, 0.0, 0.5),  # a link's first coloured visual, by a name defined inline earlier
        "rgb": (0.0, 0.0, 1.0, 1.0),  # three numbers: opaque
    }
    assert urdf_rgba(p) == (1.0, 0.0, 0.0, 1.0)  # the first coloured link in file order
    assert urdf_rgba(p, link="textured") is None and urdf_rgba(p, link="bare") is None
    assert urdf_rgba(p, link="inline") == (0.0, 1.0, 0.0, 0.5)
    with pytest.raises(ConfigError, match="no link named 'nope'"):
        urdf_rgba(p, link="nope")


def test_no_colour_and_bad_input(tmp_path):
    assert (
        urdf_rgba(_write(tmp_path, '<link name="a"><visual><geometry><box size="1 1 1"/></geometry></visual></link>'))
        is None
    )
    with pytest.raises(ConfigError, match="rgba"):
        urdf_rgba(_write(tmp_path, '<material name="x"><color rgba="1 zero 0 1"/></material><link name="a"/>'))
    with pytest.raises(ConfigError, match="not found"):
        urdf_rgba(tmp_path / "missing.urdf")
    with pytest.raises(ConfigError, match="not valid XML"):
        urdf_rgba(_write(tmp_path, "<link"))


def test_primitive_half_extents_are_those_of_each_kind_and_a_mesh_has_none():
    from twin.robot.urdf_model import primitive_half_extents

    assert primitive_half_extents("box", (0.2, 0.4, 0.6)).tolist() == [0.1, 0.2, 0.3]
    assert primitive_half_extents("cylinder", (0.05, 0.3)).tolist() == [0.05, 0.05, 0.15]
    assert primitive_half_extents("capsule", (0.05, 0.3)).tolist() == [0.05, 0.05, 0.2]
    assert primitive_half_extents("sphere", (0.07,)).tolist() == [0.07, 0.07, 0.07]
    with pytest.raises(ValueError, match="mesh"):
        primitive_half_extents("mesh", (1.0, 1.0, 1.0))
