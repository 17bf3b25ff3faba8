"""Kernels: the branch-free per-sample computations, and the backends that run them.

Four kernels do all the arithmetic of a sample; the plain-Python glue of sample_solve.py
calls them and makes every decision (continuation, Newton's iteration, checks):

    prediction(q, basis, goal)        -> PredictionRecord: the continuation's first-order
                                         predictor q + V dz towards the actuators' goal
    closure(q)                        -> ClosureRecord: closure equations at q and the
                                         Newton increment of the free joints
    dynamics(q, target, qd, qdd)      -> PoseRecord: the same, and at q the closure
                                         Jacobian's condition number, the velocity basis,
                                         eqs. (1)-(7) (pipeline.py) and, for redundant
                                         actuation, the projection increment to ``target``
    forward(q, target, qd, tau)       -> ForwardRecord: dynamics' record with the
                                         accelerations the efforts tau produce
                                         (forward_dynamics.py) in place of the torques

and a mechanism that is another's solver form (chains of three revolutes solved as
spherical joints, spherical_chains.py) has a fifth, traced and compiled with the first three:

    readout(q, qdot)                  -> joint_readout.ReadoutRecord: the chains' joint
                                         angles and rates as written (Mechanism.joints_at)

Backends (``InverseDynamics(mechanism, backend=...)``):

* ``'reference'``: the lane code itself on Python floats (spatial.ScalarOps), nothing
  traced; the readable definition of the numbers.
* ``'python'``: the same lane code traced once per mechanism (straight_line.py) into three
  straight-line functions (emitter.py) with constants folded and common subexpressions
  shared. Same operations in the same order: the same numbers to the last bit.
* ``'native'``: the same traced kernels written as C, compiled by the system's C
  compiler and cached on disk (native.py). Same operations, IEEE doubles: the same numbers.
* ``'auto'``: ``'native'`` where a compiler (or a cached library) is there, else
  ``'python'`` with one log line saying why; ``'reference'`` for a mechanism too large to
  trace quickly (:data:`TRACE_BUDGET`).
"""
import functools
import hashlib
import logging
import os
from typing import TYPE_CHECKING, Any, Callable, NamedTuple, Sequence
import weakref

import numpy as np

from ..closure import closure
from ..closure.continuation import prediction
from ..closure.joint_motion import projection_increment, velocity_basis
from ..dynamics.forward_dynamics import forward_dynamics
from ..dynamics.pipeline import inverse_dynamics
from ..errors import MechanismConfigError
from ..kinematics import joint_readout
from ..kinematics.joint_readout import ReadoutPlan, ReadoutRecord, readout_record
from ..linalg import spatial as sp
from ..linalg.lanes import columns, flat
from ..value_types import FloatArray, Lane, Ops
from . import native, native_simulation
from .emitter import c_module_source, python_function
from .straight_line import Graph, SymOps

if TYPE_CHECKING:
    from ..model.mechanism import Mechanism

#: a record's fields and their shapes (:func:`layouts`)
Layout = list[tuple[str, tuple[int, ...]]]
#: a traced kernel: (name, [(parameter, its Syms)], record type, [(field, its Syms)])
Traced = tuple[str, list[tuple[str, Any]], type, list[tuple[str, Any]]]
#: a record's field of lanes: a list or tuple of them, or an (N, k) array for N samples
Lanes = Sequence[Any]

#: InverseDynamics(backend=...) choices, the fastest first after 'auto'
BACKENDS = ('auto', 'native', 'python', 'reference')

#: links x actuators above which 'auto' does not trace: the traced code grows with that
#: product (about 8 operations each) and tracing costs ~3 kB per operation, so a large
#: mechanism would load for seconds; the reference kernels serve it instead
TRACE_BUDGET = 2500


class ClosureRecord(NamedTuple):
    """The loop equations at a pose q, and the three numbers Newton's method decides by."""
    residual: Lanes     # Phi(q): 6 equations per constraint (closure.py)
    cosines: Lanes      # per constraint, cosine of its frames' angle (> 0: not a half-turn)
    increment: Lanes    # A_f^+ Phi, the Newton increment of the free joints (q_f -= increment)
    worst: float        # max |residual| (NaN if any is NaN)
    least_cosine: float  # min of the cosines and 1.0
    largest_step: float  # max |increment|


