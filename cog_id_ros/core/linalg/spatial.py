"""Spatial algebra on lanes: the one small place where vectors, rotations and twists live.

Every scalar here is a *lane*: either a Python float (one sample, the lean per-sample path
a control loop calls) or a numpy array of shape (N,) (N samples, the vectorised batch path).
Elementwise arithmetic is the same for both, so every kinematic and dynamic quantity is
written once and serves both paths. Vectors are 3-tuples of lanes, rotation matrices
9-tuples of lanes in row-major order.

Twists are Pluecker vectors in the base frame: ``(w, v0)`` with ``w`` the angular velocity
and ``v0`` the velocity of the body point that passes through the base origin, so that the
velocity of a body point at ``x`` is ``v0 + w x x`` and twists of a chain simply add.
Spatial accelerations ``(alpha, a0)`` are their time derivatives (Featherstone's convention).
"""
import math
from typing import Callable, Iterable, Sequence

import numpy as np

from ..value_types import FloatArray, Lane, Ops, Rotation, Transform, Twist, Vec3

IDENTITY = (1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0)
ZERO3 = (0.0, 0.0, 0.0)


class ScalarOps:
    """Lane functions for Python floats (one sample)."""

    sin = staticmethod(math.sin)
    cos = staticmethod(math.cos)
    atan2 = staticmethod(math.atan2)

    @staticmethod
    def acos(x: float) -> float:
        """arccos of x clipped to [-1, 1] (rounding may leave a cosine just outside)."""
        return math.acos(min(1.0, max(-1.0, x)))

    @staticmethod
    def select(condition: bool, a: Lane, b: Lane) -> Lane:
        return a if condition else b

    @staticmethod
    def sqrt(x: float) -> float:
        return math.sqrt(x) if x >= 0.0 else math.nan

    @staticmethod
    def recip(x: float) -> float:
        return 1.0 / x if x != 0.0 else math.inf

    @staticmethod
    def maxabs(lanes: Iterable[float]) -> float:
        """The largest |lane| (0.0 for none); NaN if any lane is NaN (as numpy's max)."""
        return _fold(larger, map(abs, lanes), 0.0)

    @staticmethod
    def least(lanes: Iterable[float]) -> float:
        """The smallest lane, 1.0 for none (cosines are at most 1); NaN if any is NaN."""
        return _fold(smaller, lanes, 1.0)


def larger(a: Lane, b: Lane) -> Lane:
    """max(a, b) that keeps a NaN of either operand (the C emitter writes the same)."""
    return a if a > b or a != a else b


def smaller(a: Lane, b: Lane) -> Lane:
    """min(a, b) that keeps a NaN of either operand."""
    return a if a < b or a != a else b


def _fold(pick: Callable[[Lane, Lane], Lane], lanes: Iterable[Lane], start: float) -> Lane:
    out = start
    for x in lanes:
        out = pick(out, x)
    return out


class ArrayOps:
    """Lane functions for numpy arrays of shape (N,) (N samples)."""

    sin = staticmethod(np.sin)
    cos = staticmethod(np.cos)
    atan2 = staticmethod(np.arctan2)
    select = staticmethod(np.where)

    @staticmethod
    def acos(x: FloatArray) -> FloatArray:
        return np.arccos(np.clip(x, -1.0, 1.0))

    @staticmethod
    def sqrt(x: FloatArray) -> FloatArray:
        with np.errstate(invalid='ignore'):
            return np.sqrt(x)

    @staticmethod
    def recip(x: FloatArray) -> FloatArray:
        with np.errstate(divide='ignore', invalid='ignore'):
            return 1.0 / x

    @staticmethod
    def maxabs(lanes: Sequence[Lane]) -> Lane:
        if not lanes:
            return 0.0
        return np.max(np.abs(np.broadcast_arrays(*lanes)), axis=0)

    @staticmethod
    def least(lanes: Sequence[Lane]) -> Lane:
        if not lanes:
            return 1.0
        return np.minimum(np.min(np.broadcast_arrays(*lanes), axis=0), 1.0)


# --- 3-vectors -------------------------------------------------------------------------

def add(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] + b[0], a[1] + b[1], a[2] + b[2])


def sub(a: Vec3, b: Vec3) -> Vec3:
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def scale(a: Vec3, s: Lane) -> Vec3:
    return (a[0] * s, a[1] * s, a[2] * s)


def add_scaled(a: Vec3, b: Vec3, s: Lane) -> Vec3:
    """a + s b."""
    return (a[0] + b[0] * s, a[1] + b[1] * s, a[2] + b[2] * s)


def dot(a: Vec3, b: Vec3) -> Lane:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def cross(a: Vec3, b: Vec3) -> Vec3:
    return (a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0])


# --- rotation matrices (9-tuples, row-major) ---------------------------------------------

def mat_vec(r: Rotation, v: Vec3) -> Vec3:
    return (r[0] * v[0] + r[1] * v[1] + r[2] * v[2],
            r[3] * v[0] + r[4] * v[1] + r[5] * v[2],
            r[6] * v[0] + r[7] * v[1] + r[8] * v[2])


