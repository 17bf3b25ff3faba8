"""Mechanism: a validated description of links, joints and actuators, ready to solve.

Built from a ROS 2 parameter file (``from_params_file``; README, "Mechanism parameter
file", and docs/mechanism.md for the limits and defaults) or from the dotted names rclpy
gives a node (``from_parameters``). Everything a user can get wrong raises
MechanismConfigError naming the parameter. At load the mechanism is assembled near
``initial_positions`` (actuators held), its degrees of freedom are read off the rank of the
closure Jacobian there, and the actuators are checked to determine the motion. What the
assembly had to change is reported in ``assembly_warnings`` (and as AssemblyWarning).

Sizes are checked first (MAX_JOINTS and friends), before anything whose cost grows faster
than the size of the file; values are checked against documented bounds (MAX_LENGTH and
friends) so that finite, moderate setpoints never produce an infinite torque.
"""
import itertools
import math
import os
import re
import warnings

import numpy as np

from . import closure, spherical_chains
from . import kinematics as kin
from . import spatial as sp
from .errors import MechanismConfigError
from .kinematics import BASE, CLOSURE_TYPES, COORDINATE_TYPES, JointSpec, KinematicModel
from .parameters import ParameterReader
from .pipeline import massless

MECHANISM_KEYS = ('name', 'gravity', 'base_link', 'links', 'joints', 'active_joints',
                  'initial_positions', 'torque_weights', 'setpoint_tolerance',
                  'max_condition_number', 'closure_tolerance')
LINK_KEYS = ('mass', 'com', 'inertia')
JOINT_KEYS = ('type', 'parent', 'child', 'parent_xyz', 'parent_rpy', 'child_xyz', 'child_rpy',
              'axis', 'axis2', 'lower', 'upper', 'effort')
JOINT_TYPES = COORDINATE_TYPES + CLOSURE_TYPES
#: how far from perpendicular (cosine) a universal joint's two axes may be written
AXES_PERPENDICULAR = 1e-6

DEFAULT_SETPOINT_TOLERANCE = 1e-3      # rad or m: larger redundant disagreements are rejected
DEFAULT_MAX_CONDITION_NUMBER = 1e6     # closure Jacobian (passive joints), Frobenius norm
DEFAULT_CLOSURE_TOLERANCE = 1e-10      # m or rad: a loop counts as closed below this residual
RANK_TOLERANCE = 1e-9                  # relative singular value below which A loses rank

# --- bounds on values (docs/mechanism.md): a mechanism within them, driven by finite
# moderate setpoints, never produces an infinite torque
MAX_LENGTH = 1e6            # m: every entry of com, parent_xyz, child_xyz
MAX_COORDINATE = 1e6        # rad or m: initial_positions, parent_rpy, child_rpy
MAX_MASS = 1e9              # kg
MAX_INERTIA = 1e12          # kg m^2: every inertia entry
MAX_GRAVITY = 1e4           # m/s^2: length of the gravity vector
MIN_TORQUE_WEIGHT, MAX_TORQUE_WEIGHT = 1e-9, 1e9
#: tightest closure_tolerance: residuals of a closed loop in doubles are ~1e-16 of its size,
#: so a tolerance below this would make no pose count as closed
MIN_CLOSURE_TOLERANCE = 1e-14
MAX_CLOSURE_TOLERANCE = 1e-3          # m or rad: a looser "closed" loop gives wrong torques
MAX_CONDITION_NUMBER_LIMIT = 1e15     # beyond this double precision keeps no digit

# --- size limits (docs/mechanism.md), checked before anything expensive. The solver's work
# at load grows with links x active joints (the COG Jacobians G_i, traced into straight-line
# code) and with the cube of the loop count (dense QR of the closure Jacobian); these keep
# loading within a few seconds and a few hundred MB.
MAX_JOINTS = 200
MAX_LINKS = 200
MAX_LOOPS = 40
MAX_ACTIVE_JOINTS = 100
MAX_JACOBIAN_COLUMNS = 5000   # links x active joints

#: names of links and joints become components of ROS 2 parameter names
#: (``links.<link>.mass``): letters, digits and '_', not starting with a digit
NAME_PATTERN = re.compile(r'[A-Za-z_][A-Za-z0-9_]*\Z')

#: assembly that moves a passive joint further than this from initial_positions is reported
#: (rad for revolute joints; for prismatic ones this fraction of the mechanism's scale)
FAR_ANGLE = 0.1
FAR_FRACTION = 0.1


class AssemblyWarning(UserWarning):
    """Assembly at load had to move joints away from ``initial_positions``: the mechanism
    loaded, but its geometry or initial positions are probably not what was meant."""


