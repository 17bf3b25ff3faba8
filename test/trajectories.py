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
}


def config_path(name):
    return os.path.join(CONFIG_DIR, name)


@functools.lru_cache(maxsize=None)
def active_joints(name):
    """mechanism.active_joints of a config file."""
    with open(config_path(name), encoding='utf-8') as f:
        return yaml.safe_load(f)['/**']['ros__parameters']['mechanism']['active_joints']


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
