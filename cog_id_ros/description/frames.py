"""Rigid transforms as URDF writes them: roll-pitch-yaw angles and a translation."""
import math

import numpy as np

#: no offset, no rotation: what an <origin> or an offset left out stands for
ZERO = (0.0, 0.0, 0.0)


def rpy_matrix(rpy):
    """URDF roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(rpy[0]), math.sin(rpy[0])
    cp, sp = math.cos(rpy[1]), math.sin(rpy[1])
    cy, sy = math.cos(rpy[2]), math.sin(rpy[2])
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def rpy_of(rotation):
    """Roll, pitch, yaw of a rotation matrix (the inverse of rpy_matrix), also at +-90
    degrees of pitch: roll is taken from what yaw and pitch leave."""
    yaw = math.atan2(rotation[1, 0], rotation[0, 0])
    pitch = math.atan2(-rotation[2, 0], math.hypot(rotation[0, 0], rotation[1, 0]))
    rest = rpy_matrix((0.0, pitch, yaw)).T @ rotation
    roll = math.atan2(rest[2, 1], rest[1, 1])
    return roll, pitch, yaw


class Frame:
    """A rigid transform (rotation, translation); ``identity`` when exactly so, which keeps
    values written in the URDF unchanged through the conversion."""

    def __init__(self, rotation=None, translation=None):
        self.identity = rotation is None
        self.rotation = np.eye(3) if rotation is None else rotation
        self.translation = np.zeros(3) if translation is None else translation

    @classmethod
    def of(cls, xyz, rpy):
        return cls(rpy_matrix(rpy), np.array(xyz, dtype=float))

    def __mul__(self, other):
        if self.identity:
            return other
        if other.identity:
            return self
        return Frame(self.rotation @ other.rotation,
                      self.rotation @ other.translation + self.translation)

    def inverse(self):
        if self.identity:
            return self
        return Frame(self.rotation.T, -self.rotation.T @ self.translation)
