"""twin.transforms: the one implementation of rpy / quaternion / matrix conversions, checked against
PyBullet (the simulator the digital twin runs on) and against each other, plus the old import names."""

from __future__ import annotations

import math

import numpy as np
import pybullet as pb
import pytest

from twin import transforms as tf

RNG_SEED = 11


def _rpys(n: int = 200) -> np.ndarray:
    rng = np.random.default_rng(RNG_SEED)
    # pitch inside (-pi/2, pi/2) so that matrix_to_rpy has a unique answer
    return np.column_stack(
        [rng.uniform(-math.pi, math.pi, n), rng.uniform(-1.5, 1.5, n), rng.uniform(-math.pi, math.pi, n)]
    )


def test_rpy_is_fixed_axis_xyz_as_urdf_and_pybullet_define_it():
    for r, p, y in _rpys(50):
        Rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
        Ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
        Rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
        R = tf.rpy_to_matrix((r, p, y))
        np.testing.assert_allclose(R, Rz @ Ry @ Rx, atol=1e-15)
        B = np.array(pb.getMatrixFromQuaternion(pb.getQuaternionFromEuler((r, p, y)))).reshape(3, 3)
        np.testing.assert_allclose(R, B, atol=1e-7)


def test_quaternions_are_xyzw_as_in_pybullet():
    for rpy in _rpys(50):
        q = tf.matrix_to_quat(tf.rpy_to_matrix(rpy))
        qb = np.array(pb.getQuaternionFromEuler(rpy.tolist()))
        assert abs(abs(float(q @ qb)) - 1.0) < 1e-12  # same rotation (q and -q are equal)
        np.testing.assert_allclose(tf.quat_to_matrix(qb), tf.rpy_to_matrix(rpy), atol=1e-7)
    np.testing.assert_allclose(tf.matrix_to_quat(np.eye(3)), [0, 0, 0, 1])
    np.testing.assert_allclose(
        tf.quat_to_matrix([0, 0, math.sin(0.25), math.cos(0.25)]), tf.rpy_to_matrix((0, 0, 0.5)), atol=1e-15
    )


def test_round_trips():
    for rpy in _rpys():
        R = tf.rpy_to_matrix(rpy)
        np.testing.assert_allclose(tf.matrix_to_rpy(R), rpy, atol=1e-12)
        np.testing.assert_allclose(tf.quat_to_matrix(tf.matrix_to_quat(R)), R, atol=1e-14)
    # every branch of Shepperd's method: rotations by ~pi about each axis
    for axis_rpy in (
        (math.pi - 0.1, 0.0, 0.0),
        (0.0, math.pi / 2 - 0.01, math.pi),
        (0.0, 0.0, math.pi - 0.1),
        (3.0, 0.2, 2.9),
    ):
        R = tf.rpy_to_matrix(axis_rpy)
        np.testing.assert_allclose(tf.quat_to_matrix(tf.matrix_to_quat(R)), R, atol=1e-14)
    # a non-unit quaternion is normalised
    np.testing.assert_allclose(tf.quat_to_matrix([0, 0, 0, 3.0]), np.eye(3))


def test_matrix_to_rpy_accepts_a_pose_and_clips_round_off():
    T = tf.pose_from_xyz_rpy((1, 2, 3), (0.1, 0.2, 0.3))
    np.testing.assert_allclose(tf.matrix_to_rpy(T), (0.1, 0.2, 0.3), atol=1e-12)
    R = tf.rpy_to_matrix((0.0, math.pi / 2, 0.0))
    R[2, 0] = -1.0 - 1e-15  # round-off outside asin's domain
    assert tf.matrix_to_rpy(R)[1] == pytest.approx(math.pi / 2)


def test_pose_from_xyz_rpy():
    T = tf.pose_from_xyz_rpy((0.1, -0.2, 0.3), (0.3, -0.5, 1.1))
    np.testing.assert_array_equal(T[:3, :3], tf.rpy_to_matrix((0.3, -0.5, 1.1)))
    np.testing.assert_array_equal(T[:3, 3], [0.1, -0.2, 0.3])
    np.testing.assert_array_equal(T[3], [0, 0, 0, 1])
    np.testing.assert_array_equal(tf.pose_from_xyz_rpy(), np.eye(4))


def test_batched_quaternions_equal_single_ones():
    q = np.random.default_rng(RNG_SEED).normal(size=(100, 4))
    # Two computations of the norm: 1-D np.linalg.norm is BLAS ddot, the batched one numpy's reduction along
    # axis 1; how each rounds depends on the OpenBLAS kernel and numpy's SIMD path of the machine (AVX-512
    # ddot: 84 of these 900 entries 1-4 ulp apart). The norms differ by up to ~3 ulp and the entry formulas
    # (in [-1, 1]) amplify that by at most 4: 16 ulp of 1 (measured worst over 40,000 quaternions: 6 ulp).
    # A wrong entry formula is off by ~0.1.
    np.testing.assert_allclose(
        tf.quats_to_matrices(q), np.array([tf.quat_to_matrix(v) for v in q]), rtol=0, atol=16 * np.finfo(float).eps
    )


def test_old_names_are_the_same_functions():
    from twin import types
    from twin.robot import urdf_model

    assert types.rpy_matrix is tf.rpy_to_matrix
    assert types.matrix_to_quat is tf.matrix_to_quat and types.quat_to_matrix is tf.quat_to_matrix
    assert urdf_model.rpy_to_matrix is tf.rpy_to_matrix and urdf_model.pose_from_xyz_rpy is tf.pose_from_xyz_rpy
    p = types.Pose.from_xyz_rpy((0.1, 0.2, 0.3), (0.4, 0.5, 0.6))
    np.testing.assert_allclose(p.matrix(), tf.pose_from_xyz_rpy((0.1, 0.2, 0.3), (0.4, 0.5, 0.6)), atol=1e-15)
