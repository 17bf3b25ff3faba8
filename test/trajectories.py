"""One smooth test motion per example parameter file in config/.

``TRAJECTORIES[config_file_name](t) -> (q, qd, qdd)``, each of shape (N, M) in the order of
that file's ``mechanism.active_joints``, for a 1-D array of times ``t`` (s); the motions are
meant for t in [0, T_END] and start at the file's ``initial_positions``.

* Non-redundant mechanisms, and the paper's parallelogram (b) (where joint1 = joint3 holds
  exactly): analytic positions and derivatives.
* Redundantly actuated mechanisms otherwise (five_bar_redundant.yaml): DOF-many joints are
  driven analytically (``DRIVERS``) and the remaining active joints are taken from the
  Pinocchio oracle (position solve, qd = V z, qdd with the closure drift), so the active
  setpoints are consistent with the closure. Samples are computed in increasing time,
  each warm-started from the previous one.

``sample(name, n)`` returns ``(t, q, qd, qdd)`` on ``np.linspace(0, T_END, n)``, cached.
"""
from __future__ import annotations

import functools
import os
import sys

import numpy as np

_HERE = os.path.dirname(os.path.abspath(__file__))
if _HERE not in sys.path:
    sys.path.insert(0, _HERE)

import yaml  # noqa: E402

CONFIG_DIR = os.path.join(os.path.dirname(_HERE), 'config')
T_END = 2.0
PI = np.pi


def _law(c0, c1=0.0, terms=()):
    """theta(t) = c0 + c1 t + sum(a sin(w t) + b (1 - cos(w t))), with exact derivatives."""
    def f(t):
        q = c0 + c1 * t
        qd = c1 + 0.0 * t
        qdd = 0.0 * t
        for a, b, w in terms:
            s, c = np.sin(w * t), np.cos(w * t)
            q = q + a * s + b * (1.0 - c)
            qd = qd + a * w * c + b * w * s
            qdd = qdd - a * w * w * s + b * w * w * c
        return q, qd, qdd
    return f


# Driving laws, one per driven joint (name -> law). t in [0, 2] s.
_PAPER = _law(PI / 2, 0.0, [(0.5, 0.0, PI)])                  # pi/2 + 0.5 sin(pi t)
_FIVE_J1 = _law(2.0, 0.0, [(0.3, 0.0, PI)])                  # 2.0 + 0.3 sin(pi t)
# 1.14 + 0.2 sin(2 pi t) - 0.15 (1 - cos(pi t))
_FIVE_J5 = _law(1.14, 0.0, [(0.2, 0.0, 2 * PI), (0.0, -0.15, PI)])

DRIVERS = {
    'paper_four_bar_a.yaml': {'joint3': _PAPER},
    'paper_four_bar_b.yaml': {'joint1': _PAPER, 'joint3': _PAPER},   # parallelogram: exact
    'slider_crank.yaml': {'crank_joint': _law(0.3, 5.0, [(0.4, 0.0, PI)])},
    'five_bar.yaml': {'j1': _FIVE_J1, 'j5': _FIVE_J5},
    'five_bar_redundant.yaml': {'j1': _FIVE_J1, 'j5': _FIVE_J5},     # j3 from the closure
    'spatial_rsur.yaml': {'crank_joint': _law(0.5, 3.5, [(0.3, 0.0, PI)])},
    'watt_six_bar.yaml': {'crank_joint': _law(0.0, PI)},          # one turn in 2 s
    'crank_rocker_urdf.yaml': {'crank_joint': _law(PI / 2, 2 * PI)},   # two turns in 2 s
    'five_bar_robot.yaml': {'motor/1': _law(0.0, 0.0, [(0.3, 0.0, PI)]),
                            'motor/2': _law(0.0, 0.0, [(0.2, 0.0, 2 * PI), (0.0, -0.15, PI)])},
    # a step of the leg: hip pitch swings, the knee bends and straightens, the shin motor
    # tilts the ankle through its rod, a little hip roll, yaw and ankle roll
    'talos_like_leg.yaml': {'motor_hip_z': _law(0.0, 0.0, [(0.05, 0.0, PI)]),
                            'motor_hip_x': _law(0.0, 0.0, [(0.08, 0.0, PI)]),
                            'motor_hip_y': _law(0.0, 0.0, [(0.3, 0.0, PI)]),
                            'motor_knee': _law(0.0, 0.0, [(0.0, 0.4, PI)]),
                            'motor_ankle': _law(0.0, 0.0, [(0.06, 0.0, PI)]),
                            'motor_shin': _law(0.023090923393947464, 0.0, [(0.25, 0.0, PI)])},
    # both legs of the biped step a little: hips swing, knees bend, the ankle motors tilt
    # the feet through their rods (about the pose its config pins)
    'digit_biped.yaml': {
        **{f'motor_hip_{axis}{side}': _law(0.0, 0.0, [(amplitude, 0.0, PI)])
           for side in ('', '_left') for axis, amplitude in (('x', 0.04), ('z', 0.03),
                                                             ('y', 0.1))},
        'motor_knee': _law(0.0076565807143723335, 0.0, [(0.0, 0.15, PI)]),
        'motor_knee_left': _law(-0.02297896219886896, 0.0, [(0.0, 0.15, PI)]),
        'motor_shin1': _law(0.8277222835522381, 0.0, [(0.05, 0.0, PI)]),
        'motor_shin2': _law(-0.8264383887084211, 0.0, [(-0.05, 0.0, PI)]),
        'motor_shin1_left': _law(0.8288705190389682, 0.0, [(0.04, 0.0, PI)]),
        'motor_shin2_left': _law(-0.8275863083840398, 0.0, [(-0.03, 0.0, PI)])},
    # the knee bends and straightens through its four-bar
    'four_bar_knee.yaml': {'motor_knee': _law(0.0, 0.0, [(0.5, 0.0, PI)])},
    # both motors together (pitch) with some of them against each other (roll)
    'parallel_ankle.yaml': {'motor_left': _law(0.0, 0.0, [(0.3, 0.0, PI), (0.1, 0.0, 2 * PI)]),
                            'motor_right': _law(0.0, 0.0, [(0.3, 0.0, PI), (-0.1, 0.0, 2 * PI)])},
}


