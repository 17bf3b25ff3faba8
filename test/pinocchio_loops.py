"""Independent reference for a URDF with a loop-closure file (the Pinocchio ecosystem's form).

TEST ORACLE ONLY; never imports cog_id_ros. Pinocchio's own URDF parser (urdfdom) reads the
tree; the file's joint edits are made as the loader of LAAS's example-parallel-robots makes
them (``SPHERICAL``: the joint model replaced by ``JointModelSpherical`` at the same
placement; ``FIXED``: the joint locked at the neutral configuration by
``buildReducedModel``; ``UJOINT_<A><B>``: two joints ``JointModelR<A>`` at the joint's
placement, named ``<joint>_<A>``, then ``JointModelR<B>`` at the identity, ``<joint>_<B>``,
carrying the body and the frames). Each frame pair of ``closed_loop`` is a constraint
between Pinocchio frames of those names: ``6d``, ``log6(oMa^-1 oMb) = 0``; ``3d``, their
origins coincide. A URDF ``<mimic>`` (Pinocchio's parser makes the follower a joint of its
own) is one more constraint row, ``q_f - m q_l - o = 0``, read from the URDF text here.
``held`` joints are held like actuators that do not move (a locked joint).

Dynamics as in test/pinocchio_reference.py, with Pinocchio's velocities (nv) instead of the
file's coordinates: V = null space of the constraint velocity Jacobian, qd = V z from the
active velocities, qdd = particular + V zdd, RNEA torques of the tree, and the active
torques tau with V_a^T tau = V^T tau_tree: the least-norm such tau where the actuators are
redundant (more than the freedoms; unit weights).
"""
from __future__ import annotations

import xml.etree.ElementTree as ElementTree

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


_AXES = {'X': 'RX', 'Y': 'RY', 'Z': 'RZ'}


def _edited(model, edits):
    """The model with the loader's SPHERICAL, FIXED and UJOINT_<A><B> edits made."""
    if not edits:
        return model
    new, locked = pin.Model(), []
    new.gravity = model.gravity
    renamed = {}         # old joint id -> the new joint that carries its body and frames
    for old_id, (place, inertia, name, parent, joint) in list(enumerate(zip(
            model.jointPlacements, model.inertias, model.names, model.parents,
            model.joints)))[1:]:
        kind = edits.get(name, '').upper()
        parent_id = renamed.get(parent, 0)
        if kind.startswith('UJOINT_'):
            first = getattr(pin, f'JointModel{_AXES[kind[7]]}')()
            second = getattr(pin, f'JointModel{_AXES[kind[8]]}')()
            middle = new.addJoint(parent_id, first, place, f'{name}_{kind[7]}')
            jid = new.addJoint(middle, second, pin.SE3.Identity(), f'{name}_{kind[8]}')
        else:
            jm = pin.JointModelSpherical() if kind == 'SPHERICAL' else joint
            jid = new.addJoint(parent_id, jm, place, name)
        renamed[old_id] = jid
        new.appendBodyToJoint(jid, inertia, pin.SE3.Identity())
        if kind == 'FIXED':
            locked.append(jid)
    for frame in list(model.frames)[1:]:
        new.addFrame(pin.Frame(frame.name, renamed.get(frame.parentJoint, 0), frame.placement,
                               frame.type), False)
    if locked:
        new = pin.buildReducedModel(new, locked, pin.neutral(new))
    return new


def _mimics(urdf):
    """(follower, leader, multiplier, offset) of every <mimic> of the URDF text."""
    out = []
    for joint in ElementTree.fromstring(urdf).iter('joint'):
        tag = joint.find('mimic')
        if tag is not None:
            out.append((joint.get('name'), tag.get('joint'),
                        float(tag.get('multiplier', 1.0)), float(tag.get('offset', 0.0))))
    return out


