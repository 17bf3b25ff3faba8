"""ActuatorSpaceSolver: the solver of actuator space (inverse_dynamics.py's InverseDynamics
adds joint space to it), a thin face over the modules that do the work.

    one sample   inputs.py -> sample_solve.py (continuation, Newton) -> kernels.py
    N samples    inputs.py -> batch.py (arrays, checked by the serial rules)
    per pose     poses.py (the closed poses of cog_poses, ..., equation_of_motion)
    the maths    pipeline.py: eqs. (1)-(7) at a closed pose, run by every path

Successive calls keep the assembly branch: each is warm-started from the previous one.
"""
import math
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union, cast

import numpy as np

from ..closure.continuation import State
from ..closure.joint_motion import active_velocity_map, combine
from ..dynamics.cog_jacobian import cog_poses
from ..dynamics.pipeline import cog_jacobians_at, cog_motion, equation_of_motion
from ..errors import MechanismConfigError, SetpointError
from ..linalg import spatial as sp
from ..linalg.lanes import stacked
from ..model.mechanism import Mechanism
from ..native.kernels import kernels_for
from .batch import Batch, Evaluation
from .forward_solve import LABELS, ForwardSolver
from .inputs import out_of_range, rates, setpoint_arrays, setpoints
from .poses import Poses, PoseSolver
from .sample_solve import SampleSolver

#: accuracy_factor of close_to_rounding: a relative error of 1e-13 at the default tolerance
ROUNDING = 1e-3

ArrayLike = Union[float, Sequence[float], Sequence[Sequence[float]], np.ndarray]


