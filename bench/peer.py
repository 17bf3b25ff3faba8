"""A Pinocchio-based closed-chain inverse dynamics, written for speed: the issue's "peer".

The way a strong Pinocchio user would write it in Python, with the method of
test/pinocchio_reference.py (and no code of cog_id_ros: it reads the parameter file itself):

* spanning tree grown breadth-first from the base in the listed joint order; every tree joint
  a Pinocchio joint (unaligned revolute / prismatic, a joint written against the tree about
  the negated axis); every loop-closing joint an extra joint on its file parent carrying a
  massless body, welded (6 equations) to the child's attachment frame;
* the constraint Jacobian analytically from ONE ``computeJointJacobians`` per pose: the
  world Jacobian of a frame is the columns of its supporting joints, so a loop's rows are
  ``data.J`` times a fixed +-1/0 column mask; rows that are zero for a planar mechanism
  written in 3-D are dropped once at load (pivoted QR at the initial pose);
* positions by Newton's method on the passive joints, warm-started from the previous sample
  plus a first-order predictor along the previous velocity map (``dq_p = -X dq_a``);
* velocities and accelerations by solving with the passive columns (square when the
  actuation is not redundant: one inverse for the velocity map, the drift and the torques),
  drift from ``forwardKinematics(q, v, 0)`` (spatial accelerations of the cut frames);
* RNEA on the tree, then ``tau_a = tau_tree_a - X^T tau_tree_p`` (``X = J_p^-1 J_a``);
  redundant actuation: the null-space projection, weighted minimum norm, as in the oracle.

``Peer(path).torques(q, qd, qdd)`` one sample (warm-started); ``torques_many`` N samples in a
loop (the peer has no batch path of its own).
"""
from collections import deque

import numpy as np
import pinocchio as pin
import scipy.linalg as sla
import yaml

__all__ = ['Peer']


def _rpy(rpy):
    return pin.rpy.rpyToMatrix(np.asarray(rpy, dtype=float))


def _se3(xyz, rpy):
    return pin.SE3(_rpy(rpy), np.asarray(xyz, dtype=float))


def _flatten(d, prefix=''):
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f'{prefix}{k}.'))
        else:
            out[f'{prefix}{k}'] = v
    return out


def read_params(path):
    with open(path, encoding='utf-8') as f:
        data = yaml.safe_load(f)
    entry = data['/**'] if '/**' in data else next(iter(data.values()))
    return _flatten(entry['ros__parameters'])