class PredictionRecord(NamedTuple):
    """The continuation's first-order predictor (continuation.prediction)."""
    predicted: Lanes    # q + V dz, the primary actuators at the goal
    moved: Lanes        # V dz: how far it moves every joint


class PoseRecord(NamedTuple):
    """Everything the solver needs at a pose q (the ClosureRecord fields first)."""
    residual: Lanes
    cosines: Lanes
    increment: Lanes
    worst: float
    least_cosine: float
    largest_step: float
    condition: float    # Frobenius condition number of the free columns of A
    torques: Lanes      # tau_m of eq. (7), active_joints order
    basis: Lanes        # rows of the velocity basis V of the free joints (dof each)
    projection: Lanes   # redundant actuation: projection increment dz to the target; else ()


class ForwardRecord(NamedTuple):
    """A PoseRecord with the accelerations of forward dynamics in place of the torques."""
    residual: Lanes
    cosines: Lanes
    increment: Lanes
    worst: float
    least_cosine: float
    largest_step: float
    condition: float
    accelerations: Lanes  # thetaddot the efforts produce, active_joints order
    basis: Lanes
    projection: Lanes
    inertia_condition: float  # of the inertia in the independent coordinates (forward_dynamics.py)


#: the record type of each kernel
RECORDS = {'prediction': PredictionRecord, 'closure': ClosureRecord, 'dynamics': PoseRecord,
           'forward': ForwardRecord}


def closure_record(mechanism: 'Mechanism', q: Sequence[Lane],
                   ops: Ops) -> tuple[closure.ClosureSolution, ClosureRecord]:
    """(pose, ClosureRecord) at q by the lane code."""
    pose = closure.evaluate(mechanism.model, q, mechanism.free_joints, ops)
    residual = [r for st in pose.loops for r in st.residual]
    cosines = [st.cosine for st in pose.loops]
    increment = pose.lsq.solve(residual)
    return pose, ClosureRecord(residual, cosines, increment, ops.maxabs(residual),
                               ops.least(cosines), ops.maxabs(increment))


def pose_record(mechanism: 'Mechanism', q: Sequence[Lane], target: Sequence[Lane],
                qd: Sequence[Lane],
                qdd: Sequence[Lane], ops: Ops) -> PoseRecord:
    """PoseRecord at q by the lane code (the definition both backends compute)."""
    pose, closed = closure_record(mechanism, q, ops)
    basis = velocity_basis(mechanism, pose)
    tau = inverse_dynamics(mechanism, pose, basis, qd, qdd, ops)
    projection = (projection_increment(mechanism, basis, q, target, ops)
                  if mechanism.is_redundant else [])
    return PoseRecord(*closed, pose.lsq.condition_number(), tau,
                      [basis[j] for j in mechanism.free_joints], projection)


def forward_record(mechanism: 'Mechanism', q: Sequence[Lane], target: Sequence[Lane],
                   qd: Sequence[Lane], tau: Sequence[Lane], ops: Ops) -> ForwardRecord:
    """ForwardRecord at q by the lane code: the pose of :func:`pose_record`, and the
    accelerations the efforts ``tau`` produce at the rates ``qd`` there."""
    pose, closed = closure_record(mechanism, q, ops)
    basis = velocity_basis(mechanism, pose)
    qdd, inertia_condition = forward_dynamics(mechanism, pose, basis, qd, tau, ops)
    projection = (projection_increment(mechanism, basis, q, target, ops)
                  if mechanism.is_redundant else [])
    return ForwardRecord(*closed, pose.lsq.condition_number(), qdd,
                         [basis[j] for j in mechanism.free_joints], projection,
                         inertia_condition)


def prediction_record(mechanism: 'Mechanism', q: Sequence[Lane], basis: Any,
                      goal: Sequence[Lane]) -> PredictionRecord:
    """PredictionRecord from the pose q with velocity basis V (list over joints) to the
    goal of the actuators."""
    return PredictionRecord(*prediction(mechanism, (q, basis), goal))