def mat_t_vec(r: Rotation, v: Vec3) -> Vec3:
    """r^T v."""
    return (r[0] * v[0] + r[3] * v[1] + r[6] * v[2],
            r[1] * v[0] + r[4] * v[1] + r[7] * v[2],
            r[2] * v[0] + r[5] * v[1] + r[8] * v[2])


def mat_mat(a: Rotation, b: Rotation) -> Rotation:
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = a
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = b
    return (a0 * b0 + a1 * b3 + a2 * b6, a0 * b1 + a1 * b4 + a2 * b7, a0 * b2 + a1 * b5 + a2 * b8,
            a3 * b0 + a4 * b3 + a5 * b6, a3 * b1 + a4 * b4 + a5 * b7, a3 * b2 + a4 * b5 + a5 * b8,
            a6 * b0 + a7 * b3 + a8 * b6, a6 * b1 + a7 * b4 + a8 * b7, a6 * b2 + a7 * b5 + a8 * b8)


def transpose(r: Rotation) -> Rotation:
    return (r[0], r[3], r[6], r[1], r[4], r[7], r[2], r[5], r[8])


def mat_combination(m0: Rotation, m1: Rotation, s1: Lane, m2: Rotation, s2: Lane) -> Rotation:
    """m0 + s1 m1 + s2 m2, entrywise (constant matrices, lane weights)."""
    return (m0[0] + m1[0] * s1 + m2[0] * s2, m0[1] + m1[1] * s1 + m2[1] * s2,
            m0[2] + m1[2] * s1 + m2[2] * s2, m0[3] + m1[3] * s1 + m2[3] * s2,
            m0[4] + m1[4] * s1 + m2[4] * s2, m0[5] + m1[5] * s1 + m2[5] * s2,
            m0[6] + m1[6] * s1 + m2[6] * s2, m0[7] + m1[7] * s1 + m2[7] * s2,
            m0[8] + m1[8] * s1 + m2[8] * s2)


def vec_combination(v0: Vec3, v1: Vec3, s1: Lane, v2: Vec3, s2: Lane) -> Vec3:
    """v0 + s1 v1 + s2 v2."""
    return (v0[0] + v1[0] * s1 + v2[0] * s2,
            v0[1] + v1[1] * s1 + v2[1] * s2,
            v0[2] + v1[2] * s1 + v2[2] * s2)


def orientation_error(ra: Rotation, rb: Rotation) -> Vec3:
    """Rotation of frame b relative to frame a, as a base-frame vector: 1/2 sum_k a_k x b_k
    (a_k, b_k the columns of the two rotation matrices).

    Zero when the frames coincide; its time derivative there is w_b - w_a, so it pairs with
    the angular rows of the closure Jacobian in Newton's method (it also vanishes for a
    half-turn, which the closure solver rules out by checking ``rotation_cosine``).
    """
    a0, a1, a2, a3, a4, a5, a6, a7, a8 = ra
    b0, b1, b2, b3, b4, b5, b6, b7, b8 = rb
    return ((a3 * b6 - a6 * b3 + a4 * b7 - a7 * b4 + a5 * b8 - a8 * b5) * 0.5,
            (a6 * b0 - a0 * b6 + a7 * b1 - a1 * b7 + a8 * b2 - a2 * b8) * 0.5,
            (a0 * b3 - a3 * b0 + a1 * b4 - a4 * b1 + a2 * b5 - a5 * b2) * 0.5)


def rotation_cosine(ra: Rotation, rb: Rotation) -> Lane:
    """cos of the angle between two frames: (trace(ra^T rb) - 1) / 2."""
    return (sum(ra[i] * rb[i] for i in range(9)) - 1.0) * 0.5


def quaternion_rotation(quaternion: Sequence[Lane],
                        ops: Ops) -> tuple[Rotation, tuple[Vec3, Vec3, Vec3, Vec3]]:
    """R(q) = R_h(q) / |q|^2 for a quaternion q = (w, x, y, z) of any nonzero length (a
    rotation whatever the length), and the columns of 2 G(q) / |q|^2: the angular velocity
    (in the frame R maps from) per unit rate of each component, G(q) = [-v, w I + [v]x].
    G(a) a = 0 for every a: the quaternion's own direction does not rotate."""
    w, x, y, z = quaternion
    ww, xx, yy, zz = w * w, x * x, y * y, z * z
    s = ops.recip(ww + xx + yy + zz)
    xy, xz, yz, wx, wy, wz = x * y, x * z, y * z, w * x, w * y, w * z
    t = 2.0 * s
    rotation = ((ww + xx - yy - zz) * s, (xy - wz) * t, (xz + wy) * t,
                (xy + wz) * t, (ww - xx + yy - zz) * s, (yz - wx) * t,
                (xz - wy) * t, (yz + wx) * t, (ww - xx - yy + zz) * s)
    rates = ((-x * t, -y * t, -z * t), (w * t, z * t, -y * t),
             (-z * t, w * t, x * t), (y * t, -x * t, w * t))
    return rotation, rates


