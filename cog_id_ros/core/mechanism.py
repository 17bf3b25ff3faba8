"""Mechanism: a validated description of links, joints and actuators, ready to solve.

Built from a ROS 2 parameter file (``from_params_file``; README, "Mechanism parameter
file", and docs/mechanism.md for limits and defaults) or from the dotted names rclpy gives a node (``from_parameters``). Everything a user can get
wrong raises MechanismConfigError naming the parameter. At load the mechanism is assembled
near ``initial_positions``, its degrees of freedom are read off the rank of the closure
Jacobian there, and the actuators are checked to determine the motion.
"""
import itertools
import math

import numpy as np

from . import closure
from . import spatial as sp
from .errors import MechanismConfigError
from .kinematics import BASE, JointSpec, KinematicModel
from .params import DEFAULT_NODE_NAME, ParameterReader, load_params_file

MECHANISM_KEYS = ('name', 'gravity', 'base_link', 'links', 'joints', 'active_joints',
                  'initial_positions', 'torque_weights', 'setpoint_tolerance',
                  'max_condition_number', 'closure_tolerance')
LINK_KEYS = ('mass', 'com', 'inertia')
JOINT_KEYS = ('type', 'parent', 'child', 'parent_xyz', 'parent_rpy', 'child_xyz', 'child_rpy',
              'axis')
JOINT_TYPES = ('revolute', 'prismatic')

DEFAULT_SETPOINT_TOLERANCE = 1e-3      # rad or m: larger redundant disagreements are rejected
DEFAULT_MAX_CONDITION_NUMBER = 1e6     # closure Jacobian (passive joints), Frobenius norm
DEFAULT_CLOSURE_TOLERANCE = 1e-10      # m or rad: a loop counts as closed below this residual
RANK_TOLERANCE = 1e-9                  # relative singular value below which A loses rank