def config_path(name):
    return os.path.join(CONFIG_DIR, name)


@functools.lru_cache(maxsize=None)
def active_joints(name):
    """mechanism.active_joints of a config file."""
    with open(config_path(name), encoding='utf-8') as f:
        mechanism = yaml.safe_load(f)['/**']['ros__parameters']['mechanism']
    if 'active_joints' in mechanism:
        return mechanism['active_joints']
    from cog_id_ros import Mechanism  # the loop-closure file's name_mot
    return Mechanism.from_params_file(config_path(name)).active_joints


@functools.lru_cache(maxsize=None)
def oracle(name, driven=False):
    """The oracle of a config (with the file's actuators, or with the driven joints as
    actuators). Needs Pinocchio: a test that gets here without it is skipped."""
    import pytest
    pytest.importorskip('pinocchio', reason='the redundant motions come from the Pinocchio oracle')
    from pinocchio_reference import Oracle
    if driven:
        return Oracle(config_path(name), active=list(DRIVERS[name]))
    return Oracle(config_path(name))


def _make(name):
    drivers = DRIVERS[name]

    def traj(t):
        t = np.atleast_1d(np.asarray(t, dtype=float))
        active = active_joints(name)
        if all(j in drivers for j in active):
            cols = [drivers[j](t) for j in active]
            return tuple(np.stack([c[k] for c in cols], axis=1) for k in range(3))
        # redundant: drive DOF-many joints, read the others off the closure
        orc = oracle(name, driven=True)
        cols = [drivers[j](t) for j in orc.active]
        qd_, qdd_ = (np.stack([c[k] for c in cols], axis=1) for k in (1, 2))
        qa = np.stack([c[0] for c in cols], axis=1)
        order = np.argsort(t, kind='stable')
        out = [np.empty((t.size, len(active))) for _ in range(3)]
        idx = [orc.joints.index(j) for j in active]
        guess = orc.initial_positions
        for k in order:
            q = orc.solve_positions(qa[k], guess)
            res = np.abs(orc.closure(q)).max()
            if res > 1e-12:
                raise RuntimeError(f'{name}: driving motion leaves the workspace at t={t[k]} (res {res})')
            qd = orc.joint_velocities(q, qd_[k])
            qdd = orc.joint_accelerations(q, qd, qdd_[k])
            out[0][k], out[1][k], out[2][k] = q[idx], qd[idx], qdd[idx]
            guess = q
        return tuple(out)

    traj.__name__ = 'trajectory_' + name.replace('.yaml', '')
    return traj


TRAJECTORIES = {name: _make(name) for name in DRIVERS}


@functools.lru_cache(maxsize=None)
def _sample(name, n):
    t = np.linspace(0.0, T_END, n)
    q, qd, qdd = TRAJECTORIES[name](t)
    for a in (t, q, qd, qdd):
        a.setflags(write=False)
    return t, q, qd, qdd


def sample(name, n=200):
    """(t, q, qd, qdd) of config ``name`` on n evenly spaced times in [0, T_END] (read-only)."""
    return _sample(name, int(n))


