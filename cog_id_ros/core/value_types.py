"""The names the core's signatures give its values (annotations only: nothing here runs).

A *lane* (spatial.py) is a Python float for one sample, a float array of shape (N,) for N
samples, or a ``straight_line.Sym`` while the lane code is traced: the lane code is written
once for all three, so a lane is typed ``Any`` under a name that says what it is.
"""
from typing import Any, Sequence

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.intp]
BoolArray = NDArray[np.bool_]

Lane = Any
Vec3 = tuple[Lane, ...]              # 3 lanes
Rotation = tuple[Lane, ...]          # 9 lanes, row-major
Twist = tuple[Vec3, Vec3]            # (w, v0): Pluecker, base frame
Transform = tuple[Rotation, Vec3]    # (R, t)
# spatial.ScalarOps, spatial.ArrayOps or straight_line.SymOps: the lane functions of a kind
Ops = Any
# a core.model.mechanism.Mechanism, named so in the modules mechanism.py itself imports (a typing
# import back would be an import cycle)
MechanismLike = Any
# a small matrix of lanes as the lane code holds it: a list of rows
LaneMatrix = list[list[Lane]]
Lanes = Sequence[Lane]
Twists = Sequence[Twist]
