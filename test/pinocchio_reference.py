"""Independent reference inverse dynamics for closed-link mechanisms, built on Pinocchio.

TEST ORACLE ONLY. It never imports cog_id_ros: it reads the mechanism parameter file
(the format documented in README.md) itself, so that it shares no code, and no reading of
the file, with the package under test.

Method (deliberately not the COG-Jacobian method of the package):

* A spanning tree of the link/joint graph is grown breadth-first from the base link, in
  the order the joints are listed. Every tree joint becomes a Pinocchio joint
  (``JointModelRevoluteUnaligned`` / ``JointModelPrismaticUnaligned``, unit axis). A joint
  written "backwards" with respect to the tree (its file ``child`` is the tree parent)
  becomes a Pinocchio joint about the negated axis, so its Pinocchio coordinate is still
  the file's coordinate ``q``.
* Every joint that is not in the tree closes a loop. It is modelled as an extra
  Pinocchio joint hanging from its file ``parent`` link, carrying a massless body, plus
  a 6-D weld between that body's frame ("cut_m") and the child's attachment frame
  ("cut_c"). Thus every joint of the file, tree or loop-closing, is one Pinocchio
  coordinate, and the closure residual is ``log6(oMcut_m^-1 * oMcut_c)``, 6 rows a loop.
* Velocities: ``V`` = SVD null space of the (world-frame) closure Jacobian, ``V_a`` its
  active rows; ``qd = V z``, ``z`` from the active velocities.
* Accelerations: ``J qdd = -drift`` with the drift from Pinocchio's frame accelerations
  at zero joint acceleration (spatial accelerations in the world frame), plus ``V zdd``.
* Torques: RNEA on the tree (massless loop bodies give zero), then the active torques
  are the W-weighted minimum-norm ``tau`` with ``V_a^T tau = V^T tau_tree``.

All joint vectors (``q_all`` etc.) are in the order of ``mechanism.joints`` of the file;
active vectors in the order of ``mechanism.active_joints``.
"""
from __future__ import annotations

from collections import deque
import math

import numpy as np
import pytest
import yaml

# a test dependency only (package.xml <test_depend>): modules that need it skip without it
pin = pytest.importorskip('pinocchio')

__all__ = ['load_params', 'rpy_matrix', 'transform', 'Oracle']


# --------------------------------------------------------------------------- file reading

def _flatten(d, prefix=''):
    out = {}
    for k, v in d.items():
        name = f'{prefix}{k}'
        if isinstance(v, dict):
            out.update(_flatten(v, name + '.'))
        else:
            out[name] = v
    return out


def load_params(path, node=None):
    """Read a ROS 2 parameter file; return the node's parameters as a flat dotted dict."""
    with open(path, 'r', encoding='utf-8') as f:
        data = yaml.safe_load(f)
    if node is not None:
        entry = data.get(node, data.get('/' + node.lstrip('/')))
        if entry is None:
            raise KeyError(f'{path}: no node entry {node!r}')
    elif '/**' in data:
        entry = data['/**']
    elif len(data) == 1:
        entry = next(iter(data.values()))
    else:
        raise KeyError(f'{path}: several node entries, name one of {list(data)}')
    return _flatten(entry['ros__parameters'])


def rpy_matrix(rpy):
    """URDF roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll), written out with numpy."""
    r, p, y = (float(v) for v in rpy)
    cr, sr, cp, sp, cy, sy = math.cos(r), math.sin(r), math.cos(p), math.sin(p), math.cos(y), math.sin(y)
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    return rz @ ry @ rx


def transform(xyz, rpy):
    """Homogeneous 4x4 transform T(xyz, rpy)."""
    t = np.eye(4)
    t[:3, :3] = rpy_matrix(rpy)
    t[:3, 3] = np.asarray(xyz, dtype=float)
    return t


def _se3(t):
    return pin.SE3(np.array(t[:3, :3]), np.array(t[:3, 3]))


class _Joint:
    def __init__(self, name, p):
        g = lambda key, default=None: p.get(f'joints.{name}.{key}', default)  # noqa: E731
        self.name = name
        self.type = g('type')
        if self.type not in ('revolute', 'prismatic'):
            raise ValueError(f'joints.{name}.type: unknown type {self.type!r}')
        self.parent = g('parent')
        self.child = g('child')
        self.t_parent = transform(g('parent_xyz', [0.0] * 3), g('parent_rpy', [0.0] * 3))
        self.t_child = transform(g('child_xyz', [0.0] * 3), g('child_rpy', [0.0] * 3))
        axis = np.asarray(g('axis', [0.0, 0.0, 1.0]), dtype=float)
        norm = np.linalg.norm(axis)
        if not norm > 0.0:
            raise ValueError(f'joints.{name}.axis: zero length')
        self.axis = axis / norm