class Mechanism:
    """Links, joints and actuators of a (closed-link) mechanism; see docs/mechanism.md."""

    def __init__(self, params, _chains=()):
        reader = ParameterReader(params)
        self.parameters = dict(reader.params)
        self.assembly_warnings = []
        self._deferred_error = None
        self._moved_actuators = None
        # made by another Mechanism as its solver form: the spherical joints that stand for
        # its chains of three revolutes (spherical_chains.py)
        self._stands_for = list(_chains)
        self._read_mechanism(reader)
        self._read_links(reader)
        self._read_joints(reader)
        self._read_positions(reader)
        self._reject_unknown(reader)
        self.model = KinematicModel(self.links, self.joint_specs, self.closure_specs)
        #: the solver's coordinates: the joints (mechanism.joints), then the hidden ones of
        #: spherical and universal joints in the spanning tree (kinematics.py)
        self.n_coordinates = self.model.n_coordinates
        #: per coordinate: 'revolute', 'prismatic' or 'quaternion'
        self.coordinate_types = list(self.model.coordinate_kinds)
        try:
            self._assemble()
            self._count_degrees_of_freedom()
        except (np.linalg.LinAlgError, ArithmeticError, FloatingPointError) as exc:
            raise MechanismConfigError(
                'mechanism.initial_positions',
                f'the mechanism could not be analysed at these positions ({exc}); check the '
                f'geometry and initial_positions') from None
        self._solver_form()
        # what the kernels are made of stays what it was read as: read-only from here on
        self._frozen = True

    def __setattr__(self, name, value):
        if getattr(self, '_frozen', False):
            raise AttributeError(
                f'Mechanism.{name} is read-only: solvers and their compiled kernels are made '
                f'from the mechanism as it was read. Change the parameters and build a new '
                f'one with Mechanism.from_parameters')
        object.__setattr__(self, name, value)

    @classmethod
    def from_parameters(cls, params: dict, base_dir: 'str | None' = None) -> 'Mechanism':
        """From a dict of dotted parameter names (as rclpy gives them) or a nested dict.

        A URDF form (``robot_description`` or ``mechanism.urdf_file`` with loop closures,
        docs/urdf.md) is first turned into the native form by :mod:`cog_id_ros.urdf_input`
        (file formats live outside the core); ``base_dir`` is where a relative
        ``mechanism.urdf_file`` is looked for (default: the working directory)."""
        if not isinstance(params, dict):
            raise MechanismConfigError('parameters',
                                       f'must be a dict, got {type(params).__name__}')
        flat = ParameterReader(params).params
        if 'robot_description' in flat or 'mechanism.urdf_file' in flat:
            from .. import urdf_input
            return cls(urdf_input.native_parameters(flat, base_dir))
        return cls(params)

    @classmethod
    def from_params_file(cls, path: 'str | os.PathLike', node_name: str = 'cog_id_node'
                         ) -> 'Mechanism':
        """From a ROS 2 parameter file (node entry ``node_name`` or ``/**``).

        The file is read by :mod:`cog_id_ros.params_file` (the ROS conventions live outside
        the core); ``node_name`` is the node's name, ``cog_id_node`` (a test checks it is
        params_file.DEFAULT_NODE_NAME). A relative ``mechanism.urdf_file`` is relative to
        the file's directory."""
        from ..params_file import load_params_file
        return cls.from_parameters(load_params_file(path, node_name),
                                   base_dir=os.path.dirname(os.path.abspath(path)))

    # --- reading ----------------------------------------------------------------------------

    def _read_mechanism(self, r):
        self.name = r.string('mechanism.name', default='mechanism')
        self.gravity = r.vector('mechanism.gravity', 3, default=(0.0, 0.0, -9.81))
        self.base_link = r.string('mechanism.base_link', default='ground')
        self.links = r.string_list('mechanism.links', required=True)
        self.declared_joints = r.string_list('mechanism.joints', required=True)
        self.active_joints = r.string_list('mechanism.active_joints', required=True)
        _check_sizes(self.links, self.declared_joints, self.active_joints)
        _check_names('mechanism.links', 'link', self.links)
        _check_names('mechanism.joints', 'joint', self.declared_joints)
        if not self.links:
            raise MechanismConfigError('mechanism.links', 'must name at least one moving link')
        if not self.declared_joints:
            raise MechanismConfigError('mechanism.joints', 'must name at least one joint')
        if not self.active_joints:
            raise MechanismConfigError('mechanism.active_joints', 'must name at least one joint')
        if self.base_link in self.links:
            raise MechanismConfigError(
                'mechanism.links',
                f"the base link '{self.base_link}' must not be listed: it does not move")
        for name in self.active_joints:
            if name not in self.declared_joints:
                raise MechanismConfigError(
                    'mechanism.active_joints', f"'{name}' is not in mechanism.joints")
        gravity_norm = math.hypot(*self.gravity)
        if gravity_norm > MAX_GRAVITY:
            raise MechanismConfigError(
                'mechanism.gravity', f'must be at most {MAX_GRAVITY:g} m/s^2 long, got '
                                     f'{list(self.gravity)} ({gravity_norm:.6g} m/s^2)')
        m = len(self.active_joints)
        self.torque_weights = r.vector('mechanism.torque_weights', m, default=(1.0,) * m)
        for k, w in enumerate(self.torque_weights):
            if w <= 0.0:
                raise MechanismConfigError(
                    'mechanism.torque_weights', f'must be positive, got {w!r} at index {k}')
            if not MIN_TORQUE_WEIGHT <= w <= MAX_TORQUE_WEIGHT:
                raise MechanismConfigError(
                    'mechanism.torque_weights',
                    f'must lie between {MIN_TORQUE_WEIGHT:g} and {MAX_TORQUE_WEIGHT:g}, got '
                    f'{w!r} at index {k} (only their ratios matter: scale them)')
        self.setpoint_tolerance = self._positive(r, 'mechanism.setpoint_tolerance',
                                                 DEFAULT_SETPOINT_TOLERANCE)
        self.max_condition_number = self._positive(r, 'mechanism.max_condition_number',
                                                   DEFAULT_MAX_CONDITION_NUMBER,
                                                   low=1.0, high=MAX_CONDITION_NUMBER_LIMIT)
        self.closure_tolerance = self._positive(r, 'mechanism.closure_tolerance',
                                                DEFAULT_CLOSURE_TOLERANCE,
                                                low=MIN_CLOSURE_TOLERANCE,
                                                high=MAX_CLOSURE_TOLERANCE)

    @staticmethod
    def _positive(r, name, default, low=None, high=None):
        value = r.number(name, default=default)
        if value <= 0.0:
            raise MechanismConfigError(name, f'must be positive, got {value!r}')
        if low is not None and value < low:
            raise MechanismConfigError(name, f'must be at least {low:g}, got {value!r}')
        if high is not None and value > high:
            raise MechanismConfigError(name, f'must be at most {high:g}, got {value!r}')
        return value

    def _read_links(self, r):
        self.link_mass, self.link_com, self.link_inertia = [], [], []
        for link in self.links:
            prefix = f'links.{link}.'
            mass = r.number(prefix + 'mass', required=True)
            if mass < 0.0:
                raise MechanismConfigError(prefix + 'mass', f'must be >= 0, got {mass!r}')
            if mass > MAX_MASS:
                raise MechanismConfigError(
                    prefix + 'mass', f'must be at most {MAX_MASS:g} kg, got {mass!r}')
            self.link_mass.append(mass)
            self.link_com.append(bounded(
                prefix + 'com', r.vector(prefix + 'com', 3, default=(0.0, 0.0, 0.0)),
                MAX_LENGTH, 'm'))
            self.link_inertia.append(_inertia(r, prefix + 'inertia'))

    def _read_joints(self, r):
        """Every joint of mechanism.joints: those with a coordinate (revolute, prismatic:
        ``joints``, ``joint_specs``) and those without one of their own (spherical,
        universal, fixed: ``closure_joints``, ``closure_specs``)."""
        self.joint_types, self.joint_specs, self.closure_specs = [], [], []
        self.position_limits, self.joint_efforts = [], []
        known = {name: k for k, name in enumerate(self.links)}
        known[self.base_link] = BASE
        for joint in self.declared_joints:
            prefix = f'joints.{joint}.'
            kind = r.string(prefix + 'type', required=True)
            if kind not in JOINT_TYPES:
                raise MechanismConfigError(
                    prefix + 'type', f"must be one of {', '.join(JOINT_TYPES)}, got {kind!r}")
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
            axis = axis2 = (0.0, 0.0, 1.0)
            if kind in ('revolute', 'prismatic', 'universal'):
                axis = _unit_axis(r, prefix + 'axis', (0.0, 0.0, 1.0))
            if kind == 'universal':
                axis2 = _unit_axis(r, prefix + 'axis2', None)
                if abs(sum(a * b for a, b in zip(axis, axis2))) > AXES_PERPENDICULAR:
                    raise MechanismConfigError(
                        prefix + 'axis2',
                        f'must be perpendicular to axis (a universal joint keeps its two axes '
                        f'perpendicular; they are written in the parent and child attachment '
                        f'frames, which coincide at rest), got axis {list(axis)} and axis2 '
                        f'{list(axis2)}')
            offsets = {}
            for key, bound, unit in (('parent_xyz', MAX_LENGTH, 'm'),
                                     ('parent_rpy', MAX_COORDINATE, 'rad'),
                                     ('child_xyz', MAX_LENGTH, 'm'),
                                     ('child_rpy', MAX_COORDINATE, 'rad')):
                value = r.vector(prefix + key, 3, default=(0.0, 0.0, 0.0))
                offsets[key] = bounded(prefix + key, value, bound, unit)
            spec = JointSpec(name=joint, revolute=(kind == 'revolute'), parent=ends[0],
                             child=ends[1], axis=axis, kind=kind,
                             axis2=axis2 if kind == 'universal' else (), **offsets)
            if kind in CLOSURE_TYPES:
                self.closure_specs.append(spec)
                continue
            self.joint_types.append(kind)
            self.joint_specs.append(spec)
            lower, upper, effort = (r.number(prefix + key) for key in ('lower', 'upper',
                                                                        'effort'))
            lower = -math.inf if lower is None else lower
            upper = math.inf if upper is None else upper
            if not lower < upper:
                raise MechanismConfigError(prefix + 'upper',
                                           f'must be above lower ({lower!r}), got {upper!r}')
            self.position_limits.append((lower, upper))
            effort = math.inf if effort is None else effort
            if not effort > 0.0:
                raise MechanismConfigError(prefix + 'effort',
                                           f'must be positive (N m or N), got {effort!r}')
            self.joint_efforts.append(effort)
        self.joints = [spec.name for spec in self.joint_specs]
        self.closure_joints = [spec.name for spec in self.closure_specs]

    def _read_positions(self, r):
        """initial_positions (one per revolute or prismatic joint); the actuators, which
        must have a coordinate, and their effort limits."""
        for name in self.active_joints:
            if name in self.closure_joints:
                kind = self.closure_specs[self.closure_joints.index(name)].kind
                raise MechanismConfigError(
                    'mechanism.active_joints',
                    f"'{name}' is a {kind} joint: spherical, universal and fixed joints are "
                    f'passive (only revolute and prismatic joints can be driven)')
        n = len(self.joints)
        values = r.vector('mechanism.initial_positions', None, default=(0.0,) * n)
        if len(values) != n:
            extra = (f' ({len(self.closure_joints)} of mechanism.joints are spherical, '
                     f'universal or fixed and have none)' if self.closure_joints else '')
            raise MechanismConfigError(
                'mechanism.initial_positions',
                f'must have {n} entries, one per revolute or prismatic joint of '
                f'mechanism.joints{extra}, got {len(values)}')
        self.initial_positions = bounded('mechanism.initial_positions', values,
                                         MAX_COORDINATE, 'rad or m')
        index = {name: k for k, name in enumerate(self.joints)}
        #: per active joint: (lower, upper) position limits and the effort limit (inf: none)
        self.active_position_limits = [self.position_limits[index[a]]
                                       for a in self.active_joints]
        self.effort_limits = [self.joint_efforts[index[a]] for a in self.active_joints]
        #: (index into active_joints, lower, upper) of every actuator with a position limit
        self.limited_actuators = [(a, lo, hi) for a, (lo, hi) in
                                  enumerate(self.active_position_limits)
                                  if lo > -math.inf or hi < math.inf]

    def _reject_unknown(self, r):
        for name in r.unused('mechanism.'):
            raise MechanismConfigError(
                name, f"unknown parameter (mechanism.* takes {', '.join(MECHANISM_KEYS)})")
        kinds = {spec.name: spec.kind for spec in self.joint_specs + self.closure_specs}
        for group, names, keys in (('links', self.links, LINK_KEYS),
                                   ('joints', self.declared_joints, JOINT_KEYS)):
            for name in r.unused(group + '.'):
                parts = name.split('.')
                if len(parts) < 3 or parts[1] not in names:
                    raise MechanismConfigError(
                        name, f"unknown {group[:-1]} '{parts[1]}' (not in mechanism.{group})")
                kind = kinds.get(parts[1]) if group == 'joints' else None
                why = None
                if kind in CLOSURE_TYPES and parts[2] in ('lower', 'upper', 'effort'):
                    why = 'has no coordinate, so no position or effort limits'
                elif kind in ('spherical', 'fixed') and parts[2] in ('axis', 'axis2'):
                    why = 'has no axis'
                elif kind in COORDINATE_TYPES and parts[2] == 'axis2':
                    why = 'has one axis (axis2 is the second axis of a universal joint)'
                if why:
                    raise MechanismConfigError(name, f'not a parameter of a {kind} joint: '
                                                     f'a {kind} joint {why}')
                raise MechanismConfigError(
                    name, f"unknown parameter ({group}.{parts[1]}.* takes {', '.join(keys)})")

    # --- analysis at load ------------------------------------------------------------------

    def _assemble(self):
        """Close the loops with the actuators held at their initial positions; failing that
        (e.g. rounded redundant initial positions), let every joint move, but refuse a move
        of an actuator by more than setpoint_tolerance. Far moves are reported."""
        self.joint_index = {name: k for k, name in enumerate(self.joints)}
        self.link_index = {name: k for k, name in enumerate(self.links)}
        self.active_index = [self.joint_index[name] for name in self.active_joints]
        start = self._started(self.model.start(self.initial_positions))
        q, residual, ok = closure.assemble(self.model, start, self.closure_tolerance,
                                           fixed=self.active_index)
        if not ok:
            held_q, held_residual = q, residual
            q, residual, ok = closure.assemble(self.model, start, self.closure_tolerance)
            if not ok:
                raise MechanismConfigError(
                    'mechanism.initial_positions',
                    f'the loops cannot be closed near these positions, not even by moving '
                    f'the actuators (closure residual {held_residual:.3g} with the actuators '
                    f'held at initial_positions); {self._check_loops_hint(held_q)}')
            moved = [(a, j) for a, j in enumerate(self.active_index)
                     if abs(q[j] - start[j]) > self.setpoint_tolerance]
            if moved:
                what = '; '.join(f"active joint '{self.joints[j]}' from {start[j]:.6g} to "
                                 f'{q[j]:.6g} (by {abs(q[j] - start[j]):.3g})' for _, j in moved)
                self._moved_actuators = what
                # raised after the degrees of freedom are counted: a rigid mechanism (whose
                # actuators cannot be held anywhere but one pose) is the clearer message
                self._deferred_error = MechanismConfigError(
                    'mechanism.initial_positions',
                    f'the loops cannot be closed with the actuators held at initial_positions '
                    f'(closure residual {held_residual:.3g}); they close only by moving {what}, '
                    f'more than mechanism.setpoint_tolerance ({self.setpoint_tolerance:g}); '
                    f'{self._check_loops_hint(held_q)}')
                self._assembled(q)
                return
            for j in self.active_index:
                if q[j] != start[j]:
                    self._note(f"assembly moved active joint '{self.joints[j]}' from "
                               f'{start[j]:.9g} to {q[j]:.9g} (by {abs(q[j] - start[j]):.3g}, '
                               f'within mechanism.setpoint_tolerance) to close the loops: the '
                               f"actuators' initial_positions disagree slightly with the loop "
                               f'closure')
        self._assembled(q)
        self._report_far_moves(start, q)

    def _started(self, start):
        """The start of assembly, with the quaternion of every tree spherical joint that
        stands for a chain of three revolutes at the chain's initial angles."""
        chains = {chain.name: chain for chain in self._stands_for}
        for e in self.model.edges:
            chain = chains.get(e.name)
            if e.kind != 'ball' or chain is None:
                continue
            turn = spherical_chains.initial_turn(chain)
            if e.child != self.link_index.get(chain.child, BASE):   # reached from C's side
                turn = sp.transpose(turn)
            for c, value in zip(e.coords, sp.rotation_quaternion(turn)):
                start[c] = value
        return start

    def _solver_form(self):
        """What the solver solves (``solver_mechanism``): this mechanism, or, where three
        revolute joints through massless links are one spherical joint (spherical_chains.py,
        ``spherical_chains``), the same mechanism with those chains as spherical joints; and
        ``joints_at``'s way back to the joints as written."""
        self.spherical_chains, self.solver_mechanism, self._readout = [], self, None
        if self._stands_for:
            return
        chains = self._chains()
        if not chains:
            return
        params = spherical_chains.solver_parameters(self.parameters, chains, self.joints,
                                                    self.assembled_positions)
        try:
            with warnings.catch_warnings():
                warnings.simplefilter('ignore', AssemblyWarning)
                solver = Mechanism(params, _chains=chains)
        except MechanismConfigError:
            return                      # (not seen: the joints as written are solved)
        if solver.dof != self.dof:
            return
        self.spherical_chains, self.solver_mechanism = chains, solver
        self._readout = spherical_chains.JointReadout(self, solver)

    def joints_at(self, coordinates, rates=None):
        """(positions, rates or None) of ``joints`` from the coordinates of
        ``solver_mechanism`` (and their rates): (n,) -> (len(joints),), (N, n) -> (N,
        len(joints)); the chains' angles read back from the pose."""
        if self._readout is None:
            q = np.asarray(coordinates, dtype=float)[..., :len(self.joints)]
            return q, None if rates is None else \
                np.asarray(rates, dtype=float)[..., :len(self.joints)]
        return self._readout(coordinates, rates)

    def coordinates_as_written(self, coordinates):
        """Every coordinate of ``model`` (the joints, then its hidden ones) at the pose of
        the solver form's ``coordinates``: (n,) or (N, n) -> (model.n_coordinates,) or (N,
        ...). Hidden ones of this model are closed onto the joints' positions (load-time
        Newton, per sample): for inspection, not for control rate."""
        if self._readout is None:
            return np.asarray(coordinates, dtype=float)
        positions = self.joints_at(coordinates)[0]
        if self.model.n_coordinates == len(self.joints):
            return positions
        rows = [closure.assemble(self.model, self.model.start(row.tolist()),
                                 self.closure_tolerance, fixed=range(len(self.joints)))[0]
                for row in np.atleast_2d(positions)]
        return np.array(rows[0] if positions.ndim == 1 else rows)

    def _assembled(self, q):
        #: every coordinate of the solver at the assembled pose (hidden ones included)
        self.assembled_coordinates = tuple(q)
        self.assembled_positions = tuple(q[:len(self.joints)])

    def _loops_of(self, q=None):
        """(loop-closing joint, joints of its loop, residual at q or None) of every loop."""
        residuals = [None] * len(self.model.loops)
        if q is not None:
            frames = kin.forward_kinematics(self.model, list(q), sp.ScalarOps)
            states = closure.loop_closure(self.model, frames, list(q), sp.ScalarOps)
            residuals = [max(map(abs, st.residual)) for st in states]
        out = []
        names = self.model.coordinate_joints
        for lp, res in zip(self.model.loops, residuals):
            joints = list(dict.fromkeys(names[j] for j in sorted(set(kin.loop_columns(lp)))))
            out.append((lp.name, joints + ([lp.name] if lp.joint is None else []), res))
        return out

    def _check_loops_hint(self, q, joints=None):
        """What to check: the joints of the loops that stay open at q, or else of the loops
        through any of ``joints`` (indices), or else of all loops."""
        loops = self._loops_of(q)
        names = {self.joints[j] for j in joints or ()}
        bad = ([lp for lp in loops if lp[2] is not None and lp[2] >= self.closure_tolerance]
               or [lp for lp in loops if names & set(lp[1])] or loops)
        which = '; '.join(f"loop closed by '{name}' (joints {', '.join(js)}"
                          + (f', residual {res:.3g})' if res is not None else ')')
                          for name, js, res in bad[:5])
        more = f' and {len(bad) - 5} more loops' if len(bad) > 5 else ''
        return (f'check the geometry (parent_xyz, child_xyz, *_rpy and axis) of the joints of '
                f'{which}{more}, and initial_positions (the assembly mode)')

    def far_move_limit(self, j):
        """(limit, unit): a move of joint j at assembly beyond this is reported as far
        (FAR_ANGLE rad; for a prismatic joint FAR_FRACTION of the mechanism's scale, its
        largest attachment offset)."""
        if self.joint_specs[j].revolute:
            return FAR_ANGLE, 'rad'
        return FAR_FRACTION * self._attachment_scale(), 'm'

    def _attachment_scale(self):
        """The largest attachment offset of a joint (m; 1.0 if there is none)."""
        scale = max([math.hypot(*spec.parent_xyz) for spec in self.joint_specs]
                    + [math.hypot(*spec.child_xyz) for spec in self.joint_specs] + [0.0])
        return scale if scale > 0.0 else 1.0

    def _report_far_moves(self, start, q):
        """A note for every passive joint the assembly moved far from initial_positions."""
        held = set(self.active_index)
        far, moved = [], []
        for j, (a, b) in enumerate(zip(start[:len(self.joints)], q)):
            if j in held:
                continue
            limit, unit = self.far_move_limit(j)
            if abs(b - a) > limit:
                far.append(f"'{self.joints[j]}' from {a:.6g} to {b:.6g} {unit}")
                moved.append(j)
        if far:
            self._note(
                f'closing the loops with the actuators held at initial_positions moved passive '
                f'joint(s) {", ".join(far)} (more than {FAR_ANGLE:g} rad or {FAR_FRACTION:.0%} of '
                f'the mechanism scale {self._attachment_scale():.3g} m): the geometry (xyz, '
                f'rpy, axis) or '
                f'initial_positions are probably not what was meant; '
                f'{self._check_loops_hint(None, moved)}')

    def _note(self, text):
        self.assembly_warnings.append(text)
        warnings.warn(f'{self.name}: {text}', AssemblyWarning, stacklevel=4)

    def _count_degrees_of_freedom(self):
        n = self.n_coordinates
        matrix, _ = closure.closure_jacobian_matrix(self.model, self.assembled_coordinates)
        singular_values = np.linalg.svd(matrix, compute_uv=False) if matrix.size else np.zeros(0)
        self.closure_rank = _rank(singular_values)
        self.dof = n - self.closure_rank
        m = len(self.active_joints)
        if self.dof == 0:
            raise MechanismConfigError(
                'mechanism.joints',
                f'the mechanism is rigid (locked) at the assembled initial positions: 0 degrees '
                f'of freedom (closure rank {self.closure_rank} of {n} joint coordinates), so '
                f'no joint can move and there is nothing to drive. Typical causes: a joint of '
                f'the wrong type (prismatic where revolute was meant) or axis (in a planar '
                f'loop every revolute axis is normal to the plane, every prismatic one in it), '
                f'or a loop with too few joints; {self._check_loops_hint(None)}'
                + (f' (the loops closed only after moving {self._moved_actuators} away from '
                   f'initial_positions)' if self._moved_actuators else ''))
        if self._deferred_error is not None:
            raise self._deferred_error
        if m < self.dof:
            hidden = n - len(self.joints)
            moving = self._free_with_actuators_held(matrix)
            raise MechanismConfigError(
                'mechanism.active_joints',
                f'{m} active joint(s) for {self.dof} degrees of freedom (closure rank '
                f'{self.closure_rank} of {n} coordinates'
                + (f', {hidden} of them hidden: the spherical and universal joints in the '
                   f'spanning tree' if hidden else '')
                + ', at the assembled initial positions): the motion is not determined'
                + (f": with every actuator held, {', '.join(moving)} can still move" if moving
                   else '')
                + '; add active (revolute or prismatic) joints, or remove the idle freedom: a '
                  'link between two spherical joints (a rod with a ball at each end) spins '
                  'about the line through their centres, so write one of them as `type: '
                  'universal`; or, if the mechanism has fewer freedoms than that, it is at a '
                  'singular pose there (e.g. three revolute joints written for a spherical '
                  'one, with the middle one at +-pi/2: gimbal lock; write it as `type: '
                  'spherical`, or change initial_positions)')
        self.primary = self._choose_primary(matrix)
        self.primary_joints = [self.active_index[i] for i in self.primary]
        #: (index into active_joints, joint index) of each primary actuator
        self.primary_pairs = list(zip(self.primary, self.primary_joints))
        fixed = set(self.primary_joints)
        self.free_joints = [j for j in range(n) if j not in fixed]
        self.inverse_torque_weights = [1.0 / w for w in self.torque_weights]

    def _free_with_actuators_held(self, matrix):
        """Names of the joints that can still move with every actuator held: those whose
        coordinates the null space of the closure Jacobian's other columns moves."""
        held = set(self.active_index)
        free = [j for j in range(self.n_coordinates) if j not in held]
        if not free or not matrix.size:
            return []
        _, values, vt = np.linalg.svd(matrix[:, free])
        null = vt[_rank(values):]
        if not null.size:
            return []
        names = self.model.coordinate_joints
        return list(dict.fromkeys(names[free[k]] for k in
                                  np.flatnonzero(np.abs(null).max(axis=0) > 1e-6)))

    def _choose_primary(self, matrix):
        """Indices (into active_joints) of ``dof`` actuators whose coordinates determine all
        others best (smallest condition number); the rest of a redundant set are secondary.

        ``matrix`` is the closure Jacobian at the assembled positions; the condition number
        of its free columns is the Frobenius one the solver uses (lane_linalg), from their
        singular values: ||A_f||_F ||A_f^+||_F."""
        best, best_cond = None, math.inf
        n = self.n_coordinates
        combos = itertools.combinations(range(len(self.active_index)), self.dof)
        for combo in itertools.islice(combos, 5000):
            fixed = {self.active_index[i] for i in combo}
            free = [j for j in range(n) if j not in fixed]
            cond = _condition_number(matrix[:, free])
            if cond < best_cond * (1.0 - 1e-9):    # ties: the first combination
                best, best_cond = combo, cond
        if best is None or not best_cond <= self.max_condition_number:
            hint = self._gimbal_lock_hint()
            if self.assembly_warnings and not hint:
                hint = ('; the assembly also had to move joints far from initial_positions ('
                        'see assembly_warnings): most likely the geometry (xyz, rpy, axis) or '
                        'initial_positions are wrong rather than the choice of actuators')
            raise MechanismConfigError(
                'mechanism.active_joints',
                f'{self.active_joints} do not determine the motion at the assembled initial '
                f'positions (closure Jacobian condition number {best_cond:.3g}): some passive '
                f'joints could move with every actuator held{hint}')
        return list(best)

    def _chains(self, near_lock=False):
        """spherical_chains.find_chains of this mechanism at its assembled pose."""
        return spherical_chains.find_chains(
            self.links, self.base_link,
            [massless(mass, inertia) for mass, inertia in zip(self.link_mass, self.link_inertia)],
            self.joint_specs, self.closure_specs, set(self.active_joints),
            self.assembled_positions, max(1.0, self._attachment_scale()), near_lock)

    def _gimbal_lock_hint(self):
        """What to do where three revolute joints through massless links (a ball joint as
        written, spherical_chains.py) are near their gimbal lock at the assembled pose."""
        chains = [chain for chain in self._chains(near_lock=True)
                  if chain.lock_distance < 0.1]
        if not chains:
            return ''
        return ('; ' + '; '.join(', '.join(c.joints) for c in chains) +
                f" {'are' if len(chains) == 1 else 'are each'} three revolute joints through "
                f'massless links at or near their gimbal lock (first and last axes '
                f'{math.degrees(math.asin(min(1.0, min(c.lock_distance for c in chains)))):.2g} '
                f'degrees from parallel): write such a ball joint as one `type: spherical` '
                f'joint, which has no lock, or give initial_positions away from it')

    @property
    def is_redundant(self):
        return len(self.active_joints) > self.dof

    def __repr__(self):
        return (f'Mechanism({self.name!r}: {len(self.links)} links, {len(self.joints)} joints, '
                f'{len(self.model.loops)} loops, {self.dof} DOF, active {self.active_joints})')


