"""Independent reference for a URDF with a loop-closure file (the Pinocchio ecosystem's form).

TEST ORACLE ONLY; never imports cog_id_ros. Pinocchio's own URDF parser (urdfdom) reads the
tree; the file's joint edits are made as the loader of LAAS's example-parallel-robots makes
them (``SPHERICAL``: the joint model replaced by ``JointModelSpherical`` at the same
placement; ``FIXED``: the joint locked at the neutral configuration by
``buildReducedModel``); ``UJOINT_*`` edits are not made here: a test gives the oracle the
URDF with the two revolute joints and the massless link written out. Each frame pair of
``closed_loop`` is a constraint between Pinocchio frames of those names: ``6d``,
``log6(oMa^-1 oMb) = 0``; ``3d``, their origins coincide.

Dynamics as in test/pinocchio_reference.py, with Pinocchio's velocities (nv) instead of the
file's coordinates: V = null space of the constraint velocity Jacobian, qd = V z from the
active velocities, qdd = particular + V zdd, RNEA torques of the tree, and the active
torques tau with V_a^T tau = V^T tau_tree.
"""
from __future__ import annotations

import numpy as np
import pytest
import yaml

pin = pytest.importorskip('pinocchio')

__all__ = ['LoopOracle']

_WORLD, _ALIGNED = pin.ReferenceFrame.WORLD, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
_LOCAL = pin.ReferenceFrame.LOCAL


def _null_space(a, rtol=1e-9):
    if a.shape[0] == 0:
        return np.eye(a.shape[1])
    _, s, vt = np.linalg.svd(a)
    rank = int(np.sum(s > rtol * max(s[0], 1e-300))) if s.size else 0
    return vt[rank:].T.copy()


def _edited(model, edits):
    """The model with the loader's SPHERICAL and FIXED edits made."""
    if not edits:
        return model
    new, locked = pin.Model(), []
    new.gravity = model.gravity
    for place, inertia, name, parent, joint in list(zip(
            model.jointPlacements, model.inertias, model.names, model.parents,
            model.joints))[1:]:
        kind = edits.get(name, '').upper()
        jm = pin.JointModelSpherical() if kind == 'SPHERICAL' else joint
        jid = new.addJoint(parent, jm, place, name)
        new.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        if kind == 'FIXED':
            locked.append(jid)
    for frame in list(model.frames)[1:]:
        new.addFrame(pin.Frame(frame.name, frame.parentJoint, frame.placement, frame.type),
                     False)
    if locked:
        new = pin.buildReducedModel(new, locked, pin.neutral(new))
    return new


