"""Mechanism: a validated description of links, joints and actuators, ready to solve.

Built from the native parameters (docs/parameter_file.md, and
docs/mechanism.md for the limits and defaults): the dotted names rclpy gives a node, or a
nested dict. Files and other forms are read outside the core: ``cog_id_ros.Mechanism``
(:mod:`cog_id_ros.description.mechanism`) is this class with ``from_params_file`` and
``from_parameters``. Everything a user can get wrong raises MechanismConfigError naming the
parameter. At load the mechanism is assembled near
``initial_positions`` (actuators held), its degrees of freedom are read off the rank of the
closure Jacobian there, and the actuators are checked to determine the motion. What the
assembly had to change is reported in ``assembly_warnings`` (and as AssemblyWarning).

Sizes are checked first (MAX_JOINTS and friends), before anything whose cost grows faster
than the size of the file; values are checked against documented bounds (MAX_LENGTH and
friends) so that finite, moderate setpoints never produce an infinite torque. What a joint
of each kind reads and checks its kind says (joints.py); the analysis at load is in
assembly.py (closing the loops) and degrees_of_freedom.py (freedoms, primary actuators).
"""
import math
import re
from typing import Any, Iterable, Mapping, Sequence, TypeVar
import warnings

import numpy as np

from ..closure import closure
from ..errors import MechanismConfigError
from ..kinematics import couplings, joints, spherical_chains
from ..kinematics.kinematics import BASE, JointSpec, KinematicModel
from ..kinematics.parameters import ParameterReader, split_owner
from ..kinematics.spherical_chains import SphericalChain
from ..value_types import FloatArray
from . import assembly, degrees_of_freedom, idle_spins
from .assembly import AssemblyWarning
from .floating_base import read_floating_base
from .joint_space import check_joint_space, read_joint_space

MECHANISM_KEYS = ('name', 'gravity', 'base_link', 'links', 'joints', 'active_joints',
                  'initial_positions', 'torque_weights', 'setpoint_tolerance',
                  'max_condition_number', 'closure_tolerance', 'locked_joints', 'idle_spins',
                  'found_at_assembly', 'assembly', 'joint_space', 'floating_base', 'contacts')
LINK_KEYS = ('mass', 'com', 'inertia')
JOINT_KEYS = ('type', 'parent', 'child', 'parent_xyz', 'parent_rpy', 'child_xyz', 'child_rpy',
              'axis', 'axis2') + couplings.KEYS + ('lower', 'upper', 'effort')

DEFAULT_SETPOINT_TOLERANCE = 1e-3      # rad or m: larger redundant disagreements are rejected
DEFAULT_MAX_CONDITION_NUMBER = 1e6     # closure Jacobian (passive joints), Frobenius norm
DEFAULT_CLOSURE_TOLERANCE = 1e-10      # m or rad: a loop counts as closed below this residual

# --- bounds on values (docs/mechanism.md): a mechanism within them, driven by finite
# moderate setpoints, never produces an infinite torque
MAX_LENGTH = 1e6            # m: every entry of com, parent_xyz, child_xyz
MAX_COORDINATE = 1e6        # rad or m: initial_positions, parent_rpy, child_rpy
MAX_MASS = 1e9              # kg
#: a link this many times heavier than the median link, and heavier than HEAVY kg, is
#: reported at load: most likely a density or unit mistake in the model (a CAD export)
HEAVIER, HEAVY = 1e4, 1e3
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

#: what :func:`bounded` checks and hands back
Values = TypeVar('Values', bound=Sequence[float])

#: what no name of a link or joint may hold: control characters (a line break would split a
#: log line, a CSV row or a parameter file's key). Anything else is a name, as URDF exporters
#: write them ('/', a leading digit, '.', spaces, non-ASCII letters): ROS 2 parameter files
#: hold such keys (``links.<name>.mass``), and outputs carry the names unchanged
NAME_REFUSED = re.compile(r'[\x00-\x1f\x7f-\x9f]')