class LoopOracle:
    """Pinocchio model of ``urdf`` (text) with the loops of ``loops`` (the loop-closure
    file's text) and active joints ``active`` (default: its name_mot)."""

    def __init__(self, urdf, loops, gravity=(0.0, 0.0, -9.81), active=None, held=(),
                 free_flyer=False):
        spec = yaml.safe_load(loops)
        model = pin.buildModelFromXML(urdf, pin.JointModelFreeFlyer()) if free_flyer else \
            pin.buildModelFromXML(urdf)
        #: the free flyer's velocity indices (held like the actuators when closing loops)
        self.ib = list(range(6)) if free_flyer else []
        model.gravity.linear = np.array(gravity, dtype=float)
        self.model = _edited(model, dict(zip(spec.get('joint_name', []),
                                             spec.get('joint_type', []))))
        self.data = self.model.createData()
        self.pairs = [(self.model.getFrameId(a), self.model.getFrameId(b), kind.lower())
                      for (a, b), kind in zip(spec['closed_loop'], spec['type'])]
        for a, b, _ in self.pairs:
            assert a < self.model.nframes and b < self.model.nframes
        self.mimics = [(self.v_index(f), self.v_index(lead), m, o)
                       for f, lead, m, o in _mimics(urdf)]
        self.active = list(active if active is not None else spec['name_mot'])
        self.held = list(held)
        self.ia = [self.v_index(name) for name in self.active]
        self.ih = [self.v_index(name) for name in self.held]

    def v_index(self, name):
        assert self.model.existJointName(name), name
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
        rows.append(np.array([q[self._q(f)] - m * q[self._q(lead)] - o
                              for f, lead, m, o in self.mimics]))
        return np.concatenate(rows)

    def _q(self, v):
        """The configuration index of a one-coordinate joint's velocity index."""
        joint = next(j for j in self.model.joints[1:] if j.idx_v == v)
        return joint.idx_q

    def _mimic_rows(self):
        rows = np.zeros((len(self.mimics), self.model.nv))
        for k, (f, lead, m, _) in enumerate(self.mimics):
            rows[k, f], rows[k, lead] = 1.0, -m
        return rows

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
        return np.vstack(rows + [self._mimic_rows()])

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
        return np.vstack(rows + [self._mimic_rows()])

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
        rows.append(np.zeros(len(self.mimics)))
        return np.concatenate(rows)

    def close(self, q, tol=1e-12, iterations=30):
        """q with the loops closed, the active joints held (Gauss-Newton; the last
        iterations only polish rounding)."""
        free = [k for k in range(self.model.nv) if k not in self.ia + self.ih + self.ib]
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
        """(tau of the active joints, qd, qdd) at the closed pose q, the held joints still
        (one constraint row each). Redundant actuators: the least-norm tau (unit weights)."""
        jac = self.velocity_jacobian(q)
        held = np.zeros((len(self.ih), self.model.nv))
        held[np.arange(len(self.ih)), self.ih] = 1.0
        basis = _null_space(np.vstack([jac, held]))
        va = basis[self.ia]
        assert np.linalg.matrix_rank(va) == basis.shape[1], 'the actuators do not determine it'
        v = basis @ np.linalg.lstsq(va, np.asarray(qd_active, dtype=float), rcond=None)[0]
        drift = np.concatenate([self.drift(q, v), np.zeros(len(self.ih))])
        particular = -np.linalg.lstsq(np.vstack([jac, held]), drift, rcond=1e-10)[0]
        a = particular + basis @ np.linalg.lstsq(
            va, np.asarray(qdd_active, dtype=float) - particular[self.ia], rcond=None)[0]
        tau_tree = pin.rnea(self.model, self.data, q, v, a)
        tau = va @ np.linalg.solve(va.T @ va, basis.T @ tau_tree)   # least norm
        return tau, v, a

    # ------------------------------------------------------------------ free flyer
    def add_contact(self, name, link, xyz=(0.0, 0.0, 0.0), rpy=(0.0, 0.0, 0.0)):
        """A frame ``name`` on the body of URDF link ``link`` at (xyz, rpy) in its frame."""
        parent = self.model.frames[self.model.getFrameId(link)]
        place = parent.placement * pin.SE3(pin.rpy.rpyToMatrix(np.array(rpy, dtype=float)),
                                           np.array(xyz, dtype=float))
        self.model.addFrame(pin.Frame(name, parent.parentJoint, self.model.getFrameId(link),
                                      place, pin.FrameType.OP_FRAME), False)
        self.data = self.model.createData()

    def whole_body(self, q, base_v, base_a, qd_active, qdd_active, contacts, weights=None):
        """(efforts, wrenches (k,), base_wrench) at the closed pose q of a free-flyer model:
        the generalized forces of the independent coordinates (the base's six, then the
        actuators) are V_i^-T V^T (rnea - J_c^T w); the wrenches w (world axes at each
        contact frame, ``contacts``: (frame name, 6 or 3)) of least weighted norm with the
        base's six rows zero (least squares where none is)."""
        jac = self.velocity_jacobian(q)
        basis = _null_space(jac)
        independent = self.ib + self.ia
        vi = basis[independent]
        assert np.linalg.matrix_rank(vi) == basis.shape[1] == len(independent)
        v = basis @ np.linalg.solve(vi, np.concatenate([base_v, qd_active]))
        particular = -np.linalg.lstsq(jac, self.drift(q, v), rcond=1e-10)[0]
        a = particular + basis @ np.linalg.solve(
            vi, np.concatenate([base_a, qdd_active]) - particular[independent])
        to_independent = np.linalg.inv(vi).T @ basis.T            # (6 + M, nv)
        generalized = to_independent @ pin.rnea(self.model, self.data, q, v, a)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        columns = [pin.getFrameJacobian(self.model, self.data, self.model.getFrameId(name),
                                        _ALIGNED)[:size].T for name, size in contacts]
        maps = to_independent @ (np.hstack(columns) if columns else np.zeros((self.model.nv, 0)))
        base_map, weights = maps[:6], np.ones(maps.shape[1]) if weights is None else weights
        scale = 1.0 / np.sqrt(weights)
        w = scale * (np.linalg.pinv(base_map * scale, rcond=1e-10) @ generalized[:6]) \
            if maps.shape[1] else np.zeros(0)
        return generalized[6:] - maps[6:] @ w, w, generalized[:6] - base_map @ w