def layouts(mechanism: 'Mechanism') -> dict[str, Layout]:
    """Per kernel, its record's fields and their shapes: () a number, (k,) k numbers,
    (rows, k) rows of k numbers. The order of the flat outputs of the *_many kernels."""
    m = mechanism
    n, n_free, dof, n_act = m.n_coordinates, len(m.free_joints), m.dof, len(m.active_joints)
    n_loops = len(m.model.constraints)
    closing = [('residual', (6 * n_loops,)), ('cosines', (n_loops,)), ('increment', (n_free,)),
               ('worst', ()), ('least_cosine', ()), ('largest_step', ())]
    pose = [('condition', ()), ('torques', (n_act,)), ('basis', (n_free, dof)),
            ('projection', (dof,) if m.is_redundant else (0,))]
    forward = [('accelerations', (n_act,)) if name == 'torques' else (name, shape)
               for name, shape in pose] + [('inertia_condition', ())]
    return {'prediction': [('predicted', (n,)), ('moved', (n,))],
            'closure': closing,
            'dynamics': closing + pose,
            'forward': closing + forward}


def width(layout: Layout) -> int:
    """Numbers in a record of ``layout`` (a field of shape () holds one)."""
    return sum(int(np.prod(shape)) for _, shape in layout)


def unpack(flat: FloatArray, layout: Layout, record: Callable[..., Any]) -> Any:
    """The record of N samples from their flat outputs (N, outputs): each field an array of
    shape (N,) + its shape (views, no copies)."""
    fields: list[FloatArray] = []
    offset = 0
    for _, shape in layout:
        size = int(np.prod(shape))
        block = flat[:, offset:offset + size]
        fields.append(block[:, 0] if not shape else block.reshape((len(flat),) + shape))
        offset += size
    return record(*fields)


class ReferenceKernels:
    """The kernels as lane code: on Python floats for one sample, on numpy arrays of shape
    (N,) for N samples (the *_many kernels, which return flat (N, outputs) arrays in the
    order of :func:`layouts`)."""
    name = 'reference'

    def __init__(self, mechanism: 'Mechanism') -> None:
        self._mechanism: Callable[[], Any] = weakref.ref(mechanism)
        self.layouts = layouts(mechanism)

    @property
    def mechanism(self) -> 'Mechanism':
        """The mechanism the kernels are made for. Held weakly, as by the cache
        (:class:`KernelCache`): kernels are used beside their mechanism (a solver holds
        both), and a mechanism and its kernels go together."""
        return self._mechanism()

    #: one Simulation step in C: compiled kernels only (NativeKernels)
    rk4_step: Any = None

    def with_forward(self) -> 'ReferenceKernels':
        """These kernels, with the forward kernel ready (traced or compiled on first use by
        the backends that make it: a solver that only serves torques never makes it)."""
        return self

    def prediction(self, q: Sequence[float], basis: Any,
                   goal: Sequence[float]) -> PredictionRecord:
        return prediction_record(self.mechanism, q, basis, goal)

    def closure(self, q: Sequence[float]) -> ClosureRecord:
        return closure_record(self.mechanism, q, sp.ScalarOps)[1]

    def dynamics(self, q: Sequence[float], target: Sequence[float], qd: Sequence[float],
                 qdd: Sequence[float]) -> PoseRecord:
        return pose_record(self.mechanism, q, target, qd, qdd, sp.ScalarOps)

    def forward(self, q: Sequence[float], target: Sequence[float], qd: Sequence[float],
                tau: Sequence[float]) -> ForwardRecord:
        return forward_record(self.mechanism, q, target, qd, tau, sp.ScalarOps)

    def readout(self, q: Sequence[float], qdot: Sequence[float]) -> ReadoutRecord:
        return readout_record(ReadoutPlan(self.mechanism), q, qdot, sp.ScalarOps)

    def closure_many(self, q: FloatArray) -> FloatArray:
        return flat(closure_record(self.mechanism, columns(q), sp.ArrayOps)[1], len(q))

    def dynamics_many(self, q: FloatArray, target: FloatArray, qd: FloatArray,
                      qdd: FloatArray) -> FloatArray:
        return flat(pose_record(self.mechanism, columns(q), columns(target), columns(qd),
                                columns(qdd), sp.ArrayOps), len(q))

    def forward_many(self, q: FloatArray, target: FloatArray, qd: FloatArray,
                     tau: FloatArray) -> FloatArray:
        return flat(forward_record(self.mechanism, columns(q), columns(target), columns(qd),
                                   columns(tau), sp.ArrayOps), len(q))