class Mechanism:
    """Links, joints and actuators of a (closed-link) mechanism; see docs/mechanism.md."""

    #: read by idle_spins.read_locks: the joints held at their initial positions (names,
    #: and indices into ``joints``; idle_spins: lock adds its own), and mechanism.idle_spins
    locked_joints: list
    locked_index: list
    idle_spins: str
    #: read by couplings.read_couplings: (follower, leader, multiplier, offset) per coupled
    #: joint (joints.<name>.mimic)
    couplings: list
    #: read by floating_base.read_floating_base: the base free in space, its mass
    #: properties, the contacts (name -> floating_base.Contact)
    floating_base: bool
    base_mass: float
    base_com: tuple
    base_inertia: tuple
    contacts: dict

    def __init__(self, params: Mapping[str, Any], _chains: Iterable[SphericalChain] = ()) -> None:
        reader = ParameterReader(params)
        self.parameters = dict(reader.params)
        self.assembly_warnings: list[str] = []
        #: made by another Mechanism as its solver form: the chains of three revolutes its
        #: spherical joints stand for (spherical_chains.py)
        self.stands_for = list(_chains)
        self._read_mechanism(reader)
        self._read_links(reader)
        self._read_joints(reader)
        self._read_positions(reader)
        couplings.read_couplings(self, reader, MAX_COORDINATE)
        idle_spins.read_locks(self, reader)
        #: mechanism.joint_space: the joints a controller commands ([]: none; transmission/)
        self.joint_space = read_joint_space(self, reader)
        #: mechanism.floating_base, the base's mass properties, mechanism.contacts
        read_floating_base(self, reader, lambda prefix: read_inertial(reader, prefix, False))
        self._reject_unknown(reader)
        self.model = KinematicModel(self.links, self.joint_specs, self.closure_specs, [
            couplings.constraint(f, self.joints.index(f), self.joints.index(leader), m, o)
            for f, leader, m, o in self.couplings])
        #: the solver's coordinates: the joints (mechanism.joints), then the hidden ones of
        #: spherical and universal joints in the spanning tree (kinematics.py)
        self.n_coordinates = self.model.n_coordinates
        #: per coordinate: 'revolute', 'prismatic' or 'quaternion'
        self.coordinate_types = self.model.coordinate_types
        self.joint_index = {name: k for k, name in enumerate(self.joints)}
        self.link_index = {name: k for k, name in enumerate(self.links)}
        self.active_index = [self.joint_index[name] for name in self.active_joints]
        try:
            matrix = self._analyse()
            self._actuated(degrees_of_freedom.primary_actuators(self, matrix, self.dof))
            degrees_of_freedom.report_dependent(self, matrix)
            check_joint_space(self, idle_spins.with_locks(self, matrix))
        except (np.linalg.LinAlgError, ArithmeticError, FloatingPointError) as exc:
            raise MechanismConfigError(
                'mechanism.initial_positions',
                f'the mechanism could not be analysed at these positions ({exc}); check the '
                f'geometry and initial_positions') from None
        self._solver_form()
        # what the kernels are made of stays what it was read as: read-only from here on
        self._frozen = True

    def __setattr__(self, name: str, value: object) -> None:
        if getattr(self, '_frozen', False):
            raise AttributeError(
                f'Mechanism.{name} is read-only: solvers and their compiled kernels are made '
                f'from the mechanism as it was read. Change the parameters and build a new '
                f'one with Mechanism.from_parameters')
        object.__setattr__(self, name, value)

    # --- reading ----------------------------------------------------------------------------

    def _read_mechanism(self, r: ParameterReader) -> None:
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
        #: torque_weights written: a redundancy is meant (degrees_of_freedom.report_dependent)
        self.weights_given = r.has('mechanism.torque_weights')
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
    def _positive(r: ParameterReader, name: str, default: float, low: float | None = None,
                  high: float | None = None) -> float:
        value = r.number(name, default=default)
        if value <= 0.0:
            raise MechanismConfigError(name, f'must be positive, got {value!r}')
        if low is not None and value < low:
            raise MechanismConfigError(name, f'must be at least {low:g}, got {value!r}')
        if high is not None and value > high:
            raise MechanismConfigError(name, f'must be at most {high:g}, got {value!r}')
        return value

    def _read_links(self, r: ParameterReader) -> None:
        self.link_mass, self.link_com, self.link_inertia = [], [], []
        for link in self.links:
            mass, com, inertia = read_inertial(r, f'links.{link}.')
            self.link_mass.append(mass)
            self.link_com.append(com)
            self.link_inertia.append(inertia)
        masses = sorted(m for m in self.link_mass if m > 0.0)
        median = masses[len(masses) // 2] if masses else 0.0
        for link, mass in zip(self.links, self.link_mass):
            if mass > HEAVY and mass > HEAVIER * median:
                assembly.note(self, f"link '{link}' weighs {mass:.4g} kg, {mass / median:.3g} "
                                    f'times the median link ({median:.4g} kg): most likely a '
                                    f'density or unit mistake in the model (links.{link}.mass, '
                                    f"or the URDF's <inertial>); its weight dominates every "
                                    f'torque')

    def _read_joints(self, r: ParameterReader) -> None:
        """Every joint of mechanism.joints, read by its kind (joints.py): those with a
        coordinate (revolute, prismatic: ``joints``, ``joint_specs``) and those without one
        of their own (spherical, universal, fixed: ``closure_joints``, ``closure_specs``)."""
        self.joint_types, self.joint_specs, self.closure_specs = [], [], []
        self.position_limits, self.joint_efforts = [], []
        known = {name: k for k, name in enumerate(self.links)}
        known[self.base_link] = BASE
        for joint in self.declared_joints:
            prefix = f'joints.{joint}.'
            type_name = r.string(prefix + 'type', required=True)
            kind_class = joints.kind(type_name)
            if kind_class is None:
                raise MechanismConfigError(
                    prefix + 'type',
                    f"must be one of {', '.join(joints.names())}, got {type_name!r}")
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
            kind: Any = kind_class.read(r, prefix)     # a CoordinateKind if it has_coordinate
            offsets: dict[str, tuple[float, ...]] = {}
            for key, bound, unit in (('parent_xyz', MAX_LENGTH, 'm'),
                                     ('parent_rpy', MAX_COORDINATE, 'rad'),
                                     ('child_xyz', MAX_LENGTH, 'm'),
                                     ('child_rpy', MAX_COORDINATE, 'rad')):
                value = r.vector(prefix + key, 3, default=(0.0, 0.0, 0.0))
                offsets[key] = bounded(prefix + key, value, bound, unit)
            spec = JointSpec(joint, kind, ends[0], ends[1], **offsets)
            if not kind.has_coordinate:
                self.closure_specs.append(spec)
                continue
            self.joint_types.append(kind.name)
            self.joint_specs.append(spec)
            limits, effort = kind.read_limits(r, prefix)
            self.position_limits.append(limits)
            self.joint_efforts.append(effort)
        self.joints = [spec.name for spec in self.joint_specs]
        self.closure_joints = [spec.name for spec in self.closure_specs]
        #: the largest attachment offset of a joint with a coordinate (m; 1.0 if none)
        self.attachment_scale = assembly.attachment_scale(self.joint_specs)

    def _read_positions(self, r: ParameterReader) -> None:
        """initial_positions (one per revolute or prismatic joint); the actuators, which
        must have a coordinate, and their effort limits."""
        for name in self.active_joints:
            if name in self.closure_joints:
                kind = self.closure_specs[self.closure_joints.index(name)].kind.name
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
        #: the joints whose initial position is only where the assembly starts its search
        #: (mechanism.found_at_assembly; the URDF form: those initial_positions leaves out)
        self.found_at_assembly = r.string_list('mechanism.found_at_assembly') or []
        for name in self.found_at_assembly:
            if name not in index:
                raise MechanismConfigError(
                    'mechanism.found_at_assembly',
                    f"'{name}' is not a revolute or prismatic joint of mechanism.joints")
        self.found_index = sorted(index[name] for name in self.found_at_assembly)
        self.assembly = r.string('mechanism.assembly', default=assembly.ASSEMBLY_MODES[0])
        if self.assembly not in assembly.ASSEMBLY_MODES:
            raise MechanismConfigError(
                'mechanism.assembly', f"must be {' or '.join(map(repr, assembly.ASSEMBLY_MODES))}"
                                      f', got {self.assembly!r}')
        #: per active joint: its kind object (joints.py), (lower, upper) position limits
        #: and the effort limit (inf: none)
        self.active_kinds = [self.joint_specs[index[a]].kind for a in self.active_joints]
        self.active_position_limits = [self.position_limits[index[a]]
                                       for a in self.active_joints]
        self.effort_limits = [self.joint_efforts[index[a]] for a in self.active_joints]
        #: (index into active_joints, lower, upper) of every actuator with a position limit
        self.limited_actuators = [(a, lo, hi) for a, (lo, hi) in
                                  enumerate(self.active_position_limits)
                                  if lo > -math.inf or hi < math.inf]

    def _reject_unknown(self, r: ParameterReader) -> None:
        for name in r.unused('mechanism.'):
            raise MechanismConfigError(
                name, f"unknown parameter (mechanism.* takes {', '.join(MECHANISM_KEYS)})")
        kinds = {spec.name: spec.kind for spec in self.joint_specs + self.closure_specs}
        joint_keys = JOINT_KEYS + tuple(key for key in joints.parameter_names()
                                        if key not in JOINT_KEYS)
        for group, names, keys in (('links', self.links, LINK_KEYS),
                                   ('joints', self.declared_joints, joint_keys)):
            for name in r.unused(group + '.'):
                owner, key = split_owner(name[len(group) + 1:], names)
                if owner is None:
                    raise MechanismConfigError(
                        name, f"unknown {group[:-1]} '{key.split('.')[0]}' (not in "
                              f"mechanism.{group})")
                kind: Any = kinds.get(owner) if group == 'joints' else None
                why = kind.refused.get(key) if kind is not None else None
                if why:
                    raise MechanismConfigError(name, f'not a parameter of a {kind.name} joint: '
                                                     f'a {kind.name} joint {why}')
                raise MechanismConfigError(
                    name, f"unknown parameter ({group}.{owner}.* takes {', '.join(keys)})")

    # --- after reading: the solver form, the assembled pose, the actuators ------------------

    def _solver_form(self) -> None:
        """What the solver solves (``solver_mechanism``): this mechanism, or, where three
        revolute joints through massless links are one spherical joint (spherical_chains.py,
        ``spherical_chains``), the same mechanism with those chains as spherical joints; and
        ``joints_at``'s way back to the joints as written."""
        self.spherical_chains, self.solver_mechanism, self._readout = [], self, None
        if self.stands_for:
            return
        chains = spherical_chains.chains_of(self)
        if not chains:
            return
        params = spherical_chains.solver_parameters(self.parameters, chains, self.joints,
                                                    self.assembled_positions)
        # the spins are locked already, and every position is where the assembly put it
        for name in ('mechanism.idle_spins', 'mechanism.found_at_assembly',
                     'mechanism.assembly', 'mechanism.joint_space'):
            params.pop(name, None)
        if self.locked_joints:
            params['mechanism.locked_joints'] = list(self.locked_joints)
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

    def settled_parameters(self) -> dict[str, Any]:
        """The parameters of this mechanism with its assembled pose pinned: every joint's
        position given (where the assembly found it), the joints it locked named. A
        Mechanism made from them is this one without the search at load (another process's
        copy, the node's trajectory worker)."""
        params = dict(self.parameters)
        for name in ('mechanism.found_at_assembly', 'mechanism.assembly',
                     'mechanism.idle_spins'):
            params.pop(name, None)
        params['mechanism.initial_positions'] = [float(x) for x in self.assembled_positions]
        if self.locked_joints:
            params['mechanism.locked_joints'] = list(self.locked_joints)
        return params

    def joints_at(self, coordinates: Any,
                  rates: Any = None) -> tuple[FloatArray, FloatArray | None]:
        """(positions, rates or None) of ``joints`` from the coordinates of
        ``solver_mechanism`` (and their rates): (n,) -> (len(joints),), (N, n) -> (N,
        len(joints)); the chains' angles read back from the pose."""
        if self._readout is None:
            q = np.asarray(coordinates, dtype=float)[..., :len(self.joints)]
            return q, None if rates is None else \
                np.asarray(rates, dtype=float)[..., :len(self.joints)]
        return self._readout(coordinates, rates)

    def coordinates_as_written(self, coordinates: Any) -> FloatArray:
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

    def _analyse(self) -> FloatArray:
        """Assembly and the degrees of freedom (assembly.py, degrees_of_freedom.py); with
        ``idle_spins: lock``, once more with the joints that take out the idle spins
        locked (idle_spins.py), held where the first assembly put them (or at their
        initial positions where those were given). The closure Jacobian at the assembled
        pose."""
        #: True once idle_spins: lock has locked joints of its own choice; what spun, and
        #: which joint was locked for each (idle_spins.record)
        self.spins_locked = False
        self.idle_spin_sets: list[dict] = []
        notes: list[str] = []
        start = None
        while True:
            q, moved, problem = assembly.assemble(self, start, settled=start is not None)
            self._assembled(q)
            try:
                matrix, self.closure_rank, self.dof = degrees_of_freedom.count(
                    self, moved, problem)
            except idle_spins.LockThem as lock:
                self.spins_locked, notes, self.idle_spin_sets = True, lock.notes, lock.spins
                self.locked_joints = self.locked_joints + [self.joints[j] for j in lock.joints]
                self.locked_index = sorted(self.locked_index + lock.joints)
                start = [q[j] if j in self.found_index or j >= len(self.joints) else
                         self.initial_positions[j] for j in range(len(q))]
                continue
            for text in notes:
                assembly.note(self, text)
            # where the assembly found a position, that is the initial position from here on
            found = set(self.found_index)
            self.initial_positions = tuple(
                float(q[j]) if j in found else x for j, x in enumerate(self.initial_positions))
            return matrix

    def _assembled(self, q: Sequence[float]) -> None:
        #: every coordinate of the solver at the assembled pose (hidden ones included)
        self.assembled_coordinates = tuple(q)
        self.assembled_positions = tuple(q[:len(self.joints)])

    def _actuated(self, primary: list[int]) -> None:
        #: indices into active_joints of the ``dof`` primary actuators (degrees_of_freedom.py)
        self.primary = primary
        self.primary_joints = [self.active_index[i] for i in self.primary]
        #: (index into active_joints, joint index) of each primary actuator
        self.primary_pairs = list(zip(self.primary, self.primary_joints))
        fixed = set(self.primary_joints) | set(self.locked_index)
        #: the coordinates solved for: all but the primary actuators and the locked joints
        self.free_joints = [j for j in range(self.n_coordinates) if j not in fixed]
        self.inverse_torque_weights = [1.0 / w for w in self.torque_weights]

    def far_move_limit(self, j: int) -> tuple[float, str | None]:
        """(limit, unit): assembly.far_move_limit, the move of joint j at assembly beyond
        which it is reported as far."""
        return assembly.far_move_limit(self, j)

    @property
    def is_redundant(self) -> bool:
        return len(self.active_joints) > self.dof

    def __repr__(self) -> str:
        return (f'Mechanism({self.name!r}: {len(self.links)} links, {len(self.joints)} joints, '
                f'{len(self.model.loops)} loops, {self.dof} DOF, active {self.active_joints})')


def read_inertial(r: ParameterReader, prefix: str, required: bool = True
                  ) -> tuple[float, tuple[float, ...], tuple[float, ...]]:
    """(mass, COG, inertia as a row-major 9-tuple) of ``<prefix>mass``, ``com``,
    ``inertia`` (the mass 0 when not ``required`` and absent)."""
    mass = r.number(prefix + 'mass', required=True) if required else \
        r.number(prefix + 'mass', default=0.0)
    if mass < 0.0:
        raise MechanismConfigError(prefix + 'mass', f'must be >= 0, got {mass!r}')
    if mass > MAX_MASS:
        raise MechanismConfigError(prefix + 'mass',
                                   f'must be at most {MAX_MASS:g} kg, got {mass!r}')
    com = bounded(prefix + 'com', r.vector(prefix + 'com', 3, default=(0.0, 0.0, 0.0)),
                  MAX_LENGTH, 'm')
    return mass, com, _inertia(r, prefix + 'inertia')


def _inertia(r: ParameterReader, name: str) -> tuple[float, ...]:
    values = r.vector(name, default=(0.0,) * 6)
    if len(values) not in (6, 9):
        raise MechanismConfigError(
            name, f'must have 6 entries [ixx, iyy, izz, ixy, ixz, iyz], got {len(values)}')
    problem = inertia_problem(values)
    if problem:
        raise MechanismConfigError(name, problem)
    return tuple(float(x) for x in _inertia_matrix(values).ravel())


def _inertia_matrix(values: Sequence[float]) -> FloatArray:
    if len(values) == 6:
        ixx, iyy, izz, ixy, ixz, iyz = values
        return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
    return np.array(values).reshape(3, 3)


def inertia_problem(values: Sequence[float]) -> str | None:
    """What makes ``values`` (6 entries [ixx, iyy, izz, ixy, ixz, iyz], or 9 row by row,
    finite) no rigid body's inertia, as a message, or None. One test for the native
    ``links.<l>.inertia`` and for the URDF's ``<inertia>`` (description/urdf_tree.py), so that both
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


def bounded(name: str, values: Values, bound: float, unit: str) -> Values:
    """values unchanged, or MechanismConfigError if an entry exceeds +-bound. Also applied by
    description/loop_closures.py to the loop closures' offsets as written, in the same
    words."""
    for k, x in enumerate(values):
        if abs(x) > bound:
            raise MechanismConfigError(
                name, f'entries must lie within +-{bound:g} {unit}, got {x!r} at index {k}')
    return values


def _check_sizes(links: Sequence[str], joints: Sequence[str], active: Sequence[str]) -> None:
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


def name_problem(name: str) -> str | None:
    """Why ``name`` cannot name a link or joint (a control character in it), or None."""
    found = NAME_REFUSED.search(name)
    if found is None:
        return None
    return (f'holds the control character U+{ord(found.group()):04X} at index '
            f'{found.start()}, which would split log lines, CSV rows and parameter keys')


def _check_names(parameter: str, kind: str, names: Iterable[str]) -> None:
    """Any name but one with a control character (NAME_REFUSED)."""
    for name in names:
        problem = name_problem(name)
        if problem:
            raise MechanismConfigError(parameter, f'{kind} name {name!r} {problem}; remove it')
