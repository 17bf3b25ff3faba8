"""The whole-body kernel: a floating robot's generalized forces and contact maps at a pose.

    whole_body(q, qd, qdd, base, rotation) -> WholeBodyRecord
        q          the solver's coordinates at a closed pose
        qd, qdd    the actuators' rates and accelerations
        base       (v_b, w_b, dv_b, dw_b): the base's twist and its derivative, base frame
        rotation   R_b, world from base, row-major

The record holds Q_b (the base's six rows) and tau (the actuators') of the motion without
contacts, and the maps A (6 x K) and C (M x K) of every contact of mechanism.contacts
(K: their wrench components in order): dynamics/floating_base.py's equations, closed
(closure.evaluate) and given their velocity basis as the dynamics kernel is (kernels.py).
The backends are those of kernels.py: the lane code itself ('reference'), traced into
straight-line Python ('python') or C ('native', a library of its own per mechanism, built
or loaded on first use: a fixed-base solver never makes it). Same numbers to the last bit.
"""
from typing import TYPE_CHECKING, Any, Callable, NamedTuple, Sequence

import numpy as np

from ..closure import closure
from ..closure.joint_motion import velocity_basis
from ..dynamics.floating_base import contact_maps, whole_body_forces
from ..linalg import spatial as sp
from ..linalg.lanes import columns, flat
from ..value_types import FloatArray, Lane, Ops
from . import native
from .emitter import c_module_source, python_function
from .kernels import KERNELS, kernel_key, unpack, width
from .straight_line import Graph, SymOps

if TYPE_CHECKING:
    from ..model.mechanism import Mechanism


class WholeBodyRecord(NamedTuple):
    """What the whole-body kernel returns (one sample: lists; N samples: arrays)."""
    base_forces: Sequence[Lane]   # Q_b: force, moment at the base origin (base frame)
    torques: Sequence[Lane]       # tau of the actuators, active_joints order
    base_map: Sequence[Lane]      # A, 6 x K row by row
    joint_map: Sequence[Lane]     # C, M x K row by row


def whole_body_record(mechanism: 'Mechanism', q: Sequence[Lane], qd: Sequence[Lane],
                      qdd: Sequence[Lane], base: Sequence[Lane], rotation: Sequence[Lane],
                      ops: Ops) -> WholeBodyRecord:
    """WholeBodyRecord at the closed pose q by the lane code (what every backend computes)."""
    pose = closure.evaluate(mechanism.model, q, mechanism.free_joints, ops)
    basis = velocity_basis(mechanism, pose)
    motion = (tuple(base[0:3]), tuple(base[3:6]), tuple(base[6:9]), tuple(base[9:12]))
    q_base, tau, cogs, jac = whole_body_forces(mechanism, pose, basis, qd, qdd, motion,
                                               rotation, ops)
    a_rows, c_rows = contact_maps(mechanism, pose, cogs, jac, list(mechanism.contacts.values()),
                                  rotation)
    return WholeBodyRecord(q_base, tau, [x for row in a_rows for x in row],
                           [x for row in c_rows for x in row])


def components(mechanism: 'Mechanism') -> int:
    """K: the wrench components of every contact of the mechanism."""
    return sum(contact.size for contact in mechanism.contacts.values())


def layout(mechanism: 'Mechanism') -> list[tuple[str, tuple[int, ...]]]:
    m, k = len(mechanism.active_joints), components(mechanism)
    return [('base_forces', (6,)), ('torques', (m,)), ('base_map', (6 * k,)),
            ('joint_map', (m * k,))]


def trace(mechanism: 'Mechanism') -> tuple[str, list[tuple[str, Any]], type, list[Any]]:
    """The kernel run once on symbolic lanes (emitter.py writes it as code)."""
    graph, m = Graph(), mechanism
    q, qd, qdd, base, rotation = (graph.inputs(name, size) for name, size in (
        ('q', m.n_coordinates), ('qd', len(m.active_joints)), ('qdd', len(m.active_joints)),
        ('base', 12), ('rotation', 9)))
    params = [('q', q), ('qd', qd), ('qdd', qdd), ('base', base), ('rotation', rotation)]
    record = whole_body_record(m, q, qd, qdd, base, rotation, SymOps)
    return 'whole_body', params, WholeBodyRecord, list(zip(WholeBodyRecord._fields, record))


class WholeBodyKernel:
    """The kernel of one mechanism on one backend: :meth:`one` for a sample (lists of
    floats), :meth:`many` for N (arrays (N, k) in, a WholeBodyRecord of arrays out)."""

    def __init__(self, mechanism: 'Mechanism', backend: str) -> None:
        self.mechanism, self.layout = mechanism, layout(mechanism)
        self.name = backend
        self._many: Callable[..., FloatArray] | None = None
        self.one: Callable[..., WholeBodyRecord] = self._reference
        if backend == 'python':
            name, params, record, fields = trace(mechanism)
            self.one = python_function(name, params, record, fields)[0]
        elif backend == 'native':
            module, _ = native.load_module(self.key(), self._source)
            module.set_record_types(WholeBodyRecord)
            self.one, self._module = module.whole_body, module

    def key(self) -> str:
        """What the library is made of: the mechanism's kernels and its floating base."""
        m = self.mechanism
        return kernel_key(m) + ':whole_body:' + repr((
            m.base_mass, m.base_com, m.base_inertia, list(m.contacts.values())))

    def _source(self, module: str) -> tuple[str, dict[str, int]]:
        name, params, record, fields = trace(self.mechanism)
        return c_module_source(module, [(name, params, record.__name__, fields)])

    def _reference(self, q: Sequence[float], qd: Sequence[float], qdd: Sequence[float],
                   base: Sequence[float], rotation: Sequence[float]) -> WholeBodyRecord:
        return whole_body_record(self.mechanism, q, qd, qdd, base, rotation, sp.ScalarOps)

    def many(self, q: FloatArray, qd: FloatArray, qdd: FloatArray, base: FloatArray,
             rotation: FloatArray) -> WholeBodyRecord:
        arrays = [np.ascontiguousarray(a, dtype=float) for a in (q, qd, qdd, base, rotation)]
        if self.name == 'native':
            out = np.empty((len(q), width(self.layout)))
            self._module.whole_body_many(*arrays, out)
        else:
            lanes = [columns(a) for a in arrays]
            with np.errstate(all='ignore'):
                out = flat(whole_body_record(self.mechanism, lanes[0], lanes[1], lanes[2],
                                             lanes[3], lanes[4], sp.ArrayOps), len(q))
        return unpack(out, self.layout, WholeBodyRecord)


def whole_body_kernel(mechanism: 'Mechanism', backend: str) -> WholeBodyKernel:
    """The whole-body kernel of ``mechanism`` on ``backend`` (that of its solver), made once
    per process; compiled kernels that cannot be had fall back to the traced Python ones
    (said once, as kernels.py says it)."""
    def make(m: 'Mechanism') -> Any:
        try:
            return WholeBodyKernel(m, backend)
        except native.NativeUnavailable as exc:
            KERNELS.say_fallback(exc)
            return WholeBodyKernel(m, 'python')
    return KERNELS.kernels(mechanism, 'whole_body:' + backend, make)  # type: ignore[return-value]