def _null_space(a, rtol=1e-9):
    """Orthonormal basis of the null space of ``a`` (columns) and the rank."""
    n = a.shape[1]
    if a.shape[0] == 0:
        return np.eye(n), 0
    _, s, vt = np.linalg.svd(a)
    rank = int(np.sum(s > rtol * max(s[0], 1e-300))) if s.size else 0
    return vt[rank:].T.copy(), rank


# --------------------------------------------------------------------------- the oracle

class Oracle:
    """Pinocchio model of the mechanism in a parameter file.

    ``active`` overrides ``mechanism.active_joints`` (e.g. to drive a redundant mechanism
    through an independent subset of its actuators); ``weights`` then defaults to ones.
    """

    def __init__(self, path, node=None, active=None):
        p = load_params(path, node)
        self.params = p
        self.name = p.get('mechanism.name', '')
        self.base = p.get('mechanism.base_link', 'ground')
        self.links = list(p['mechanism.links'])
        self.joints = list(p['mechanism.joints'])
        self.gravity = np.asarray(p.get('mechanism.gravity', [0.0, 0.0, -9.81]), dtype=float)
        file_active = list(p['mechanism.active_joints'])
        self.active = list(active) if active is not None else file_active
        w = p.get('mechanism.torque_weights') if active is None else None
        self.weights = np.asarray(w if w is not None else [1.0] * len(self.active), dtype=float)
        init = p.get('mechanism.initial_positions')
        self.initial_positions = (np.asarray(init, dtype=float) if init is not None
                                  else np.zeros(len(self.joints)))
        self.n = len(self.joints)
        self.ia = np.array([self.joints.index(j) for j in self.active], dtype=int)
        self.ip = np.array([i for i in range(self.n) if i not in set(self.ia.tolist())], dtype=int)
        self.joint = {j: _Joint(j, p) for j in self.joints}
        self.inertia = {}
        for ln in self.links:
            m = float(p[f'links.{ln}.mass'])
            c = np.asarray(p[f'links.{ln}.com'], dtype=float)
            ixx, iyy, izz, ixy, ixz, iyz = (float(v) for v in p[f'links.{ln}.inertia'])
            i3 = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
            self.inertia[ln] = pin.Inertia(m, c, i3)
        self._build()

    # ---------------------------------------------------------------- model construction
    def _build(self):
        model = pin.Model()
        model.gravity = pin.Motion(np.r_[self.gravity, 0.0, 0.0, 0.0])
        link_joint = {self.base: 0}            # Pinocchio joint carrying each link
        link_in_joint = {self.base: np.eye(4)}  # pose of the link frame in that joint's frame
        self.tree_joints, self.reversed, self.loop_joints = [], [], []
        pin_id = {}
        queue = deque([self.base])
        used = set()
        while queue:
            a = queue.popleft()
            for jn in self.joints:
                if jn in used:
                    continue
                j = self.joint[jn]
                if j.parent == a and j.child not in link_joint:
                    b, rev = j.child, False
                elif j.child == a and j.parent not in link_joint:
                    b, rev = j.parent, True
                else:
                    continue
                if b not in self.inertia:
                    raise ValueError(f'joints.{jn}: unknown link {b!r}')
                used.add(jn)
                if not rev:
                    # T_w_b Tc = T_w_a Tp M(a, q)  ->  T_w_b = (T_w_a Tp) M(a, q) Tc^-1
                    placement = link_in_joint[a] @ j.t_parent
                    axis = j.axis
                    b_in_joint = np.linalg.inv(j.t_child)
                else:
                    # T_w_a Tc = T_w_b Tp M(a, q)  ->  T_w_b = (T_w_a Tc) M(-a, q) Tp^-1
                    placement = link_in_joint[a] @ j.t_child
                    axis = -j.axis
                    b_in_joint = np.linalg.inv(j.t_parent)
                jm = (pin.JointModelRevoluteUnaligned(axis) if j.type == 'revolute'
                      else pin.JointModelPrismaticUnaligned(axis))
                jid = model.addJoint(link_joint[a], jm, _se3(placement), jn)
                model.appendBodyToJoint(jid, self.inertia[b], _se3(b_in_joint))
                model.addFrame(pin.Frame('link:' + b, jid, _se3(b_in_joint), pin.FrameType.OP_FRAME))
                link_joint[b] = jid
                link_in_joint[b] = b_in_joint
                pin_id[jn] = jid
                self.tree_joints.append(jn)
                if rev:
                    self.reversed.append(jn)
                queue.append(b)
        missing = [ln for ln in self.links if ln not in link_joint]
        if missing:
            raise ValueError(f'links not connected to {self.base}: {missing}')
        self.cut_frames = []
        for jn in self.joints:
            if jn in used:
                continue
            j = self.joint[jn]
            pl = link_joint[j.parent]
            placement = link_in_joint[j.parent] @ j.t_parent
            jm = (pin.JointModelRevoluteUnaligned(j.axis) if j.type == 'revolute'
                  else pin.JointModelPrismaticUnaligned(j.axis))
            jid = model.addJoint(pl, jm, _se3(placement), jn)
            model.appendBodyToJoint(jid, pin.Inertia.Zero(), pin.SE3.Identity())
            fm = model.addFrame(pin.Frame('cut_m:' + jn, jid, pin.SE3.Identity(), pin.FrameType.OP_FRAME))
            fc = model.addFrame(pin.Frame('cut_c:' + jn, link_joint[j.child],
                                          _se3(link_in_joint[j.child] @ j.t_child),
                                          pin.FrameType.OP_FRAME))
            pin_id[jn] = jid
            self.loop_joints.append(jn)
            self.cut_frames.append((fm, fc))
        self.model = model
        self.data = model.createData()
        # file index -> Pinocchio velocity index (all joints have nq = nv = 1)
        self.perm = np.array([model.joints[pin_id[jn]].idx_v for jn in self.joints], dtype=int)
        assert sorted(self.perm.tolist()) == list(range(self.n)) and model.nv == self.n
        self.link_frame = {ln: model.getFrameId('link:' + ln) for ln in self.links}

    # ---------------------------------------------------------------- ordering helpers
    def _to_pin(self, x):
        out = np.empty(self.n)
        out[self.perm] = x
        return out

    def _from_pin(self, y):
        return np.asarray(y)[self.perm]

    # ---------------------------------------------------------------- kinematics
    def link_poses(self, q_all):
        """World 4x4 pose of every link frame (and the base), from Pinocchio."""
        q = self._to_pin(q_all)
        pin.framesForwardKinematics(self.model, self.data, q)
        out = {self.base: np.eye(4)}
        for ln, fid in self.link_frame.items():
            out[ln] = self.data.oMf[fid].homogeneous.copy()
        return out

    def closure(self, q_all):
        """Residual, 6 rows per loop-closing joint: log6 of the cut frames' mismatch."""
        q = self._to_pin(q_all)
        pin.framesForwardKinematics(self.model, self.data, q)
        r = [pin.log6(self.data.oMf[fm].actInv(self.data.oMf[fc])).vector for fm, fc in self.cut_frames]
        return np.concatenate(r) if r else np.zeros(0)

    def closure_jacobian(self, q_all):
        """Exact derivative of ``closure`` w.r.t. all joint coordinates (file order)."""
        q = self._to_pin(q_all)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        rows = []
        for fm, fc in self.cut_frames:
            err = self.data.oMf[fm].actInv(self.data.oMf[fc])
            jm = pin.getFrameJacobian(self.model, self.data, fm, pin.LOCAL)
            jc = pin.getFrameJacobian(self.model, self.data, fc, pin.LOCAL)
            rows.append(pin.Jlog6(err) @ (jc - err.inverse().action @ jm))
        j = np.vstack(rows) if rows else np.zeros((0, self.n))
        return j[:, self.perm]

    def velocity_jacobian(self, q_all):
        """World-frame velocity closure Jacobian: relative spatial twist of the cut frames."""
        q = self._to_pin(q_all)
        pin.computeJointJacobians(self.model, self.data, q)
        pin.updateFramePlacements(self.model, self.data)
        rows = [pin.getFrameJacobian(self.model, self.data, fc, pin.WORLD)
                - pin.getFrameJacobian(self.model, self.data, fm, pin.WORLD)
                for fm, fc in self.cut_frames]
        j = np.vstack(rows) if rows else np.zeros((0, self.n))
        return j[:, self.perm]

    def drift(self, q_all, qd_all):
        """d/dt(J) qd: the relative spatial acceleration of the cut frames at zero qdd."""
        q, v = self._to_pin(q_all), self._to_pin(qd_all)
        pin.forwardKinematics(self.model, self.data, q, v, np.zeros(self.n))
        pin.updateFramePlacements(self.model, self.data)
        r = [(pin.getFrameAcceleration(self.model, self.data, fc, pin.WORLD)
              - pin.getFrameAcceleration(self.model, self.data, fm, pin.WORLD)).vector
             for fm, fc in self.cut_frames]
        return np.concatenate(r) if r else np.zeros(0)

    def velocity_basis(self, q_all):
        """Orthonormal basis V (n, dof) of the feasible joint velocities."""
        v, _ = _null_space(self.velocity_jacobian(q_all))
        return v

    def dof(self, q_all=None):
        return self.velocity_basis(self.initial_positions if q_all is None else q_all).shape[1]

    def solve_positions(self, q_active, q_guess=None, tol=1e-14, max_iter=100):
        """Close the loops with the active coordinates fixed (Gauss-Newton, lstsq steps)."""
        q = np.array(self.initial_positions if q_guess is None else q_guess, dtype=float)
        q[self.ia] = q_active
        r = self.closure(q)
        for _ in range(max_iter):
            if np.linalg.norm(r) < tol:
                break
            j = self.closure_jacobian(q)[:, self.ip]
            step = np.linalg.lstsq(j, -r, rcond=1e-12)[0]
            alpha = 1.0
            while True:
                qn = q.copy()
                qn[self.ip] += alpha * step
                rn = self.closure(qn)
                if np.linalg.norm(rn) < np.linalg.norm(r) or alpha < 1e-4:
                    break
                alpha *= 0.5
            if np.linalg.norm(rn) >= np.linalg.norm(r):
                break
            q, r = qn, rn
        return q

    def _z_from_active(self, v, x, weights):
        va = v[self.ia]
        if weights is None:
            return np.linalg.lstsq(va, x, rcond=None)[0]
        wi = 1.0 / np.asarray(weights, dtype=float)
        a = va.T @ (wi[:, None] * va)
        return np.linalg.solve(a, va.T @ (wi * x))

    def joint_velocities(self, q_all, qd_active, weights=None):
        v = self.velocity_basis(q_all)
        return v @ self._z_from_active(v, np.asarray(qd_active, dtype=float), weights)

    def joint_accelerations(self, q_all, qd_all, qdd_active, weights=None):
        j = self.velocity_jacobian(q_all)
        v, _ = _null_space(j)
        qdd_p = -np.linalg.lstsq(j, self.drift(q_all, qd_all), rcond=1e-10)[0]
        zdd = self._z_from_active(v, np.asarray(qdd_active, dtype=float) - qdd_p[self.ia], weights)
        return qdd_p + v @ zdd

    # ---------------------------------------------------------------- dynamics
    def tree_torques(self, q_all, qd_all, qdd_all):
        """RNEA generalized forces of every joint (zero for loop-closing ones), file order."""
        tau = pin.rnea(self.model, self.data, self._to_pin(q_all), self._to_pin(qd_all),
                       self._to_pin(qdd_all))
        return self._from_pin(tau)

    def active_torques(self, q_all, qd_active, qdd_active, weights=None, return_all=False):
        """Torques of the active joints (file's torque_weights unless ``weights`` given)."""
        w = self.weights if weights is None else np.asarray(weights, dtype=float)
        v = self.velocity_basis(q_all)
        qd = v @ self._z_from_active(v, np.asarray(qd_active, dtype=float), w)
        qdd = self.joint_accelerations(q_all, qd, qdd_active, w)
        tau_tree = self.tree_torques(q_all, qd, qdd)
        va = v[self.ia]
        b = v.T @ tau_tree
        wi = 1.0 / w
        lam = np.linalg.solve(va.T @ (wi[:, None] * va), b)
        tau = wi * (va @ lam)
        if return_all:
            return tau, qd, qdd
        return tau

    def energy(self, q_all, qd_all):
        """Kinetic + potential energy (potential zero at the base origin)."""
        q, v = self._to_pin(q_all), self._to_pin(qd_all)
        ke = pin.computeKineticEnergy(self.model, self.data, q, v)
        pe = pin.computePotentialEnergy(self.model, self.data, q)
        return ke + pe

    # ---------------------------------------------------------------- trajectories
    def follow(self, q_active, qd_active, qdd_active, q_start=None):
        """Positions, velocities, accelerations and torques along a sampled active motion.

        Warm-starts every sample from the previous one (from ``q_start`` or the file's
        initial_positions for the first). Returns (q_all, qd_all, qdd_all, tau) arrays.
        """
        q_active = np.atleast_2d(q_active)
        n_s = q_active.shape[0]
        qa_all, qda_all, qdda_all = (np.empty((n_s, self.n)) for _ in range(3))
        tau = np.empty((n_s, len(self.active)))
        guess = self.initial_positions if q_start is None else q_start
        for k in range(n_s):
            q = self.solve_positions(q_active[k], guess)
            tau[k], qda_all[k], qdda_all[k] = self.active_torques(q, qd_active[k], qdd_active[k],
                                                                  return_all=True)
            qa_all[k] = q
            guess = q
        return qa_all, qda_all, qdda_all, tau