def _inertia(r, name):
    values = r.vector(name, default=(0.0,) * 6)
    if len(values) not in (6, 9):
        raise MechanismConfigError(
            name, f'must have 6 entries [ixx, iyy, izz, ixy, ixz, iyz], got {len(values)}')
    problem = inertia_problem(values)
    if problem:
        raise MechanismConfigError(name, problem)
    return tuple(float(x) for x in _inertia_matrix(values).ravel())


def _inertia_matrix(values):
    if len(values) == 6:
        ixx, iyy, izz, ixy, ixz, iyz = values
        return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    return np.array(values).reshape(3, 3)


def inertia_problem(values):
    """What makes ``values`` (6 entries [ixx, iyy, izz, ixy, ixz, iyz], or 9 row by row,
    finite) no rigid body's inertia, as a message, or None. One test for the native
    ``links.<l>.inertia`` and for the URDF's ``<inertia>`` (urdf_input.py), so that both
    accept the same tensors."""
    matrix = _inertia_matrix(values)
    largest = float(np.abs(matrix).max())
    if largest > MAX_INERTIA:      # first: the checks below would overflow on huge entries
        return f'entries must lie within +-{MAX_INERTIA:g} kg m^2, got {largest!r}'
    if not np.allclose(matrix, matrix.T, rtol=0.0, atol=1e-12 * max(1.0, largest)):
        return f'must be symmetric, got {list(values)}'
    moments = np.linalg.eigvalsh(matrix)
    tol = 1e-9 * max(1e-12, np.abs(moments).max())
    if moments[0] < -tol:
        return f'must be positive semi-definite, got principal moments {moments.tolist()}'
    if moments[0] + moments[1] < moments[2] - tol:
        return (f'violates the triangle inequality of principal moments '
                f'({moments[0]:.6g} + {moments[1]:.6g} < {moments[2]:.6g})')
    return None