@functools.lru_cache(maxsize=None)
def oracle_along(name, n):
    """(t, q, qd, qdd) of ``sample(name, n)`` and the oracle's q_all, qd_all, qdd_all and
    torques along it (Oracle.follow), computed once per session."""
    t, q, qd, qdd = sample(name, n)
    return (t, q, qd, qdd) + tuple(oracle(name).follow(q, qd, qdd))


# --------------------------------------------------------------------------- parallel robots
# The Stewart-Gough platform and the delta robot are driven through their platform: a smooth
# platform motion, and the actuator coordinates from inverse kinematics with exact first and
# second derivatives (so qd, qdd are those of q to rounding). The geometry is read from the
# config file (joint names as written by bench/mechanism_family.py); the home pose (t = 0) is
# the one the file's initial_positions were computed for.

STEWART = 'stewart_6ups.yaml'
DELTA = 'delta_3rus.yaml'
STEWART_HOME_HEIGHT = 0.85      # m: platform frame origin above the base centre at t = 0
DELTA_HOME_HEIGHT = 0.70        # m: platform frame origin below the base centre at t = 0

# platform translation (m) and roll-pitch-yaw (rad), t in [0, 2] s
STEWART_LAWS = (_law(0.0, 0.0, [(0.04, 0.0, PI)]),
                _law(0.0, 0.0, [(0.0, 0.03, PI)]),
                _law(STEWART_HOME_HEIGHT, 0.0, [(0.05, 0.0, 2 * PI)]),
                _law(0.0, 0.0, [(0.08, 0.0, PI)]),
                _law(0.0, 0.0, [(0.0, 0.06, PI)]),
                _law(0.0, 0.0, [(0.10, 0.0, 2 * PI)]))
DELTA_LAWS = (_law(0.0, 0.0, [(0.08, 0.0, 2 * PI)]),
              _law(0.0, 0.0, [(0.0, 0.06, PI)]),
              _law(-DELTA_HOME_HEIGHT, 0.0, [(0.05, 0.0, 2 * PI)]))


@functools.lru_cache(maxsize=None)
def _joint_params(name):
    with open(config_path(name), encoding='utf-8') as f:
        return yaml.safe_load(f)['/**']['ros__parameters']['joints']


