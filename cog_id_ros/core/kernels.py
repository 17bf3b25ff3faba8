"""Kernels: the branch-free per-sample computations, and the backends that run them.

Two kernels do all the arithmetic of a sample; the plain-Python glue of sample_solve.py
calls them and makes every decision (continuation, Newton's iteration, checks):

    closure(q)                        -> ClosureRecord: closure equations at q and the
                                         Newton increment of the free joints
    dynamics(q, target, qd, qdd)      -> PoseRecord: the same, and at q the closure
                                         Jacobian's condition number, the velocity basis,
                                         eqs. (1)-(7) (pipeline.py) and, for redundant
                                         actuation, the projection increment to ``target``

Backends (``InverseDynamics(mechanism, backend=...)``):

* ``'reference'``: the lane code itself on Python floats (spatial.ScalarOps), nothing
  traced; the readable definition of the numbers.
* ``'python'``: the same lane code traced once per mechanism (straight_line.py) into two
  straight-line functions (emitter.py) with constants folded and common subexpressions
  shared. Same operations in the same order: the same numbers to the last bit.
* ``'auto'``: ``'python'`` unless the mechanism is too large to trace quickly
  (:data:`TRACE_BUDGET`), then ``'reference'``.
"""
from typing import NamedTuple
import weakref

from . import closure
from . import spatial as sp
from .emitter import python_function
from .errors import MechanismConfigError
from .joint_motion import projection_increment, velocity_basis
from .pipeline import inverse_dynamics
from .straight_line import Graph, SymOps

BACKENDS = ('auto', 'reference', 'python', 'native')

#: links x actuators above which 'auto' does not trace: the traced code grows with that
#: product (about 8 operations each) and tracing costs ~3 kB per operation, so a large
#: mechanism would load for seconds; the reference kernels serve it instead
TRACE_BUDGET = 2500


class ClosureRecord(NamedTuple):
    """The loop equations at a pose q."""
    residual: tuple     # Phi(q): 6 equations per loop (closure.py)
    cosines: tuple      # per loop, cosine between its attachment frames (> 0: not a half-turn)
    increment: tuple    # A_f^+ Phi, the Newton increment of the free joints (q_f -= increment)


class PoseRecord(NamedTuple):
    """Everything the solver needs at a pose q (the ClosureRecord fields first)."""
    residual: tuple
    cosines: tuple
    increment: tuple
    condition: float    # Frobenius condition number of the free columns of A
    torques: tuple      # tau_m of eq. (7), active_joints order
    basis: tuple        # rows of the velocity basis V of the free joints (dof each)
    projection: tuple   # redundant actuation: projection increment dz to the target; else ()


def closure_record(mechanism, q, ops):
    """(pose, ClosureRecord) at q by the lane code."""
    pose = closure.evaluate(mechanism.model, q, mechanism.free_joints, ops)
    residual = [r for st in pose.loops for r in st.residual]
    return pose, ClosureRecord(residual, [st.cosine for st in pose.loops],
                               pose.lsq.solve(residual))


def pose_record(mechanism, q, target, qd, qdd, ops):
    """PoseRecord at q by the lane code (the definition both backends compute)."""
    pose, closed = closure_record(mechanism, q, ops)
    basis = velocity_basis(mechanism, pose)
    tau = inverse_dynamics(mechanism, pose, basis, qd, qdd, ops)
    projection = (projection_increment(mechanism, basis, q, target, ops)
                  if mechanism.is_redundant else [])
    return PoseRecord(closed.residual, closed.cosines, closed.increment,
                      pose.lsq.condition_number(), tau,
                      [basis[j] for j in mechanism.free_joints], projection)


class ReferenceKernels:
    """The kernels as lane code on Python floats."""
    name = 'reference'

    def __init__(self, mechanism):
        self.mechanism = mechanism

    def closure(self, q):
        return closure_record(self.mechanism, q, sp.ScalarOps)[1]

    def dynamics(self, q, target, qd, qdd):
        return pose_record(self.mechanism, q, target, qd, qdd, sp.ScalarOps)


class PythonKernels:
    """The kernels traced into straight-line Python functions (``source`` keeps their text,
    ``operations`` their sizes)."""
    name = 'python'

    def __init__(self, mechanism):
        m = self.mechanism = mechanism
        graph = Graph()
        q = graph.inputs('q', len(m.joints))
        target, qd, qdd = (graph.inputs(name, len(m.active_joints))
                           for name in ('target', 'qd', 'qdd'))
        _, closed = closure_record(m, q, SymOps)
        whole = pose_record(m, q, target, qd, qdd, SymOps)
        self.closure, closure_source, closure_ops = python_function(
            'closure', [('q', q)], ClosureRecord, list(zip(ClosureRecord._fields, closed)))
        self.dynamics, dynamics_source, dynamics_ops = python_function(
            'dynamics', [('q', q), ('target', target), ('qd', qd), ('qdd', qdd)], PoseRecord,
            list(zip(PoseRecord._fields, whole)))
        self.source = {'closure': closure_source, 'dynamics': dynamics_source}
        self.operations = {'closure': closure_ops, 'dynamics': dynamics_ops}


_traced = weakref.WeakKeyDictionary()    # mechanism -> PythonKernels (traced once, shared)


def kernels_for(mechanism, backend='auto'):
    """The kernels of ``backend`` for a mechanism (traced kernels are made once and shared
    by every solver of the mechanism)."""
    if backend not in BACKENDS:
        raise MechanismConfigError('backend', f'must be one of {", ".join(BACKENDS)}, '
                                              f'got {backend!r}')
    if backend == 'native':
        raise MechanismConfigError('backend', "'native' (compiled kernels) is not available "
                                              "in this version: use 'auto' or 'python'")
    if backend == 'reference' or (backend == 'auto' and
                                  len(mechanism.links) * len(mechanism.active_joints) >
                                  TRACE_BUDGET):
        return ReferenceKernels(mechanism)
    kernels = _traced.get(mechanism)
    if kernels is None:
        kernels = _traced[mechanism] = PythonKernels(mechanism)
    return kernels