def _unit_axis(r, name, default):
    """A joint axis as a unit vector; MechanismConfigError for a missing (``default`` None)
    or zero-length one."""
    axis = r.vector(name, 3, default=default, required=default is None)
    norm = math.hypot(*axis)     # no overflow near 1e308, no underflow near 1e-308
    if not norm > 0.0:
        raise MechanismConfigError(name, f'must not be zero-length, got {list(axis)}')
    return tuple(a / norm for a in axis)


def _rank(singular_values):
    """The rank that singular values (descending) give: those above RANK_TOLERANCE times
    the largest (or times 1, if that is smaller)."""
    scale = max(1.0, singular_values[0]) if singular_values.size else 1.0
    return int(np.sum(singular_values > RANK_TOLERANCE * scale))


def _condition_number(a):
    """||A||_F ||A^+||_F of a matrix with at least as many rows as columns (inf if the
    columns are dependent); 1.0 for no columns, like QRLeastSquares.condition_number."""
    rows, cols = a.shape
    if cols == 0:
        return 1.0
    if rows < cols:
        return math.inf
    s = np.linalg.svd(a, compute_uv=False)
    if not s[-1] > 0.0:
        return math.inf
    return float(math.sqrt(float(np.sum(s * s))) * math.sqrt(float(np.sum(1.0 / (s * s)))))