class Peer:
    """Closed-chain inverse dynamics of the mechanism in a ROS 2 parameter file."""

    def __init__(self, path, tol=1e-12, max_iter=20):
        p = read_params(path)
        g = lambda k, d=None: p.get(k, d)  # noqa: E731
        self.tol, self.max_iter = tol, max_iter
        base = g('mechanism.base_link', 'ground')
        links = list(p['mechanism.links'])
        self.joints = joints = list(p['mechanism.joints'])
        self.active = active = list(p['mechanism.active_joints'])
        n = len(joints)
        w = g('mechanism.torque_weights')
        self.weights = np.asarray(w if w is not None else [1.0] * len(active), dtype=float)
        q0 = np.asarray(g('mechanism.initial_positions', [0.0] * n), dtype=float)
        inertia = {}
        for ln in links:
            ixx, iyy, izz, ixy, ixz, iyz = (float(v) for v in g(f'links.{ln}.inertia', [0.0] * 6))
            inertia[ln] = pin.Inertia(float(p[f'links.{ln}.mass']),
                                      np.asarray(g(f'links.{ln}.com', [0.0] * 3), dtype=float),
                                      np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]]))
        spec = {}
        for jn in joints:
            jg = lambda k, d=None: g(f'joints.{jn}.{k}', d)  # noqa: E731
            axis = np.asarray(jg('axis', [0.0, 0.0, 1.0]), dtype=float)
            spec[jn] = (jg('type'), jg('parent'), jg('child'),
                        _se3(jg('parent_xyz', [0.0] * 3), jg('parent_rpy', [0.0] * 3)),
                        _se3(jg('child_xyz', [0.0] * 3), jg('child_rpy', [0.0] * 3)),
                        axis / np.linalg.norm(axis))
        model = pin.Model()
        model.gravity = pin.Motion(np.r_[np.asarray(g('mechanism.gravity', [0.0, 0.0, -9.81]),
                                                    dtype=float), 0.0, 0.0, 0.0])
        holder = {base: 0}                       # Pinocchio joint carrying each link
        in_joint = {base: pin.SE3.Identity()}    # link frame in its joint's frame
        jid = {}
        used = set()
        queue = deque([base])

        def joint_model(kind, axis):
            return (pin.JointModelRevoluteUnaligned(axis) if kind == 'revolute'
                    else pin.JointModelPrismaticUnaligned(axis))

        while queue:
            a = queue.popleft()
            for jn in joints:
                kind, par, chi, tp, tc, axis = spec[jn]
                if jn in used:
                    continue
                if par == a and chi not in holder:
                    b, place, axis_, b_in = chi, in_joint[a] * tp, axis, tc.inverse()
                elif chi == a and par not in holder:
                    b, place, axis_, b_in = par, in_joint[a] * tc, -axis, tp.inverse()
                else:
                    continue
                used.add(jn)
                k = model.addJoint(holder[a], joint_model(kind, axis_), place, jn)
                model.appendBodyToJoint(k, inertia[b], b_in)
                holder[b], in_joint[b], jid[jn] = k, b_in, k
                queue.append(b)
        cuts = []
        for jn in joints:
            if jn in used:
                continue
            kind, par, chi, tp, tc, axis = spec[jn]
            k = model.addJoint(holder[par], joint_model(kind, axis), in_joint[par] * tp, jn)
            model.appendBodyToJoint(k, pin.Inertia.Zero(), pin.SE3.Identity())
            jid[jn] = k
            cuts.append((k, holder[chi], in_joint[chi] * tc))
        self.model, self.data = model, model.createData()
        self.cuts = cuts
        perm = np.array([model.joints[jid[jn]].idx_v for jn in joints])
        self.perm = perm                          # file index -> Pinocchio index
        self.ia = perm[[joints.index(j) for j in active]]
        self.ip = np.array(sorted(set(range(n)) - set(self.ia.tolist())))
        # column masks: +1 on the support of the child side, -1 on that of the cut joint
        support = [set(model.supports[j].tolist()) - {0} for j in range(model.njoints)]
        idx_v = [model.joints[j].idx_v if j else -1 for j in range(model.njoints)]
        self.masks = np.zeros((len(cuts), n))
        for c, (km, kc, _) in enumerate(cuts):
            for j in support[kc]:
                self.masks[c, idx_v[j]] += 1.0
            for j in support[km]:
                self.masks[c, idx_v[j]] -= 1.0
        self.q = np.empty(n)
        self.q[perm] = q0
        self.rows = np.arange(6 * len(cuts))
        jac = self._jacobian(self.q)
        dof_rank = np.linalg.matrix_rank(jac) if jac.size else 0
        if dof_rank < jac.shape[0]:               # planar loops written in 3-D: drop zero rows
            _, _, piv = sla.qr(jac.T, pivoting=True, mode='economic')
            self.rows = np.sort(piv[:dof_rank])
        self.dof = n - dof_rank
        self.redundant = len(active) > self.dof
        self.x = None                             # last velocity map J_p^-1 J_a
        self.start = self.q.copy()

    def reset(self):
        self.q, self.x = self.start.copy(), None

    # ------------------------------------------------------------------ kinematics
    def _jacobian(self, q):
        """World-frame constraint Jacobian (selected rows) at q; data holds the kinematics."""
        pin.computeJointJacobians(self.model, self.data, q)
        j = self.data.J
        full = (j[None, :, :] * self.masks[:, None, :]).reshape(-1, j.shape[1])
        return full[self.rows] if len(self.rows) < full.shape[0] else full

    def _residual(self):
        """Closure residual in world axes consistent with the world Jacobian: per loop the
        translation mismatch plus p x the rotation mismatch, then the rotation mismatch."""
        oMi = self.data.oMi
        out = []
        for km, kc, pl in self.cuts:
            mc = oMi[kc] * pl
            mm = oMi[km]
            rot = mm.rotation @ pin.log3(mm.rotation.T @ mc.rotation)
            px, py, pz = pos = mc.translation
            rx, ry, rz = rot
            out.append(pos - mm.translation + (py * rz - pz * ry, pz * rx - px * rz, px * ry - py * rx))
            out.append(rot)
        r = np.concatenate(out) if out else np.zeros(0)
        return r[self.rows]

    def _solve_positions(self, qa):
        q = self.q
        dqa = qa - q[self.ia]
        if self.x is not None:                    # predictor along the last velocity map
            q[self.ip] -= self.x @ dqa
        q[self.ia] = qa
        for _ in range(self.max_iter):
            jac = self._jacobian(q)
            r = self._residual()
            if np.abs(r).max() < self.tol:
                return q, jac
            jp = jac[:, self.ip]
            step = (np.linalg.solve(jp, r) if jp.shape[0] == jp.shape[1]
                    else np.linalg.lstsq(jp, r, rcond=None)[0])
            q[self.ip] -= step
        raise RuntimeError(f'peer: loops do not close (residual {np.abs(r).max():.2e})')

    def _drift(self, q, v):
        pin.forwardKinematics(self.model, self.data, q, v, np.zeros_like(v))
        oMi, a = self.data.oMi, self.data.a
        d = np.concatenate([(oMi[kc].act(a[kc]) - oMi[km].act(a[km])).vector
                            for km, kc, _ in self.cuts])
        return d[self.rows]

    # ------------------------------------------------------------------ dynamics
    def torques(self, q_active, qd_active, qdd_active):
        """Actuator torques (mechanism.active_joints order) of one sample, warm-started."""
        qa = np.asarray(q_active, dtype=float)
        qda = np.asarray(qd_active, dtype=float)
        qdda = np.asarray(qdd_active, dtype=float)
        q, jac = self._solve_positions(qa)
        n = len(q)
        v = np.empty(n)
        a = np.empty(n)
        if not self.redundant:
            jp, ja = jac[:, self.ip], jac[:, self.ia]
            inv = np.linalg.inv(jp)               # one factorisation, three uses
            self.x = x = inv @ ja
            v[self.ia], v[self.ip] = qda, -x @ qda
            a[self.ia] = qdda
            a[self.ip] = -x @ qdda - inv @ self._drift(q, v)
            tau = pin.rnea(self.model, self.data, q, v, a)
            return tau[self.ia] - x.T @ tau[self.ip]
        # redundant actuation: null space V, weighted minimum norm (as in the oracle)
        _, s, vt = np.linalg.svd(jac)
        basis = vt[np.sum(s > 1e-9 * s[0]):].T
        va = basis[self.ia]
        wi = 1.0 / self.weights
        gram = va.T @ (wi[:, None] * va)
        z = np.linalg.solve(gram, va.T @ (wi * qda))
        v = basis @ z
        a0 = -np.linalg.lstsq(jac, self._drift(q, v), rcond=None)[0]
        a = a0 + basis @ np.linalg.solve(gram, va.T @ (wi * (qdda - a0[self.ia])))
        pp = np.linalg.lstsq(jac[:, self.ip], -jac[:, self.ia], rcond=None)[0]
        self.x = -pp
        tau = pin.rnea(self.model, self.data, q, v, a)
        return wi * (va @ np.linalg.solve(gram, basis.T @ tau))

    def torques_many(self, q, qd, qdd):
        """N samples, one after the other (warm-started): (N, M)."""
        return np.array([self.torques(q[k], qd[k], qdd[k]) for k in range(len(q))])


class OraclePeer:
    """The peer the speed issue measured (771 us a sample on the Stewart platform): the test
    oracle, test/pinocchio_reference.Oracle, timed per sample as it is, warm-started from
    the previous pose (Gauss-Newton with numpy least squares, SVD null space, RNEA)."""

    def __init__(self, path):
        from pinocchio_reference import Oracle
        self.oracle = Oracle(path)
        self.q = None

    def torques(self, q_active, qd_active, qdd_active):
        self.q = self.oracle.solve_positions(q_active, q_guess=self.q)
        return self.oracle.active_torques(self.q, qd_active, qdd_active)