#: the kernels every solver loads (the torques), and those made on first use by forward
#: dynamics and the simulator (a second library: a solver that only serves torques does not
#: trace or compile them)
TORQUE_KERNELS = ('prediction', 'closure', 'dynamics')
FORWARD_KERNELS = ('prediction', 'closure', 'forward')


def first_kernels(mechanism: 'Mechanism') -> tuple[str, ...]:
    """The kernels of a mechanism's first library: the torque kernels, and the read-out
    of the joints as written where it is another's solver form (joint_readout.py)."""
    return TORQUE_KERNELS + (('readout',) if mechanism.stands_for else ())


def trace(mechanism: 'Mechanism', kinds: Sequence[str] = TORQUE_KERNELS) -> list[Traced]:
    """The kernels ``kinds`` run once on symbolic lanes: [(name, params, record type,
    fields)], what the emitters (emitter.py) write as code."""
    m = mechanism
    graph = Graph()
    q = graph.inputs('q', m.n_coordinates)
    effort = 'tau' if 'forward' in kinds else 'qdd'      # dynamics' qdd, forward's tau
    target, qd, qdd = (graph.inputs(name, len(m.active_joints))
                       for name in ('target', 'qd', effort))
    flat = graph.inputs('basis', m.n_coordinates * m.dof)
    basis = [flat[j * m.dof:(j + 1) * m.dof] for j in range(m.n_coordinates)]
    out: list[Any] = []
    for kind in kinds:
        if kind == 'prediction':
            out.append(('prediction', [('q', q), ('basis', basis), ('goal', target)],
                        PredictionRecord, list(zip(PredictionRecord._fields,
                                                   prediction_record(m, q, basis, target)))))
        elif kind == 'closure':
            out.append(('closure', [('q', q)], ClosureRecord,
                        list(zip(ClosureRecord._fields, closure_record(m, q, SymOps)[1]))))
        elif kind == 'dynamics':
            out.append(('dynamics', [('q', q), ('target', target), ('qd', qd), ('qdd', qdd)],
                        PoseRecord, list(zip(PoseRecord._fields,
                                             pose_record(m, q, target, qd, qdd, SymOps)))))
        elif kind == 'readout':         # last: the others' operations keep their numbers
            qdot = graph.inputs('qdot', m.n_coordinates)
            out.append(('readout', [('q', q), ('qdot', qdot)], ReadoutRecord,
                        list(zip(ReadoutRecord._fields,
                                 readout_record(ReadoutPlan(m), q, qdot, SymOps)))))
        else:
            out.append(('forward', [('q', q), ('target', target), ('qd', qd), ('tau', qdd)],
                        ForwardRecord, list(zip(ForwardRecord._fields,
                                                forward_record(m, q, target, qd, qdd,
                                                               SymOps)))))
    return out


class PythonKernels(ReferenceKernels):
    """The kernels traced into straight-line Python functions (``source`` keeps their text,
    ``operations`` their sizes); N samples run the lane code on arrays (reference). The
    forward kernel is traced when first used."""
    name = 'python'

    def __init__(self, mechanism: 'Mechanism', traced: Sequence[Traced] | None = None) -> None:
        super().__init__(mechanism)
        self.source: dict[str, str] = {}
        self.operations: dict[str, int] = {}
        self._add(trace(mechanism, first_kernels(mechanism)) if traced is None else traced)
        if 'readout' in self.source:
            joint_readout.offer(mechanism, self.name, self.readout)

    def _add(self, traced: Sequence[Traced]) -> None:
        for name, params, record, fields in traced:
            function, self.source[name], self.operations[name] = python_function(
                name, params, record, fields)
            setattr(self, name, function)

    def with_forward(self) -> 'PythonKernels':
        if 'forward' not in self.source:        # traced on first use
            self._add(trace(self.mechanism, ('forward',)))
        return self