def bounded(name, values, bound, unit):
    """values unchanged, or MechanismConfigError if an entry exceeds +-bound. Also applied by
    urdf_input.py to the loop closures' offsets as written, in the same words."""
    for k, x in enumerate(values):
        if abs(x) > bound:
            raise MechanismConfigError(
                name, f'entries must lie within +-{bound:g} {unit}, got {x!r} at index {k}')
    return values


def _check_sizes(links, joints, active):
    """The documented size limits, before anything whose cost grows faster than the file."""
    loops = len(joints) - len(links)
    for name, count, limit, what in (
            ('mechanism.joints', len(joints), MAX_JOINTS, 'joints'),
            ('mechanism.links', len(links), MAX_LINKS, 'links'),
            ('mechanism.active_joints', len(active), MAX_ACTIVE_JOINTS, 'active joints')):
        if count > limit:
            raise MechanismConfigError(
                name, f'{count} {what}, more than the supported {limit} (docs/mechanism.md, '
                      f'size limits)')
    if loops > MAX_LOOPS:
        raise MechanismConfigError(
            'mechanism.joints',
            f'{len(joints)} joints on {len(links)} moving links make {loops} closed loops, more '
            f'than the supported {MAX_LOOPS} (docs/mechanism.md, size limits)')
    columns = len(links) * len(active)
    if columns > MAX_JACOBIAN_COLUMNS:
        raise MechanismConfigError(
            'mechanism.active_joints',
            f'{len(links)} links x {len(active)} active joints = {columns} COG Jacobian '
            f'columns, more than the supported {MAX_JACOBIAN_COLUMNS} (docs/mechanism.md, '
            f'size limits)')


def _check_names(parameter, kind, names):
    """Names of links and joints are parts of ROS 2 parameter names: letters, digits, '_'."""
    for name in names:
        if NAME_PATTERN.match(name):
            continue
        fixed = re.sub(r'[^A-Za-z0-9_]', '_', name)
        if fixed[:1].isdigit():
            fixed = f'{kind}_{fixed}'
        if '.' in name:
            why = (f"contains '.', which ROS 2 reads as a separator of parameter names "
                   f"('{parameter.split('.')[1]}.{name}.*' is ambiguous)")
        elif name[:1].isdigit():
            why = 'starts with a digit, which a ROS 2 parameter name component must not'
        else:
            bad = sorted({c for c in name if not (c.isascii() and (c.isalnum() or c == '_'))})
            why = f"contains {', '.join(repr(c) for c in bad)}"
        raise MechanismConfigError(
            parameter,
            f"{kind} name '{name}' {why}; names of links and joints become parts of ROS 2 "
            f"parameter names ({parameter.split('.')[1]}.<name>.*) and may hold only letters, "
            f"digits and '_', not starting with a digit: use '_' instead, e.g. '{fixed}'")