class LoopOracle:
    """Pinocchio model of ``urdf`` (text) with the loops of ``loops`` (the loop-closure
    file's text) and active joints ``active`` (default: its name_mot)."""

    def __init__(self, urdf, loops, gravity=(0.0, 0.0, -9.81), active=None):
        spec = yaml.safe_load(loops)
        model = pin.buildModelFromXML(urdf)
        model.gravity.linear = np.array(gravity, dtype=float)
        self.model = _edited(model, dict(zip(spec.get('joint_name', []),
                                             spec.get('joint_type', []))))
        self.data = self.model.createData()
        self.pairs = [(self.model.getFrameId(a), self.model.getFrameId(b), kind.lower())
                      for (a, b), kind in zip(spec['closed_loop'], spec['type'])]
        for a, b, _ in self.pairs:
            assert a < self.model.nframes and b < self.model.nframes
        self.active = list(active if active is not None else spec['name_mot'])
        self.ia = [self.v_index(name) for name in self.active]

    def v_index(self, name):
        joint = self.model.joints[self.model.getJointId(name)]
        assert joint.nv == 1, name
        return joint.idx_v

    def configuration(self, positions):
        """Pinocchio's q with the one-coordinate joints of ``positions`` (name -> value) set
        and the others (spherical joints) at their neutral configuration; joints this model
        locked (FIXED) are left out."""
        q = pin.neutral(self.model)
        for name, value in positions.items():
            if not self.model.existJointName(name):     # locked here (a FIXED edit)
                continue
            joint = self.model.joints[self.model.getJointId(name)]
            assert joint.nq == 1, name
            q[joint.idx_q] = value
        return q

    def position(self, q, name):
        return float(q[self.model.joints[self.model.getJointId(name)].idx_q])

    # ------------------------------------------------------------------ constraints
    def residual(self, q):
        pin.framesForwardKinematics(self.model, self.data, q)
        rows = []
        for a, b, kind in self.pairs:
            ma, mb = self.data.oMf[a], self.data.oMf[b]
            rows.append(pin.log6(ma.actInv(mb)).vector if kind == '6d'
                        else mb.translation - ma.translation)
        return np.concatenate(rows)

    def _jacobian(self, frame, reference):
        return pin.getFrameJacobian(self.model, self.data, frame, reference)

    def position_jacobian(self, q):
        """d residual / dv (for Newton)."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        rows = []
        for a, b, kind in self.pairs:
            if kind == '6d':
                err = self.data.oMf[a].actInv(self.data.oMf[b])
                rows.append(pin.Jlog6(err) @ (self._jacobian(b, _LOCAL) - err.inverse().action
                                              @ self._jacobian(a, _LOCAL)))
            else:
                rows.append(self._jacobian(b, _ALIGNED)[:3] - self._jacobian(a, _ALIGNED)[:3])
        return np.vstack(rows)

    def velocity_jacobian(self, q):
        """Rows of the constraints on velocities: the relative twist (6d, world frame) or
        the relative velocity of the origins (3d)."""
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        rows = []
        for a, b, kind in self.pairs:
            if kind == '6d':
                rows.append(self._jacobian(b, _WORLD) - self._jacobian(a, _WORLD))
            else:
                rows.append(self._jacobian(b, _ALIGNED)[:3] - self._jacobian(a, _ALIGNED)[:3])
        return np.vstack(rows)

    def drift(self, q, v):
        pin.forwardKinematics(self.model, self.data, q, v, np.zeros(self.model.nv))
        pin.updateFramePlacements(self.model, self.data)
        rows = []
        for a, b, kind in self.pairs:
            if kind == '6d':
                rows.append((pin.getFrameAcceleration(self.model, self.data, b, _WORLD)
                             - pin.getFrameAcceleration(self.model, self.data, a, _WORLD)
                             ).vector)
            else:
                rows.append(
                    pin.getFrameClassicalAcceleration(self.model, self.data, b, _ALIGNED).linear
                    - pin.getFrameClassicalAcceleration(self.model, self.data, a, _ALIGNED
                                                        ).linear)
        return np.concatenate(rows)

    def close(self, q, tol=1e-12, iterations=30):
        """q with the loops closed, the active joints held (Gauss-Newton; the last
        iterations only polish rounding)."""
        free = [k for k in range(self.model.nv) if k not in self.ia]
        for k in range(iterations):
            r = self.residual(q)
            if np.linalg.norm(r) < tol or k > 10 and np.linalg.norm(r) < 1e3 * tol:
                return q
            step = np.zeros(self.model.nv)
            step[free] = np.linalg.lstsq(self.position_jacobian(q)[:, free], -r,
                                         rcond=1e-12)[0]
            q = pin.integrate(self.model, q, step)
        raise AssertionError(f'the oracle could not close the loops: {np.linalg.norm(r)}')

    # ------------------------------------------------------------------ dynamics
    def torques(self, q, qd_active, qdd_active):
        """(tau of the active joints, qd, qdd) at the closed pose q."""
        jac = self.velocity_jacobian(q)
        basis = _null_space(jac)
        va = basis[self.ia]
        assert basis.shape[1] == len(self.ia), 'the oracle expects one actuator per freedom'
        v = basis @ np.linalg.solve(va, np.asarray(qd_active, dtype=float))
        particular = -np.linalg.lstsq(jac, self.drift(q, v), rcond=1e-10)[0]
        a = particular + basis @ np.linalg.solve(
            va, np.asarray(qdd_active, dtype=float) - particular[self.ia])
        tau_tree = pin.rnea(self.model, self.data, q, v, a)
        return np.linalg.solve(va.T, basis.T @ tau_tree), v, a