class NativeKernels(ReferenceKernels):
    """The kernels compiled from C (native.py): a library per mechanism, cached on disk by a
    hash of what the kernels are made of (:func:`kernel_key`), so a cached mechanism loads
    without tracing. N samples run the same C in a loop. Forward dynamics and the simulator
    step (``forward``, ``rk4_step``) are a second library of the mechanism, loaded (or
    built) when first used. Raises native.NativeUnavailable when they cannot be had."""
    name = 'native'

    def __init__(self, mechanism: 'Mechanism') -> None:
        super().__init__(mechanism)
        module, self.operations = native.load_module(kernel_key(mechanism), self._source)
        module.set_record_types(PredictionRecord, ClosureRecord, PoseRecord, ReadoutRecord)
        # the compiled functions stand in for the lane code's methods
        self.prediction = module.prediction                                 # type: ignore[method-assign]
        self.closure, self.dynamics = module.closure, module.dynamics     # type: ignore[method-assign]
        if hasattr(module, 'readout'):
            self.readout = module.readout                                   # type: ignore[method-assign]
            joint_readout.offer(mechanism, self.name, module.readout)
        self.module = module
        self.modules: dict[str, Any] = dict.fromkeys(TORQUE_KERNELS, module)
        self.widths = {name: width(layout) for name, layout in self.layouts.items()}

    def with_forward(self) -> 'NativeKernels':
        """``forward`` and ``rk4_step`` (one Simulation step in C, native_simulation.py) from
        the second library, loaded (or built) on first use. Where it cannot be had, the
        forward kernel is traced into Python (one log line says why), without rk4_step."""
        if 'forward' in self.modules:
            return self
        m = self.mechanism
        try:
            module, operations = native.load_module(kernel_key(m) + ':forward',
                                                    self._forward_source)
        except native.NativeUnavailable as exc:
            KERNELS.say_fallback(exc)
            self.forward = PythonKernels(m, []).with_forward().forward  # type: ignore[method-assign]
            self.modules['forward'] = None
            return self
        module.set_record_types(PredictionRecord, ClosureRecord, ForwardRecord)
        self.operations['forward'] = operations['forward']
        self.forward = module.forward  # type: ignore[method-assign]
        self.rk4_step = module.rk4_step
        self.modules['forward'] = module
        return self

    def closure_many(self, q: FloatArray) -> FloatArray:
        return self._many('closure', q)

    def dynamics_many(self, q: FloatArray, target: FloatArray, qd: FloatArray,
                      qdd: FloatArray) -> FloatArray:
        return self._many('dynamics', q, target, qd, qdd)

    def forward_many(self, q: FloatArray, target: FloatArray, qd: FloatArray,
                     tau: FloatArray) -> FloatArray:
        if self.with_forward().modules['forward'] is None:
            return super().forward_many(q, target, qd, tau)
        return self._many('forward', q, target, qd, tau)

    def _many(self, name: str, *arrays: FloatArray) -> FloatArray:
        contiguous = [np.ascontiguousarray(a, dtype=float) for a in arrays]
        out = np.empty((len(contiguous[0]), self.widths[name]))
        getattr(self.modules[name], name + '_many')(*contiguous, out)
        return out

    def _source(self, module: str) -> tuple[str, dict[str, int]]:
        """(C source of the module, operations per kernel): traced here, only when the
        library must be built, and not kept (a large mechanism's trace is tens of MB)."""
        return c_module_source(module, [(name, params, record.__name__, fields)
                                        for name, params, record, fields in
                                        trace(self.mechanism, first_kernels(self.mechanism))])

    def _forward_source(self, module: str) -> tuple[str, dict[str, int]]:
        """The same for the second library: the forward kernel, the two it is closed with,
        and the Simulation step (native_simulation.py)."""
        m = self.mechanism
        return c_module_source(module, [(name, params, record.__name__, fields)
                                        for name, params, record, fields in
                                        trace(m, FORWARD_KERNELS)],
                               native_simulation.simulation_source(m, self.layouts),
                               [(name, 'sim_' + name, doc)
                                for name, doc in native_simulation.METHODS])