class Mechanism:
    """Links, joints and actuators of a (closed-link) mechanism; see docs/mechanism.md."""

    def __init__(self, params):
        reader = ParameterReader(params)
        self.parameters = dict(reader.params)
        self._read_mechanism(reader)
        self._read_links(reader)
        self._read_joints(reader)
        self._reject_unknown(reader)
        self.model = KinematicModel(self.links, self.joint_specs)
        self._assemble()
        self._count_degrees_of_freedom()

    @classmethod
    def from_parameters(cls, params):
        """From a dict of dotted parameter names (as rclpy gives them) or a nested dict."""
        if not isinstance(params, dict):
            raise MechanismConfigError('parameters', f'must be a dict, got {type(params).__name__}')
        return cls(params)

    @classmethod
    def from_params_file(cls, path, node_name=DEFAULT_NODE_NAME):
        """From a ROS 2 parameter file (node entry ``node_name`` or ``/**``)."""
        return cls(load_params_file(path, node_name))

    # --- reading ----------------------------------------------------------------------------

    def _read_mechanism(self, r):
        self.name = r.string('mechanism.name', default='mechanism')
        self.gravity = r.vector('mechanism.gravity', 3, default=(0.0, 0.0, -9.81))
        self.base_link = r.string('mechanism.base_link', default='ground')
        self.links = r.string_list('mechanism.links', required=True)
        self.joints = r.string_list('mechanism.joints', required=True)
        self.active_joints = r.string_list('mechanism.active_joints', required=True)
        if not self.links:
            raise MechanismConfigError('mechanism.links', 'must name at least one moving link')
        if not self.joints:
            raise MechanismConfigError('mechanism.joints', 'must name at least one joint')
        if not self.active_joints:
            raise MechanismConfigError('mechanism.active_joints', 'must name at least one joint')
        if self.base_link in self.links:
            raise MechanismConfigError(
                'mechanism.links', f"the base link '{self.base_link}' must not be listed: it does not move")
        for name in self.active_joints:
            if name not in self.joints:
                raise MechanismConfigError(
                    'mechanism.active_joints', f"'{name}' is not in mechanism.joints")
        n, m = len(self.joints), len(self.active_joints)
        self.initial_positions = r.vector('mechanism.initial_positions', n, default=(0.0,) * n)
        self.torque_weights = r.vector('mechanism.torque_weights', m, default=(1.0,) * m)
        for k, w in enumerate(self.torque_weights):
            if w <= 0.0:
                raise MechanismConfigError(
                    'mechanism.torque_weights', f'must be positive, got {w!r} at index {k}')
        self.setpoint_tolerance = self._positive(r, 'mechanism.setpoint_tolerance',
                                                 DEFAULT_SETPOINT_TOLERANCE)
        self.max_condition_number = self._positive(r, 'mechanism.max_condition_number',
                                                   DEFAULT_MAX_CONDITION_NUMBER)
        self.closure_tolerance = self._positive(r, 'mechanism.closure_tolerance',
                                                DEFAULT_CLOSURE_TOLERANCE)

    @staticmethod
    def _positive(r, name, default):
        value = r.number(name, default=default)
        if value <= 0.0:
            raise MechanismConfigError(name, f'must be positive, got {value!r}')
        return value

    def _read_links(self, r):
        self.link_mass, self.link_com, self.link_inertia = [], [], []
        for link in self.links:
            prefix = f'links.{link}.'
            mass = r.number(prefix + 'mass', required=True)
            if mass < 0.0:
                raise MechanismConfigError(prefix + 'mass', f'must be >= 0, got {mass!r}')
            self.link_mass.append(mass)
            self.link_com.append(r.vector(prefix + 'com', 3, default=(0.0, 0.0, 0.0)))
            self.link_inertia.append(_inertia(r, prefix + 'inertia'))

    def _read_joints(self, r):
        self.joint_types, self.joint_specs = [], []
        known = {name: k for k, name in enumerate(self.links)}
        known[self.base_link] = BASE
        for joint in self.joints:
            prefix = f'joints.{joint}.'
            kind = r.string(prefix + 'type', required=True)
            if kind not in JOINT_TYPES:
                raise MechanismConfigError(
                    prefix + 'type', f"must be 'revolute' or 'prismatic', got {kind!r}")
            ends = []
            for side in ('parent', 'child'):
                link = r.string(prefix + side, required=True)
                if link not in known:
                    raise MechanismConfigError(
                        prefix + side,
                        f"unknown link '{link}' (not in mechanism.links and not the base link "
                        f"'{self.base_link}')")
                ends.append(known[link])
            if ends[0] == ends[1]:
                raise MechanismConfigError(prefix + 'child', 'must differ from the parent link')
            axis = r.vector(prefix + 'axis', 3, default=(0.0, 0.0, 1.0))
            norm = math.sqrt(sum(a * a for a in axis))
            if norm < 1e-12:
                raise MechanismConfigError(prefix + 'axis', f'must not be zero-length, got {list(axis)}')
            self.joint_types.append(kind)
            self.joint_specs.append(JointSpec(
                name=joint, revolute=(kind == 'revolute'), parent=ends[0], child=ends[1],
                parent_xyz=r.vector(prefix + 'parent_xyz', 3, default=(0.0, 0.0, 0.0)),
                parent_rpy=r.vector(prefix + 'parent_rpy', 3, default=(0.0, 0.0, 0.0)),
                child_xyz=r.vector(prefix + 'child_xyz', 3, default=(0.0, 0.0, 0.0)),
                child_rpy=r.vector(prefix + 'child_rpy', 3, default=(0.0, 0.0, 0.0)),
                axis=tuple(a / norm for a in axis)))

    def _reject_unknown(self, r):
        for name in r.unused('mechanism.'):
            raise MechanismConfigError(
                name, f"unknown parameter (mechanism.* takes {', '.join(MECHANISM_KEYS)})")
        for group, names, keys in (('links', self.links, LINK_KEYS),
                                   ('joints', self.joints, JOINT_KEYS)):
            for name in r.unused(group + '.'):
                parts = name.split('.')
                if len(parts) < 3 or parts[1] not in names:
                    raise MechanismConfigError(
                        name, f"unknown {group[:-1]} '{parts[1]}' (not in mechanism.{group})")
                raise MechanismConfigError(
                    name, f"unknown parameter ({group}.{parts[1]}.* takes {', '.join(keys)})")

    # --- analysis at load ------------------------------------------------------------------

    def _assemble(self):
        """Close the loops with the actuators held at their initial positions; failing that
        (e.g. rounded redundant initial positions), let every joint move."""
        held = [self.joints.index(name) for name in self.active_joints]
        q, residual, ok = closure.assemble(self.model, self.initial_positions,
                                           self.closure_tolerance, fixed=held)
        if not ok:
            q, residual, ok = closure.assemble(self.model, self.initial_positions,
                                               self.closure_tolerance)
        if not ok:
            raise MechanismConfigError(
                'mechanism.initial_positions',
                f'the loops cannot be closed near these positions (closure residual '
                f'{residual:.3g} after Newton iterations); check the geometry and the assembly mode')
        self.assembled_positions = tuple(q)

    def _count_degrees_of_freedom(self):
        n = len(self.joints)
        matrix, _ = closure.closure_jacobian_matrix(self.model, self.assembled_positions)
        singular_values = np.linalg.svd(matrix, compute_uv=False) if matrix.size else np.zeros(0)
        scale = max(1.0, singular_values[0]) if singular_values.size else 1.0
        self.closure_rank = int(np.sum(singular_values > RANK_TOLERANCE * scale))
        self.dof = n - self.closure_rank
        self.joint_index = {name: k for k, name in enumerate(self.joints)}
        self.link_index = {name: k for k, name in enumerate(self.links)}
        self.active_index = [self.joint_index[name] for name in self.active_joints]
        m = len(self.active_joints)
        if m < self.dof:
            raise MechanismConfigError(
                'mechanism.active_joints',
                f'{m} active joint(s) for {self.dof} degrees of freedom (closure rank '
                f'{self.closure_rank} of {n} joint coordinates at the assembled initial '
                f'positions): the motion is not determined; add active joints')
        self.primary = self._choose_primary()
        self.primary_joints = [self.active_index[i] for i in self.primary]
        fixed = set(self.primary_joints)
        self.free_joints = [j for j in range(n) if j not in fixed]
        self.inverse_torque_weights = [1.0 / w for w in self.torque_weights]

    def _choose_primary(self):
        """Indices (into active_joints) of ``dof`` actuators whose coordinates determine all
        others best (smallest condition number); the rest of a redundant set are secondary."""
        best, best_cond = None, math.inf
        combos = itertools.combinations(range(len(self.active_index)), self.dof)
        for combo in itertools.islice(combos, 5000):
            fixed = {self.active_index[i] for i in combo}
            free = [j for j in range(len(self.joints)) if j not in fixed]
            sol = closure.evaluate(self.model, list(self.assembled_positions), free, sp.ScalarOps)
            cond = sol.lsq.condition_number()
            if cond < best_cond:
                best, best_cond = combo, cond
        if best is None or not best_cond <= self.max_condition_number:
            raise MechanismConfigError(
                'mechanism.active_joints',
                f'{self.active_joints} do not determine the motion at the assembled initial '
                f'positions (closure Jacobian condition number {best_cond:.3g}): some passive '
                f'joints could move with every actuator held')
        return list(best)

    @property
    def is_redundant(self):
        return len(self.active_joints) > self.dof

    def __repr__(self):
        return (f'Mechanism({self.name!r}: {len(self.links)} links, {len(self.joints)} joints, '
                f'{len(self.model.loops)} loops, {self.dof} DOF, active {self.active_joints})')


def _inertia(r, name):
    values = r.vector(name, default=(0.0,) * 6)
    if len(values) == 6:
        ixx, iyy, izz, ixy, ixz, iyz = values
        matrix = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    elif len(values) == 9:
        matrix = np.array(values).reshape(3, 3)
        if not np.allclose(matrix, matrix.T, rtol=0.0, atol=1e-12 * max(1.0, np.abs(matrix).max())):
            raise MechanismConfigError(name, f'must be symmetric, got {list(values)}')
    else:
        raise MechanismConfigError(
            name, f'must have 6 entries [ixx, iyy, izz, ixy, ixz, iyz], got {len(values)}')
    moments = np.linalg.eigvalsh(matrix)
    tol = 1e-9 * max(1e-12, np.abs(moments).max())
    if moments[0] < -tol:
        raise MechanismConfigError(
            name, f'must be positive semi-definite, got principal moments {moments.tolist()}')
    if moments[0] + moments[1] < moments[2] - tol:
        raise MechanismConfigError(
            name, f'violates the triangle inequality of principal moments '
                  f'({moments[0]:.6g} + {moments[1]:.6g} < {moments[2]:.6g})')
    return tuple(float(x) for x in matrix.ravel())
