"""The closed poses that the per-pose queries of InverseDynamics are computed at.

solve_positions, cog_poses, cog_jacobians, cog_drifts and equation_of_motion evaluate parts
of eqs. (1)-(7) (pipeline.py) at the closed poses of one sample or a batch: solved here from
the warm start like torques (sample_solve.py, batch.py), then evaluated once more by the lane
code, on floats or on (N,) lanes. Nothing is kept: the solver moves its warm start only
when it accepts a result (InverseDynamics._moved_to).
"""
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from ..closure import closure
from ..closure.joint_motion import velocity_basis
from ..errors import SingularConfigurationError
from ..linalg import spatial as sp
from ..linalg.lanes import columns
from ..value_types import LaneMatrix
from .inputs import check_values, setpoint_arrays

if TYPE_CHECKING:
    from ..closure.continuation import State
    from ..model.mechanism import Mechanism
    from .batch import Batch
    from .sample_solve import SampleSolver


class Poses(NamedTuple):
    positions: np.ndarray      # every joint of mechanism.joints: (n_joints,) or (N, n_joints)
    pose: closure.ClosureSolution  # on floats or (N,) lanes
    basis: list                # velocity basis V (list over joints)
    rates: list                # thetadot as lanes
    ops: type                  # spatial.ScalarOps or ArrayOps
    state: tuple               # the warm start there
    qd: np.ndarray             # (N, M), for messages
    single: bool


def pose_of(mechanism: 'Mechanism',
            positions: np.ndarray) -> tuple[closure.ClosureSolution, LaneMatrix]:
    """(closure solution, velocity basis) of N poses (N, n_joints) on (N,) lanes, for the
    lane code of eqs. (1)-(4); nothing solved."""
    pose = closure.evaluate(mechanism.model, columns(positions), mechanism.free_joints,
                            sp.ArrayOps)
    return pose, velocity_basis(mechanism, pose)


class PoseSolver:
    """The closed poses of one mechanism (as written) for its solver's per-sample and batch
    paths."""

    def __init__(self, mechanism: 'Mechanism', sample_solver: 'SampleSolver',
                 batch: 'Batch') -> None:
        self.mechanism = mechanism
        self.serial, self.batch = sample_solver, batch

    def at(self, state: 'State', q: Any, qd: Any, solved: bool = False,
           velocities: bool = False) -> Poses:
        """The closed poses (Poses) of one sample or a batch ``q`` with rates ``qd`` from the
        warm start ``state``, of the mechanism as written (of its solver form with
        ``solved``). ``velocities``: the velocity basis is used, so a chain of revolutes
        solved as a spherical joint (spherical_chains.py) must be away from its gimbal lock,
        where the joints as written have no rates."""
        solver = self.mechanism.solver_mechanism
        m = solver if solved else self.mechanism
        q, qd, _, single = setpoint_arrays(m, q, qd, None)
        _, errors = check_values(m, self.serial.wrapping, q, qd, qd, single)
        if errors:
            raise errors[min(errors)]
        n = len(m.joints)
        if single:
            state = self.serial.solve(state, q[0].tolist())[1]
            at = m.coordinates_as_written(state[0]).tolist()
            pose = closure.evaluate(m.model, at, m.free_joints, sp.ScalarOps)
            basis = state[1] if solver is m else velocity_basis(m, pose)
            at = Poses(np.array(at[:n]), pose, basis, qd[0].tolist(), sp.ScalarOps, state,
                       qd, single)
        else:
            with np.errstate(all='ignore'):
                _, positions, _, _, state = self.batch.positions(state, q, 'raise')
                coordinates = m.coordinates_as_written(positions)
                pose, basis = pose_of(m, coordinates)
            at = Poses(coordinates[:, :n], pose, basis, columns(qd), sp.ArrayOps, state, qd,
                       single)
        if velocities and solver is not m:
            self.away_from_locks(at)
        return at

    def away_from_locks(self, at: Poses) -> None:
        """SingularConfigurationError where the mechanism as written is singular at a pose
        its solver form is not: a chain of three revolutes at its gimbal lock, whose rates
        (and so the per-link quantities of the links as written) are not defined there."""
        m = self.mechanism
        with np.errstate(all='ignore'):
            condition = np.atleast_1d(np.asarray(at.pose.lsq.condition_number(), np.float64))
        bad = np.flatnonzero(~(condition <= m.max_condition_number))
        if bad.size:
            k = int(bad[0])
            chains = '; '.join(', '.join(chain.joints) for chain in m.spherical_chains)
            raise SingularConfigurationError(
                f'{"" if at.single else f"sample {k}: "}the joints as written are singular '
                f'here (closure condition number {condition[k]:.3g} > '
                f'mechanism.max_condition_number {m.max_condition_number:g}): a chain of three '
                f'revolute joints solved as a spherical joint ({chains}) is at or near its '
                f'gimbal lock, where its angles have no rates and the per-link quantities of '
                f'its links as written are not defined; torques and equation_of_motion are '
                f'(they are solved with the spherical joint)',
                condition[k], None if at.single else k)
