"""Forward dynamics of one sample or N samples: the closed pose as torques finds it, then
the accelerations the efforts produce there (forward_dynamics.py, by the 'forward' kernel).

The pose is solved exactly as for the torques (sample_solve.py, batch.py: warm start,
continuation on the assembly branch, the redundant projection), by a SampleSolver and a
Batch that evaluate closed poses with the forward kernel instead of the dynamics kernel, so
nothing is computed twice. What can go wrong is what can go wrong for the torques, and a
singular inertia (:data:`forward_dynamics.INERTIA_CONDITION_LIMIT`).
"""
import math
from typing import Any, Optional, Sequence, Tuple, cast

import numpy as np

from ..closure.continuation import State
from ..dynamics.forward_dynamics import INERTIA_CONDITION_LIMIT
from ..errors import CogIdError, SetpointError, SingularConfigurationError
from ..model.mechanism import Mechanism
from ..native.kernels import ForwardRecord
from .batch import Batch
from .inputs import check_values
from .sample_solve import SampleSolver

#: what forward dynamics calls its inputs in messages (inputs.LABELS for the torques)
LABELS = ('q', 'qd', 'tau')


class ForwardSolver:
    """Forward dynamics of one mechanism (its solver form) with one set of kernels."""

    def __init__(self, mechanism: Mechanism, kernels: Any, continuation_step: float,
                 joints_at: Any) -> None:
        self.mechanism = mechanism
        self.kernels = kernels = kernels.with_forward()     # (made now on first use)
        self.serial = SampleSolver(mechanism, kernels, continuation_step, whole='forward')
        self.batch = Batch(mechanism, self.serial, joints_at)

    def one(self, state: State, q: Sequence[float], qd: Sequence[float],
            tau: Sequence[float], project: bool = True, sample: Optional[int] = None
            ) -> Tuple[ForwardRecord, State]:
        """(ForwardRecord at the closed pose of ``q``, new state) from the warm start; with
        ``project`` False a redundant mechanism's primary actuators are put at ``q`` and the
        others follow (SampleSolver.solve). Raises as torques does, and for a singular
        inertia or accelerations that are not finite."""
        record, new_state = self.serial.solve(state, q, qd, tau, sample, project)
        return checked(self.mechanism, cast(ForwardRecord, record), qd, tau, sample), new_state

    def again(self, state: State, qd: Sequence[float], tau: Sequence[float],
              sample: Optional[int] = None) -> ForwardRecord:
        """The ForwardRecord at the closed pose of ``state`` with other rates and efforts
        (nothing is solved: the pose is closed)."""
        m, q = self.mechanism, state[0]
        record = self.serial.whole(q, [q[j] for j in m.active_index], qd, tau)
        return checked(m, record, qd, tau, sample)

    def many(self, state: State, q: np.ndarray, qd: np.ndarray, tau: np.ndarray
             ) -> Tuple[np.ndarray, State]:
        """(accelerations (N, M), new state) of N > 1 samples; raises for the first sample
        that cannot be served (the warm start is then the caller's, unchanged)."""
        m = self.mechanism
        _, refused = check_values(m, self.serial.wrapping, q, qd, tau, False, labels=LABELS)
        if refused:
            raise refused[min(refused)]
        with np.errstate(all='ignore'):
            record, _, ok, errors, new_state = self.batch.positions(state, q, 'raise',
                                                                    qd=qd, qdd=tau)
        bad = np.flatnonzero(~(ok & (record.inertia_condition <= INERTIA_CONDITION_LIMIT) &
                               np.isfinite(record.accelerations).all(axis=1)))
        if bad.size:
            i = int(bad[0])
            if errors[i] is not None:
                raise errors[i]
            one = ForwardRecord(*(field[i] for field in record))
            checked(m, one, qd[i], tau[i], i)
            raise AssertionError(f'sample {i} failed no check')     # pragma: no cover
        return np.array(record.accelerations), new_state


def checked(mechanism: Mechanism, record: ForwardRecord, qd: Sequence[float],
            tau: Sequence[float], sample: Optional[int]) -> ForwardRecord:
    """``record``, once its inertia is known not singular and its accelerations finite."""
    if not record.inertia_condition <= INERTIA_CONDITION_LIMIT:
        raise singular_inertia(mechanism, float(record.inertia_condition), sample)
    if not all(map(math.isfinite, record.accelerations)):
        raise not_finite(qd, tau, sample)
    return record


def singular_inertia(mechanism: Mechanism, condition: float, sample: Optional[int]
                     ) -> SingularConfigurationError:
    """SingularConfigurationError for an inertia matrix that cannot be solved (its condition
    infinite where the factorisation gave NaN: no mass at all)."""
    where = '' if sample is None else f'sample {sample}: '
    if math.isnan(condition):
        condition = math.inf
    return SingularConfigurationError(
        f'{where}singular inertia: the inertia of {mechanism.active_joints} in the '
        f'independent coordinates has condition {condition:.3g} (more than '
        f'{INERTIA_CONDITION_LIMIT:.3g}): some motion of the mechanism moves (almost) no '
        f'mass, so no finite acceleration answers the efforts', condition, sample)


def not_finite(qd: Sequence[float], tau: Sequence[float], sample: Optional[int]
               ) -> CogIdError:
    """SetpointError(reason='out_of_range') for finite input whose accelerations overflow."""
    where = '' if sample is None else f'sample {sample}: '
    largest = max([abs(x) for x in list(qd) + list(tau)] or [0.0])
    return SetpointError(
        f'{where}the accelerations are not finite here: the velocities or efforts (largest '
        f'magnitude {largest:.3g}) are too large to compute with', sample=sample,
        reason='out_of_range')