def _axis_rotation(k, a, ad, add):
    """R = exp([e_k] a), Rd, Rdd for arrays of angles, rates, accelerations: (N, 3, 3)."""
    kx = np.zeros((3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][k]
    kx[i, j], kx[j, i] = -1.0, 1.0
    c, s = np.cos(a)[:, None, None], np.sin(a)[:, None, None]
    r = np.eye(3) + s * kx + (1.0 - c) * (kx @ kx)
    rd = r @ kx * ad[:, None, None]
    rdd = r @ (kx * add[:, None, None] + kx @ kx * (ad * ad)[:, None, None])
    return r, rd, rdd


def stewart_platform_motion(t):
    """Platform position p (N, 3) and rotation R = Rz(yaw) Ry(pitch) Rx(roll) (N, 3, 3), with
    their first and second time derivatives: (p, pd, pdd, R, Rd, Rdd)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    laws = [f(t) for f in STEWART_LAWS]
    p, pd, pdd = (np.stack([laws[i][k] for i in range(3)], axis=1) for k in range(3))
    a = _axis_rotation(2, *laws[5])     # yaw
    b = _axis_rotation(1, *laws[4])     # pitch
    c = _axis_rotation(0, *laws[3])     # roll
    r = a[0] @ b[0] @ c[0]
    rd = a[1] @ b[0] @ c[0] + a[0] @ b[1] @ c[0] + a[0] @ b[0] @ c[1]
    rdd = (a[2] @ b[0] @ c[0] + a[0] @ b[2] @ c[0] + a[0] @ b[0] @ c[2]
           + 2.0 * (a[1] @ b[1] @ c[0] + a[1] @ b[0] @ c[1] + a[0] @ b[1] @ c[1]))
    return p, pd, pdd, r, rd, rdd


def _stewart(t):
    """Leg extensions (prismatic coordinates) of the Stewart platform along its platform
    motion: L = |p + R c_i - b_i| minus the fixed part of the leg, exact derivatives."""
    joints = _joint_params(STEWART)
    p, pd, pdd, r, rd, rdd = stewart_platform_motion(t)
    out = [[], [], []]
    for leg in active_joints(STEWART):
        i = leg[:-2]                                   # 'l3_p' -> 'l3'
        b = np.asarray(joints[f'{i}_u1']['parent_xyz'], dtype=float)
        c = np.asarray(joints[f'{i}_s3']['child_xyz'], dtype=float)
        offset = joints[leg]['parent_xyz'][2] - joints[leg]['child_xyz'][2]
        u, ud, udd = p + r @ c - b, pd + rd @ c, pdd + rdd @ c
        length = np.linalg.norm(u, axis=1)
        ld = np.einsum('ij,ij->i', u, ud) / length
        ldd = (np.einsum('ij,ij->i', ud, ud) + np.einsum('ij,ij->i', u, udd) - ld * ld) / length
        for k, x in enumerate((length - offset, ld, ldd)):
            out[k].append(x)
    return tuple(np.stack(x, axis=1) for x in out)


def delta_platform_motion(t):
    """Platform position (N, 3) of the delta robot, with its derivatives (p, pd, pdd)."""
    t = np.atleast_1d(np.asarray(t, dtype=float))
    laws = [f(t) for f in DELTA_LAWS]
    return tuple(np.stack([laws[i][k] for i in range(3)], axis=1) for k in range(3))


def _delta(t):
    """Arm angles of the delta robot along its platform motion: closed-form delta IK (elbow
    out), derivatives by differentiating |E(theta) - C(p)|^2 = rod^2 twice."""
    joints = _joint_params(DELTA)
    p, pd, pdd = delta_platform_motion(t)
    out = [[], [], []]
    for arm in active_joints(DELTA):
        i = arm.split('_')[0][1:]                      # 'l2_arm_joint' -> '2'
        pivot = np.asarray(joints[arm]['parent_xyz'], dtype=float)
        phi = joints[arm]['parent_rpy'][2]
        la = joints[f'r{i}a_u1']['parent_xyz'][0]
        rod = joints[f'r{i}a_s1']['parent_xyz'][2]
        cp, sp = np.cos(phi), np.sin(phi)
        to_leg = np.array([[cp, sp, 0.0], [-sp, cp, 0.0], [0.0, 0.0, 1.0]])
        rb = float(to_leg[0] @ pivot)
        rp = float(to_leg[0] @ np.asarray(joints[f'r{i}a_s3']['child_xyz'], dtype=float))
        x, xd, xdd = p @ to_leg.T, pd @ to_leg.T, pdd @ to_leg.T
        a = rb - rp - x[:, 0]
        kk = rod ** 2 - a * a - la ** 2 - x[:, 1] ** 2 - x[:, 2] ** 2
        th = np.arctan2(x[:, 2], a) + np.arccos(kk / (2.0 * la * np.hypot(a, x[:, 2])))
        c, s = np.cos(th), np.sin(th)
        zero = 0.0 * th
        g = np.stack([rb + la * c, zero, -la * s], axis=1) - (x + np.array([rp, 0.0, 0.0]))
        e1 = np.stack([-la * s, zero, -la * c], axis=1)
        e2 = np.stack([-la * c, zero, la * s], axis=1)
        dot = lambda u, v: np.einsum('ij,ij->i', u, v)  # noqa: E731
        ge1 = dot(g, e1)
        thd = dot(g, xd) / ge1
        w = e1 * thd[:, None] - xd
        thdd = (dot(g, xdd) - dot(g, e2) * thd * thd - dot(w, w)) / ge1
        for k, v in enumerate((th, thd, thdd)):
            out[k].append(v)
    return tuple(np.stack(v, axis=1) for v in out)


def _platform_driven(name, f):
    def traj(t):
        return f(np.atleast_1d(np.asarray(t, dtype=float)))
    traj.__name__ = 'trajectory_' + name.replace('.yaml', '')
    return traj


TRAJECTORIES[STEWART] = _platform_driven(STEWART, _stewart)
TRAJECTORIES[DELTA] = _platform_driven(DELTA, _delta)

#: configs that describe the mechanism of another config differently (same actuators, same
#: motion): test/core/test_closure_joints.py checks them against it, the oracle does not
#: read them (it knows revolute and prismatic joints only)
TWINS = {'stewart_6ups_spherical.yaml': STEWART, 'delta_3rus_spherical.yaml': DELTA}
for _twin, _original in TWINS.items():
    TRAJECTORIES[_twin] = TRAJECTORIES[_original]

#: configs the oracle cannot read: the twins, and URDF descriptions
#: (test/description/test_urdf.py and test_loop_closure_file.py check those against
#: Pinocchio's own URDF parser)
NOT_FOR_ORACLE = set(TWINS) | {'crank_rocker_urdf.yaml', 'five_bar_robot.yaml',
                                'talos_like_leg.yaml', 'parallel_ankle.yaml', 'digit_biped.yaml'}