# --- constant frames (plain floats, built once at load time) -----------------------------

def compose(a: Transform, b: Transform) -> Transform:
    """The transform a b of two (rotation, translation) pairs."""
    (ra, ta), (rb, tb) = a, b
    return mat_mat(ra, rb), add(ta, mat_vec(ra, tb))


def rotation_quaternion(r: Rotation) -> tuple[float, ...]:
    """The unit quaternion (w, x, y, z), w >= 0, of a rotation matrix (Shepperd: from its
    largest diagonal combination, so no division by a small number)."""
    r0, r1, r2, r3, r4, r5, r6, r7, r8 = r
    trace = r0 + r4 + r8
    k = max(range(4), key=lambda i: (trace, r0, r4, r8)[i])
    if k == 0:
        s = 2.0 * math.sqrt(1.0 + trace)
        q = (0.25 * s, (r7 - r5) / s, (r2 - r6) / s, (r3 - r1) / s)
    elif k == 1:
        s = 2.0 * math.sqrt(1.0 + r0 - r4 - r8)
        q = ((r7 - r5) / s, 0.25 * s, (r1 + r3) / s, (r2 + r6) / s)
    elif k == 2:
        s = 2.0 * math.sqrt(1.0 - r0 + r4 - r8)
        q = ((r2 - r6) / s, (r1 + r3) / s, 0.25 * s, (r5 + r7) / s)
    else:
        s = 2.0 * math.sqrt(1.0 - r0 - r4 + r8)
        q = ((r3 - r1) / s, (r2 + r6) / s, (r5 + r7) / s, 0.25 * s)
    return q if q[0] >= 0.0 else tuple(-x for x in q)


def inverse_transform(r: Rotation, t: Vec3) -> Transform:
    """(R^T, -R^T t): the inverse of the transform (R, t)."""
    rt = transpose(r)
    return rt, scale(mat_vec(rt, t), -1.0)


def rpy_matrix(rpy: Sequence[float]) -> Rotation:
    """URDF roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = (math.cos(r), math.sin(r), math.cos(p), math.sin(p),
                              math.cos(y), math.sin(y))
    return (cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr,
            sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr,
            -sp, cp * sr, cp * cr)


def matrix_rpy(r: Rotation) -> tuple[float, float, float]:
    """(roll, pitch, yaw) of a rotation matrix, the inverse of :func:`rpy_matrix` (at
    pitch +-pi/2, where only roll - yaw or roll + yaw is defined, roll 0)."""
    pitch = math.atan2(-r[6], math.hypot(r[0], r[3]))
    if math.hypot(r[7], r[8]) < 1e-12:
        return (0.0, pitch, math.atan2(-r[1], r[4]))
    return (math.atan2(r[7], r[8]), pitch, math.atan2(r[3], r[0]))


def skew(u: Vec3) -> Rotation:
    """The matrix K with K v = u x v."""
    return (0.0, -u[2], u[1], u[2], 0.0, -u[0], -u[1], u[0], 0.0)


def rotation_about(axis_unit: Vec3, angle: Lane, ops: Ops = ScalarOps) -> Rotation:
    """Rodrigues: I + sin(q) K + (1 - cos(q)) K^2."""
    k = skew(axis_unit)
    return mat_combination(IDENTITY, k, ops.sin(angle), mat_mat(k, k), 1.0 - ops.cos(angle))


# --- twists (Pluecker, base frame) -------------------------------------------------------

def twist_add_scaled(t: Twist, u: Twist, s: Lane) -> Twist:
    """t + s u for twists."""
    (w0, w1, w2), (v0, v1, v2) = t
    (x0, x1, x2), (y0, y1, y2) = u
    return ((w0 + x0 * s, w1 + x1 * s, w2 + x2 * s), (v0 + y0 * s, v1 + y1 * s, v2 + y2 * s))


def twist_at(t: Twist, x: Vec3) -> tuple[Vec3, Vec3]:
    """Twist t as (velocity of the body point at x, angular velocity)."""
    w, v = t
    return ((v[0] + w[1] * x[2] - w[2] * x[1],
             v[1] + w[2] * x[0] - w[0] * x[2],
             v[2] + w[0] * x[1] - w[1] * x[0]), w)


def motion_cross(t: Twist, u: Twist) -> Twist:
    """Spatial cross product t x u of two twists: the rate of change of a twist u
    fixed in a body that moves with twist t: (w x wu, w x vu + v x wu)."""
    (w0, w1, w2), (v0, v1, v2) = t
    (a0, a1, a2), (b0, b1, b2) = u
    return ((w1 * a2 - w2 * a1, w2 * a0 - w0 * a2, w0 * a1 - w1 * a0),
            (w1 * b2 - w2 * b1 + v1 * a2 - v2 * a1,
             w2 * b0 - w0 * b2 + v2 * a0 - v0 * a2,
             w0 * b1 - w1 * b0 + v0 * a1 - v1 * a0))


ZERO_TWIST = (ZERO3, ZERO3)