class ActuatorSpaceSolver:
    """Active-joint torques of a closed-link mechanism by per-link COG Jacobians, every array
    in actuator space (the public face is inverse_dynamics.InverseDynamics).

    All arrays are in ``mechanism.active_joints`` order; shapes (M,) for one sample or
    (N, M) for N samples. Angles are never wrapped. ``backend``: 'auto' (default),
    'reference' (the lane code on floats, nothing traced) or 'python' (traced
    straight-line kernels); all give the same numbers (kernels.py).
    """

    #: largest motion of any joint in one continuation step: rad, or for prismatic joints
    #: this times the mechanism's length scale (continuation.py); longer moves are followed
    #: in steps so that the solver stays on the assembly branch it is on. Read at construction.
    continuation_step = 0.1
    #: whether one sample (of torques, sample_torques, forward_dynamics) with an actuator
    #: outside its position limits (joints.<name>.lower / upper) is refused (SetpointError
    #: 'limit'); False serves it (a measured pose: the robot is where it is, and its
    #: controller must act there). Batches are checked against the limits either way.
    check_position_limits = True

    def __init__(self, mechanism: Mechanism, backend: str = 'auto') -> None:
        if not isinstance(mechanism, Mechanism):
            raise MechanismConfigError(
                'mechanism', f'must be a cog_id_ros.Mechanism (from Mechanism.from_params_file '
                             f'or from_parameters), got {type(mechanism).__name__}')
        self.mechanism = mechanism
        # what is solved: the mechanism, or its form with chains of three revolutes as
        # spherical joints (spherical_chains.py); outputs show the joints as written
        self._solved = solved = mechanism.solver_mechanism
        kernels = kernels_for(solved, backend)
        self._backend = kernels.name
        self._serial = SampleSolver(solved, kernels, self.continuation_step)
        self._rows_memo: dict = {}      # _solved_rows of each set of rows asked for
        #: the primary actuators' active joints, None where they are all in that order
        self._primary_order = None if list(solved.primary) == list(
            range(len(solved.active_joints))) else list(solved.primary)
        self._serial.refine = True      # closed past the tolerance where conditioning needs it
        self._batch = Batch(solved, self._serial, mechanism.joints_at)
        self._poses = PoseSolver(mechanism, self._serial, self._batch)
        self._kernels = kernels
        self._forward: Optional[ForwardSolver] = None     # made on first use
        self.reset()

    def close_to_rounding(self) -> None:
        """From now on close every pose past the closure tolerance as far as rounding
        allows (one Newton increment more a call where it helps): positions exact to about
        1e-15 rather than the tolerance's 1e-9 (the transmission's maps, transmission/)."""
        self._serial.accuracy_factor = ROUNDING
        if self._forward is not None:
            self._forward.serial.accuracy_factor = ROUNDING

    @property
    def backend(self) -> str:
        """The kernels this solver uses: 'native', 'python' or 'reference'."""
        return self._backend

    def reset(self) -> None:
        """Forget the previous calls: the next one starts from the assembled initial_positions."""
        m = self._solved
        start = list(m.assembled_coordinates)
        q, record, _, _ = self._serial.close(start, [start[j] for j in m.active_index],
                                             self._serial.zeros, self._serial.zeros)
        self._state: State = (list(q), self._serial.basis(record))

    def torques(self, q: ArrayLike, qd: Optional[ArrayLike] = None,
                qdd: Optional[ArrayLike] = None) -> np.ndarray:
        """tau = H(q) qdd + B(q, qd) for the active joints: (M,) or (N, M).

        Raises ClosureError, SingularConfigurationError or SetpointError for the first sample
        that cannot be served (``.sample`` is its index); the warm start is then unchanged.
        """
        q, qd, qdd, single = setpoints(self.mechanism, self._serial.wrapping, q, qd, qdd,
                                       self.check_position_limits)
        if single:
            return np.array(self._serve_one(q, qd, qdd))
        return self.evaluate(q, qd, qdd).torques

    def forward_dynamics(self, q: ArrayLike, qd: Optional[ArrayLike],
                         tau: Optional[ArrayLike]) -> np.ndarray:
        """The accelerations (M,) or (N, M) the efforts ``tau`` (N m or N, active_joints
        order) produce at positions ``q`` and rates ``qd``, with gravity: eq. (7) solved for
        qdd (docs/simulation.md). ``qd``, ``tau``: zeros when None.

        The pose is solved as :meth:`torques` solves it (warm start, branch, errors); a
        redundant mechanism moves by the generalized force of its efforts alone.
        SingularConfigurationError also for an inertia that cannot be solved.
        """
        positions, rates_in, efforts, single = setpoints(
            self.mechanism, self._serial.wrapping, q, qd, tau, self.check_position_limits,
            labels=LABELS)
        if self._forward is None:       # (its kernels are loaded, or built, now)
            self._forward = ForwardSolver(self._solved, self._kernels, self.continuation_step,
                                          self.mechanism.joints_at)
            self._forward.serial.refine = True      # (as the torques' solver)
            self._forward.serial.accuracy_factor = self._serial.accuracy_factor
        if single:
            record, self._state = self._forward.one(self._state, positions, rates_in, efforts)
            return np.array(record.accelerations)
        if len(positions) == 0:
            return np.zeros(np.shape(positions))
        if len(positions) == 1:
            record, self._state = self._forward.one(
                self._state, *(x[0].tolist() for x in (positions, rates_in, efforts)))
            return np.array([record.accelerations])
        accelerations, self._state = self._forward.many(self._state, positions, rates_in,
                                                        efforts)
        return accelerations

    def sample_torques(self, q: Sequence[float], qd: Optional[Sequence[float]] = None,
                       qdd: Optional[Sequence[float]] = None) -> list:
        """One sample at control rate: three sequences of M floats in, a list of M torques out.

        The same numbers, state and errors as :meth:`torques` on one sample, without the
        numpy round trip (cog_id_node calls this for every setpoint).
        """
        q, qd, qdd, single = setpoints(self.mechanism, self._serial.wrapping, q, qd, qdd,
                                       self.check_position_limits)
        if not single:
            raise SetpointError(f'sample_torques takes one sample (one number per active '
                                f'joint), got shape {np.shape(q)}: use torques() for a batch')
        return self._serve_one(q, qd, qdd)

    def evaluate(self, q: ArrayLike, qd: Optional[ArrayLike] = None,
                 qdd: Optional[ArrayLike] = None, on_invalid: str = 'raise') -> Evaluation:
        """Torques with per-sample status (an Evaluation). on_invalid='skip' marks samples that
        cannot be served as invalid instead of raising; the others are computed as usual."""
        if on_invalid not in ('raise', 'skip'):
            raise SetpointError(f"on_invalid must be 'raise' or 'skip', got {on_invalid!r}")
        q, qd, qdd, _ = setpoint_arrays(self.mechanism, q, qd, qdd)
        if len(q) == 1:
            result, self._state = self._batch.evaluate_one(self._state, q, qd, qdd, on_invalid)
            return result
        if len(q) == 0:
            m, empty = self.mechanism, np.zeros(q.shape)
            return Evaluation(empty, np.zeros(0, bool), [], np.zeros((0, len(m.joints))),
                              empty, np.zeros(0), np.zeros(0))
        result, self._state = self._batch.evaluate(self._state, q, qd, qdd, on_invalid)
        return result

    def solve_positions(self, q: ArrayLike) -> np.ndarray:
        """Every joint coordinate (mechanism.joints order): (n_joints,) or (N, n_joints)."""
        at = self._poses.at(self._state, q, None)
        return self._moved_to(at, at.positions)

    def solve_positions_by_name(self, q: ArrayLike) -> Dict[str, Union[float, np.ndarray]]:
        """:meth:`solve_positions` keyed by joint name: {name: coordinate} for every joint of
        mechanism.joints (a float for one sample, an (N,) array for a batch); the same
        numbers, warm start and errors."""
        positions = self.solve_positions(q)
        if positions.ndim == 1:
            return {name: float(x) for name, x in zip(self.mechanism.joints, positions)}
        return {name: positions[:, j] for j, name in enumerate(self.mechanism.joints)}

    def last_pose(self, qd: Optional[Sequence[float]] = None
                  ) -> Tuple[List[float], Optional[List[float]]]:
        """(q, qdot) of the closed pose the solver is at, read-only: nothing is solved again.

        ``q``: every joint coordinate (mechanism.joints order, a list of floats) of the last
        pose a call reached, which the next call starts from: after :meth:`sample_torques` or
        :meth:`torques` on one sample, the pose its torques were computed at; after
        :meth:`reset`, the assembled initial_positions. A call that raised leaves it where it
        was. ``qdot``: with ``qd`` (M rates in active_joints order), the rates of every joint
        there, qdot = S qd (docs/api.md: the joint-rate map S of redundant actuation); None
        without ``qd``.
        """
        m, (q, basis) = self.mechanism, self._state
        if qd is None:
            return m.joints_at(q)[0].tolist(), None
        rates_in = rates(m, qd)
        qdot: Any = combine(active_velocity_map(self._solved, basis, sp.ScalarOps), rates_in)
        positions, qdot = m.joints_at(q, qdot)
        if not np.isfinite(qdot).all():
            raise out_of_range(rates_in, [], None)
        return positions.tolist(), qdot.tolist()

    def closed_pose(self, q: Sequence[float], with_rates: bool = False,
                    rows: Optional[Sequence[int]] = None,
                    limits: Optional[bool] = None,
                    with_positions: bool = True) -> Tuple[List[float], Any]:
        """One sample at control rate: (every joint's position, mechanism.joints order; with
        ``with_rates`` the joint-rate map S (n_joints, M) there, else None) at the closed
        pose of the M actuator positions ``q``. The same numbers as :meth:`solve_positions`
        and :meth:`joint_rate_map` of one sample, through the lean sample path (no second
        evaluation of the pose); the warm start moves there. ``rows`` (joint indices): only
        those rows of S, as lists of floats where the joints are the solver's own
        coordinates (:meth:`_solved_rows`: the basis's rows as they are). ``limits``: the
        actuators' position limits checked (default: check_position_limits). Without
        ``with_positions`` the positions are [] (the joints read back from the pose, balls
        written as three revolutes, are not: the rates alone are wanted)."""
        m = self.mechanism
        zeros = self._serial.zeros          # (lists: a control loop's fast way in)
        target, _, _, single = setpoints(m, self._serial.wrapping, q, zeros, zeros,
                                         self.check_position_limits if limits is None
                                         else limits)
        if not single:
            raise SetpointError(f'closed_pose takes one sample (one number per active '
                                f'joint), got shape {np.shape(q)}')
        _, state = self._serial.solve(self._state, target)
        coordinates, n = state[0], len(m.joints)
        chains = m.spherical_chains          # (joints read back from the pose: the kernel)
        positions = [] if not with_positions else m.joints_at(coordinates)[0].tolist() \
            if chains else list(coordinates[:n])
        s: Any = None
        solved_rows = self._solved_rows(rows) if with_rates and rows is not None else None
        if solved_rows is not None:
            s = _basis_rows(state[1], self._primary_order, solved_rows, len(target))
            if not math.isfinite(sum(map(sum, s))):      # (a NaN or inf anywhere)
                raise out_of_range(list(target), [], None)
        elif with_rates:
            solved = active_velocity_map(self._solved, state[1], sp.ScalarOps)
            s = np.column_stack([cast(np.ndarray, m.joints_at(coordinates,
                                                             [row[k] for row in solved])[1])
                                 for k in range(len(target))]) if chains else \
                np.array(solved[:n], dtype=float)
            if not np.isfinite(s).all():
                raise out_of_range(list(target), [], None)
            if rows is not None:
                s = s[list(rows)]
        self._state = state
        return positions, s

    def rate_scale(self) -> float:
        """The size (Frobenius norm) of the velocity basis at the pose the solver is at:
        every coordinate's rate per unit rate of the primary actuators, over all of them."""
        return math.hypot(*[math.hypot(*row) for row in self._state[1]])

    def _solved_rows(self, rows: Sequence[int]) -> Optional[List[int]]:
        """The solver's coordinates of joints ``rows`` (mechanism.joints indices) where each
        is one of its joints as written (not in a chain read back) and the mechanism is not
        redundant: their rates are the velocity basis's rows; else None."""
        key = tuple(rows)
        if key not in self._rows_memo:
            solved, names = self._solved, self.mechanism.joints
            self._rows_memo[key] = None if solved.is_redundant or not all(
                names[j] in solved.joint_index for j in rows) else \
                [solved.joint_index[names[j]] for j in rows]
        return self._rows_memo[key]

    def joint_rate_map(self, q: ArrayLike) -> np.ndarray:
        """S (n_joints, M), qdot = S thetadot, at the closed pose of ``q`` (M actuator
        positions): every joint's rate (mechanism.joints order) per actuator rate; (N,
        n_joints, M) for N samples, solved one after the other from the warm start (the
        per-sample rule). Redundant actuation: the map of docs/api.md (torque_weights)."""
        positions, _, _, single = setpoint_arrays(self.mechanism, q, None, None)
        # (the actuators' limits checked on every sample, as the per-pose queries do)
        maps = [self.closed_pose(row.tolist(), with_rates=True, limits=True)[1]
                for row in positions]
        return maps[0] if single else np.array(maps).reshape(len(positions), -1,
                                                             positions.shape[1])

    def cog_poses(self, q: ArrayLike) -> Tuple[np.ndarray, np.ndarray]:
        """g_i (eq. 1): (positions (..., n_links, 3), rotations (..., n_links, 3, 3))."""
        at = self._poses.at(self._state, q, None)
        cogs = cog_poses(self.mechanism, at.pose.frames)
        positions = self._moved_to(at, stacked([list(c) for c, _ in cogs]), keep=True)
        rotations = self._moved_to(at, stacked([list(r) for _, r in cogs]))
        return positions, rotations.reshape(rotations.shape[:-1] + (3, 3))

    def cog_jacobians(self, q: ArrayLike) -> np.ndarray:
        """G_i (eq. 3): (n_links, 6, M) or (N, n_links, 6, M); rows vx vy vz wx wy wz of the
        COG (linear) and the link (angular), base frame."""
        at = self._poses.at(self._state, q, None, velocities=True)
        _, _, jac = cog_jacobians_at(self.mechanism, at.pose, at.basis, at.ops)
        return self._moved_to(at, stacked([[[gv[r] for gv, _ in cols] for r in range(3)] +
                                          [[gw[r] for _, gw in cols] for r in range(3)]
                                          for cols in jac]))

    def cog_drifts(self, q: ArrayLike, qd: ArrayLike) -> np.ndarray:
        """Gdot_i thetadot (eq. 4): (n_links, 6) or (N, n_links, 6): COG acceleration and link
        angular acceleration when thetaddot = 0."""
        at = self._poses.at(self._state, q, qd, velocities=True)
        with np.errstate(all='ignore'):          # overflow is reported by _moved_to
            _, _, _, drifts = cog_motion(self.mechanism, at.pose, at.basis, at.rates, at.ops)
        return self._moved_to(at, stacked([list(a) + list(alpha) for a, alpha in drifts]))

    def equation_of_motion(self, q: ArrayLike, qd: Optional[ArrayLike] = None
                           ) -> Tuple[np.ndarray, np.ndarray]:
        """H (M, M) and B (M,) of eq. (7), tau = H qdd + B; batch: (N, M, M), (N, M)."""
        # (of the links as solved: the same H and B)
        at = self._poses.at(self._state, q, qd, solved=True)
        with np.errstate(all='ignore'):          # overflow is reported by _moved_to
            h, b = equation_of_motion(self._solved, at.pose, at.basis, at.rates, at.ops)
        return self._moved_to(at, stacked(h), keep=True), self._moved_to(at, stacked(b))

    # --- helpers ------------------------------------------------------------------------

    def _serve_one(self, target: Any, qd: Any,
                   qdd: Any) -> list[float]:
        """Torques of one well-formed sample (lists of floats); the warm start moves on."""
        record, self._state = self._serial.solve_torques(self._state, target, qd, qdd)
        return list(record.torques)

    def _moved_to(self, at: Poses, values: np.ndarray, keep: bool = False) -> np.ndarray:
        """``values`` computed at ``at``, once known to be finite: the warm start moves to
        ``at`` (unless ``keep``: more values follow). SetpointError (out_of_range) naming the
        first sample where they are not finite."""
        if not np.isfinite(values).all():
            bad = 0 if at.single else \
                int(np.flatnonzero(~np.isfinite(values.reshape(len(values), -1)).all(axis=1))[0])
            raise out_of_range(at.qd[bad].tolist(), [0.0] * at.qd.shape[1],
                               None if at.single else bad)
        if not keep:
            self._state = at.state
        return values


def _basis_rows(basis: Sequence[Sequence[float]], order: Optional[Sequence[int]],
                rows: Sequence[int], m: int) -> list[list[float]]:
    """Rows ``rows`` of S from the velocity basis of a non-redundant mechanism: the basis's
    column k is the rate per unit rate of primary actuator k, active joint order[k] (None:
    active joint k)."""
    if order is None:
        return [list(basis[j]) for j in rows]
    out = []
    for j in rows:
        row, b = [0.0] * m, basis[j]
        for k, a in enumerate(order):
            row[a] = b[k]
        out.append(row)
    return out