def kernel_key(mechanism: 'Mechanism') -> str:
    """Everything a mechanism's kernels are made of, as text: the model as read (joints,
    inertias, gravity, actuators, weights; the same whatever types the parameters came in,
    e.g. rclpy's arrays, and whatever the initial positions), the chains of a solver form
    (their axes, frames and assembled angles: the read-out's) and the core's source."""
    m = mechanism
    chains = repr(m.stands_for) if m.stands_for else ''
    return repr((m.joint_specs, m.closure_specs, m.link_mass, m.link_com, m.link_inertia,
                 m.gravity, m.active_index, m.primary, m.free_joints, m.dof,
                 m.torque_weights)) + chains + core_version()


@functools.cache
def core_version() -> str:
    """A hash of the core's source files (its Python and the C of the kernels' prelude):
    what the kernels are made of."""
    digest = hashlib.sha256()
    # the whole of core/, every folder (this module is in core/native/)
    core = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    for folder, folders, names in os.walk(core):
        folders[:] = sorted(f for f in folders if f != '__pycache__')
        for name in sorted(names):
            if name.endswith(('.py', '.c')):
                path = os.path.join(folder, name)
                with open(path, 'rb') as f:
                    relative = os.path.relpath(path, core).replace(os.sep, '/')
                    digest.update(relative.encode() + b'\0' + f.read())
    return digest.hexdigest()


class KernelCache:
    """The kernels made in this process, per mechanism and backend: a mechanism's traced and
    compiled kernels are made once and shared by every solver of it (the node makes
    several), and go when the mechanism goes (the cache holds the mechanism weakly, and so
    do its kernels; the frozen Mechanism holds nothing of them). Also what this process has
    said once: that compiled kernels are unavailable."""

    def __init__(self) -> None:
        # mechanism -> {backend: kernels}
        self._made: 'weakref.WeakKeyDictionary[Mechanism, dict[str, ReferenceKernels]]' = \
            weakref.WeakKeyDictionary()
        #: the fallback to the Python kernels has been logged (it is said once per process)
        self.fallback_said = False

    def kernels(self, mechanism: 'Mechanism', backend: str,
                make: Callable[['Mechanism'], ReferenceKernels]) -> ReferenceKernels:
        """The ``backend`` kernels of ``mechanism``: ``make(mechanism)`` the first time."""
        made = self._made.setdefault(mechanism, {})
        kernels = made.get(backend)
        if kernels is None:
            kernels = made[backend] = make(mechanism)
        return kernels

    def say_fallback(self, why: object) -> None:
        """Log, once per process, that the Python kernels serve where compiled ones were
        wanted and ``why``."""
        if not self.fallback_said:
            _log.warning('cog_id_ros: compiled kernels unavailable (%s): using the '
                         "Python kernels (backend='python')", why)
            self.fallback_said = True


#: the kernels of this process
KERNELS = KernelCache()
_log = logging.getLogger('cog_id_ros')


def kernels_for(mechanism: 'Mechanism', backend: str = 'auto') -> ReferenceKernels:
    """The kernels of ``backend`` for a mechanism (traced and compiled kernels are made once
    and shared by every solver of the mechanism: :data:`KERNELS`).

    'auto': native where a C compiler (or a cached library) is there, else the Python
    kernels with one log line saying why; the reference kernels above TRACE_BUDGET."""
    if backend not in BACKENDS:
        raise MechanismConfigError('backend', f'must be one of {", ".join(BACKENDS)}, '
                                              f'got {backend!r}')
    if backend == 'reference' or (backend == 'auto' and
                                  len(mechanism.links) * len(mechanism.active_joints) >
                                  TRACE_BUDGET):
        return ReferenceKernels(mechanism)
    if backend in ('auto', 'native'):
        try:
            return KERNELS.kernels(mechanism, 'native', NativeKernels)
        except native.NativeUnavailable as exc:
            if backend == 'native':
                raise MechanismConfigError(
                    'backend', f"'native' needs compiled kernels, and {exc}; use 'auto', "
                               f"'python' or 'reference'") from None
            KERNELS.say_fallback(exc)
    return KERNELS.kernels(mechanism, 'python', PythonKernels)
