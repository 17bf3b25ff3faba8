"""Transmission: the exact map between actuator space and joint space, both ways.

A mechanism that names ``mechanism.joint_space`` (model/joint_space.py) has two sets of
independent coordinates: the motors theta (active_joints, M) and the joints a controller
commands q (joint_space, D = its degrees of freedom). Both close the same loops, so the map
is two solvers of the same mechanism, each solving the loops with one set held:

    actuators  the mechanism as written (ActuatorSpaceSolver): theta -> every joint
    joints     the same mechanism with active_joints := joint_space: q -> every joint

and their joint-rate maps S (qdot_all = S rates, ActuatorSpaceSolver.joint_rate_map):

    J = dq/dtheta      the joint-space rows of the actuators' S       (D, M)
    K = dtheta/dq      the motors' rows of the joints' S              (M, D)

Power is kept, tau_m . theta_dot = tau_q . q_dot, so efforts map by the transposes:
tau_q = K^T tau_m; tau_m = J^T tau_q, which for a redundant mechanism (M > D) is the
effort of least weighted norm (mechanism.torque_weights) among those that make tau_q, as
the actuators' S is the weighted map (docs/api.md). The exact motor torques of a joint-space
motion are the joints' solver's torques (the linkage's inertia and gravity included, as
every torque here) carried to the motors the same way, and forward dynamics in joint space
is the joints' solver driven by K^T tau_m. No map is inverted here: where one set of
joints cannot drive the other (a rod in line with its crank), the solver that would need
it finds its loops singular (mechanism.max_condition_number) and the error names both
sets. Every call keeps each solver's assembly branch (warm starts), a batch follows the
per-sample rule.
"""
import math
import numbers
import operator
from typing import Any, Literal, Optional, cast

import numpy as np

from ..errors import (
    ClosureError,
    MechanismConfigError,
    SetpointError,
    SingularConfigurationError,
)
from ..model.joint_space import PARAMETER, seen_condition
from ..model.mechanism import Mechanism
from ..solve.actuator_space import ActuatorSpaceSolver, ArrayLike


def joint_space_parameters(mechanism: Any) -> dict:
    """The parameters of ``mechanism`` driven at its joint space: its assembled pose pinned
    (settled_parameters), active_joints := joint_space."""
    params = mechanism.settled_parameters()
    for name in ('mechanism.joint_space', 'mechanism.torque_weights'):
        params.pop(name, None)
    params['mechanism.active_joints'] = list(mechanism.joint_space)
    return params


class Transmission:
    """The map between ``mechanism.active_joints`` (actuator space, M) and
    ``mechanism.joint_space`` (joint space, D): positions, velocities, Jacobian and efforts,
    both ways. Shapes: one sample (M,) or (D,); N samples (N, M) or (N, D). Its two solvers
    are its own (their warm starts move with its calls only), closing every pose to
    rounding (ActuatorSpaceSolver.close_to_rounding)."""

    def __init__(self, mechanism: Any, backend: str = 'auto') -> None:
        if not getattr(mechanism, 'joint_space', None):
            raise MechanismConfigError(
                PARAMETER, f'{mechanism.name} names no joint space: give mechanism.joint_space '
                           f'(the {mechanism.dof} joints a controller commands, e.g. the knee, '
                           'the ankle pitch and roll)')
        self.mechanism = mechanism
        self.joint_space = list(mechanism.joint_space)
        self.active_joints = list(mechanism.active_joints)
        self.actuators = ActuatorSpaceSolver(mechanism, backend)
        try:
            self.joint_mechanism = Mechanism(joint_space_parameters(mechanism))
        except MechanismConfigError as exc:
            raise MechanismConfigError(
                PARAMETER, 'the mechanism cannot be driven at its joint space: '
                + str(exc).replace('mechanism.active_joints', 'mechanism.joint_space')) from None
        self.joints = ActuatorSpaceSolver(self.joint_mechanism, self.actuators.backend)
        self.joints.check_position_limits = False       # the joints' limits are not motors'
        for solver in (self.actuators, self.joints):
            solver.close_to_rounding()
        self._q = [mechanism.joint_index[name] for name in self.joint_space]
        self._theta = list(mechanism.active_index)
        self.redundant = mechanism.is_redundant
        self._blocks = _MotorRows(self.joint_space, self.active_joints)
        self._renames = _NamedSingular(self)

    # --- positions ----------------------------------------------------------------------

    def to_joint_space(self, theta: ArrayLike) -> np.ndarray:
        """q (D,) or (N, D) of the motors' positions theta (M,) or (N, M)."""
        with self._named():
            if _one(theta):
                return _rows(self.actuators.closed_pose(_floats(theta))[0], self._q)
            return self.actuators.solve_positions(theta)[..., self._q]

    def to_actuator_space(self, q: ArrayLike) -> np.ndarray:
        """theta (M,) or (N, M) of the joint-space positions q (D,) or (N, D): the
        consistent motor positions (every motor, a redundant one too)."""
        with self._named():
            if _one(q):
                return _rows(self.joints.closed_pose(_floats(q))[0], self._theta)
            return self.joints.solve_positions(q)[..., self._theta]

    def joint_state(self, theta: ArrayLike, theta_dot: Optional[ArrayLike] = None
                    ) -> tuple[np.ndarray, Optional[np.ndarray]]:
        """One sample: (every joint's position, mechanism.joints order; with ``theta_dot``
        every joint's rate S theta_dot, else None) at the motors' positions theta, from one
        solve (what a joint_states message of the whole mechanism holds)."""
        with self._named():
            positions, s = self.actuators.closed_pose(_floats(theta),
                                                      with_rates=theta_dot is not None)
        if theta_dot is None:
            return np.array(positions), None
        return np.array(positions), _times(s, theta_dot)

    # --- velocities -----------------------------------------------------------------------

    def jacobian(self, theta: ArrayLike) -> np.ndarray:
        """J = dq/dtheta (D, M) at theta, or (N, D, M)."""
        with self._named():
            if _one(theta):
                return np.array(self._rows_at(self.actuators, theta, self._q), dtype=float)
            return self.actuators.joint_rate_map(theta)[..., self._q, :]

    def inverse_jacobian(self, q: ArrayLike) -> np.ndarray:
        """K = dtheta/dq (M, D) at the joint-space position q, or (N, M, D)."""
        with self._named():
            if _one(q):
                return np.array(self._rows_at(self.joints, q, self._theta), dtype=float)
            return self.joints.joint_rate_map(q)[..., self._theta, :]

    def joint_velocities(self, theta: ArrayLike, theta_dot: ArrayLike) -> np.ndarray:
        """q_dot = J(theta) theta_dot: (D,) or (N, D)."""
        if _one(theta):
            return _times(self._rows_at(self.actuators, theta, self._q), theta_dot)
        return _apply(self.jacobian(theta), theta_dot)

    def actuator_velocities(self, q: ArrayLike, q_dot: ArrayLike) -> np.ndarray:
        """theta_dot = K(q) q_dot: (M,) or (N, M), the motors' rates of a joint-space motion."""
        if _one(q):
            return _times(self._rows_at(self.joints, q, self._theta), q_dot)
        return _apply(self.inverse_jacobian(q), q_dot)

    # --- efforts --------------------------------------------------------------------------

    def actuator_efforts(self, theta: ArrayLike, tau_q: ArrayLike) -> np.ndarray:
        """tau_m = J^T tau_q (M,) or (N, M): the motors' share of joint-space efforts at
        theta, the linkage massless (its own inertia and gravity: :meth:`torques`);
        redundant, the one of least weighted norm."""
        if _one(theta):
            rows = self._rows_at(self.actuators, theta, self._q)
            return _times([list(column) for column in zip(*rows)], tau_q)
        return _apply(np.swapaxes(self.jacobian(theta), -1, -2), tau_q)

    def joint_efforts(self, theta: ArrayLike, tau_m: ArrayLike) -> np.ndarray:
        """tau_q = K^T tau_m (D,) or (N, D): the joint-space efforts the motors' efforts make
        at theta (the linkage massless). One sample: K from the motion at theta alone
        (:meth:`_inverse_at`); N samples: the same, one after the other."""
        if _one(theta) and not self.redundant:
            rows = self._rows_at(self.actuators, theta, self._q)
            v = _vector(tau_m, len(self.active_joints))
            tau_q, size = self._blocks.efforts(rows, v)
            # seen_condition of the joint space is at most scale / least (the basis's
            # primary columns are unit rates), and 1 / least = |J^-1|_2 <= |J^-1|_F:
            # well within the bound, K = J^-1 at once
            if self.actuators.rate_scale() * size <= self.mechanism.max_condition_number:
                return _finite(tau_q, v)
        if not _one(theta):
            return self._joint_efforts_each(theta, tau_m)
        with self._named():
            k = self._inverse_at(_rate_map(self.actuators, theta))
        return _apply(np.swapaxes(k, -1, -2), tau_m)

    def _joint_efforts_each(self, theta: ArrayLike, tau_m: ArrayLike) -> np.ndarray:
        """N samples of :meth:`joint_efforts`, one after the other from the warm start (the
        per-sample rule: K at each theta on the motors' branch; through q, the joints'
        solver took the other theta of the same q past a toggle, and the sign with it)."""
        thetas, efforts = np.asarray(theta, dtype=float), np.asarray(tau_m, dtype=float)
        if efforts.shape != thetas.shape:
            raise _shape(thetas.shape[-1], efforts.shape, len(thetas))
        out = []
        for i, (one, tau) in enumerate(zip(thetas, efforts)):
            try:
                out.append(self.joint_efforts(one, tau))
            except SingularConfigurationError as exc:
                raise self._singular(SingularConfigurationError(
                    'singular', exc.condition_number, i)) from None
            except SetpointError as exc:
                raise SetpointError(f'sample {i}: {exc}', i, exc.reason or 'malformed') from None
        return np.array(out, dtype=float).reshape(len(thetas), len(self._q))

    def _inverse_at(self, s: np.ndarray) -> np.ndarray:
        """K = dtheta/dq (M, D) from the joint-rate map S (n_joints, M) of one pose: an
        orthonormal basis U of the motions (S's range: D columns) gives K = U_a U_q^-1;
        refused as singular where the joint space sees too little of the motion
        (:func:`.joint_space.seen_condition`, as mechanism.joint_space is checked at load)."""
        u = np.linalg.svd(s, full_matrices=False)[0][:, :len(self._q)]
        u_q = u[self._q]
        condition = seen_condition(u_q)
        if not condition <= self.mechanism.max_condition_number:
            raise self._singular(SingularConfigurationError('singular', condition))
        return u[self._theta] @ np.linalg.inv(u_q)

    # --- dynamics in joint space ----------------------------------------------------------

    def torques(self, q: ArrayLike, qd: Optional[ArrayLike] = None,
                qdd: Optional[ArrayLike] = None) -> np.ndarray:
        """The exact motor torques (M,) or (N, M) of the joint-space motion (q, qd, qdd):
        the joint-space efforts of the whole mechanism (eq. 7 with the joint space as its
        independent coordinates), carried to the motors, tau_m = J^T tau_q (redundant: the
        least weighted norm)."""
        with self._named():
            tau_q = self.joints.torques(q, qd, qdd)
            theta = self.joints.solve_positions(q)[..., self._theta]
            jac = self.actuators.joint_rate_map(theta)[..., self._q, :]
        return _apply(np.swapaxes(jac, -1, -2), tau_q)

    def forward_dynamics(self, q: ArrayLike, qd: Optional[ArrayLike],
                         tau_m: Optional[ArrayLike]) -> np.ndarray:
        """The joint-space accelerations (D,) or (N, D) the motors' efforts tau_m produce at
        the joint-space state (q, qd), with gravity: the joints' forward dynamics under
        tau_q = K^T tau_m."""
        with self._named():
            k = self.joints.joint_rate_map(q)[..., self._theta, :]
            tau = np.zeros(k.shape[:-2] + k.shape[-2:-1]) if tau_m is None else tau_m
            tau_q = _apply(np.swapaxes(k, -1, -2), tau)
            return self.joints.forward_dynamics(q, qd, tau_q)

    # --- helpers --------------------------------------------------------------------------

    def _rows_at(self, solver: ActuatorSpaceSolver, x: ArrayLike, rows: list) -> Any:
        """Rows ``rows`` of the joint-rate map S of one sample (lists of floats)."""
        with self._named():
            return solver.closed_pose(_floats(x), with_rates=True, rows=rows,
                                      with_positions=False)[1]

    def _singular(self, error: SingularConfigurationError) -> SingularConfigurationError:
        where = '' if error.sample is None else f' at sample {error.sample}'
        return SingularConfigurationError(
            f"the transmission between the motors ({', '.join(self.active_joints)}) and the "
            f"joint space ({', '.join(self.joint_space)}) is singular{where} (condition number "
            f'{error.condition_number:.3g}, over mechanism.max_condition_number '
            f'{self.mechanism.max_condition_number:g}): a rod in line with its crank or '
            'lever; one set cannot drive the other there', error.condition_number,
            error.sample)

    def _named(self) -> '_NamedSingular':
        return self._renames          # (one, reused: no state of its own)


class _NamedSingular:
    """Re-raises a solver's SingularConfigurationError or ClosureError naming both sets of
    joints."""

    def __init__(self, transmission: Transmission) -> None:
        self.transmission = transmission

    def __enter__(self) -> None:
        return None

    def __exit__(self, kind: Any, exc: Any, tb: Any) -> Literal[False]:
        if isinstance(exc, SingularConfigurationError) and 'transmission' not in str(exc):
            raise self.transmission._singular(exc) from exc
        if isinstance(exc, ClosureError) and 'transmission' not in str(exc):
            t = self.transmission
            raise ClosureError(
                f"{exc} (the transmission between the motors ({', '.join(t.active_joints)}) "
                f"and the joint space ({', '.join(t.joint_space)}): where the loops stop "
                'closing on the way, the pose is past what the linkage can reach, e.g. '
                'beyond the toggle of a crank)', exc.residual, exc.sample,
                exc.reason or 'closure') from exc
        return False


def _one(x: ArrayLike) -> bool:
    """Whether ``x`` is one sample: a number or a flat sequence."""
    return np.ndim(x) <= 1


def _floats(x: ArrayLike) -> Any:
    """One sample as the lean sample path takes it: a list of floats (a number stays one)."""
    return x.tolist() if isinstance(x, np.ndarray) else x


def _rows(values: list, index: list) -> np.ndarray:
    return np.array([values[j] for j in index])


def _rate_map(solver: ActuatorSpaceSolver, x: ArrayLike) -> np.ndarray:
    """S (n_joints, M) of one sample by the lean sample path."""
    return cast(np.ndarray, solver.closed_pose(_floats(x), with_rates=True)[1])


class _MotorRows:
    """K^T tau_m = J^-T tau_m for a square J (not redundant) whose joint space names motors
    too (a leg's hip and knee motors beside its ankle's joints): the row of J of a joint
    that is motor k is e_k, so only the block A = J[R, F] of the other joints R and the
    other motors F is inverted. With y = A^-T tau_m[F]: tau_q[R] = y, and the joint that
    is motor k gets tau_m[k] - J[R, k] . y; K's Frobenius norm (the singularity check) is
    sqrt(#motors named + |A^-1|_F^2 + |A^-1 J[R, C]|_F^2), C the motors named, at most
    the bound :meth:`efforts` gives (beyond it the exact check decides)."""

    def __init__(self, joint_space: list, active_joints: list) -> None:
        index = {name: k for k, name in enumerate(active_joints)}
        #: (row, motor) of each joint-space joint that is a motor; the other rows
        self.unit = [(i, index[name]) for i, name in enumerate(joint_space) if name in index]
        self.rest = [i for i, name in enumerate(joint_space) if name not in index]
        #: the motors named in the joint space, and the others
        self.named = [k for _, k in self.unit]
        self.free = [k for k in range(len(active_joints)) if k not in self.named]

    def efforts(self, rows: list, tau_m: list) -> tuple[list, float]:
        """(tau_q, a bound of |K|_F) from J's ``rows`` and the motors' efforts ``tau_m``
        (floats): |A^-1 J[R, C]|_F <= |A^-1|_F |J[R, C]|_F; inf where A is singular
        (tau_q then is not to be used)."""
        rest, free, unit = self.rest, self.free, self.unit
        inverse_t, size = _inverse_transposed(
            [[rows[i][k] for k in free] for i in rest] if unit else rows)
        if inverse_t is None:
            return [], math.inf
        tau_f = [tau_m[k] for k in free] if unit else tau_m
        y = [sum(map(operator.mul, row, tau_f)) for row in inverse_t]
        if not unit:                    # no joint-space joint is a motor: J^-T tau_m
            return y, size
        tau_q = [0.0] * len(rows)
        for i, value in zip(rest, y):
            tau_q[i] = value
        coupling = 0.0                                   # |J[R, C]|_F^2
        w = [0.0] * len(tau_m)                           # J[R, :]^T y
        for r, value in zip(rest, y):
            row = rows[r]
            w = [a + value * b for a, b in zip(w, row)]
            named = [row[k] for k in self.named]
            coupling += sum(map(operator.mul, named, named))
        for i, k in unit:
            tau_q[i] = tau_m[k] - w[k]
        return tau_q, math.sqrt(len(unit) + size * size * (1.0 + coupling))


def _inverse_transposed(rows: list) -> tuple[Any, float]:
    """(J^-T as rows, |J^-1|_F) of the square J given by ``rows`` (lists of floats);
    (None, inf) where J is singular. One or two joints in closed form, more by numpy."""
    if not rows:
        return [], 0.0
    if len(rows) == 1:
        (a,), = rows
        return ([[1.0 / a]], abs(1.0 / a)) if a != 0.0 else (None, math.inf)
    if len(rows) == 2:
        (a, b), (c, d) = rows
        det = a * d - b * c
        if det == 0.0:
            return None, math.inf
        return ([[d / det, -c / det], [-b / det, a / det]],
                math.sqrt(a * a + b * b + c * c + d * d) / abs(det))
    try:
        inverse = np.linalg.inv(rows)
    except np.linalg.LinAlgError:
        return None, math.inf
    flat = inverse.ravel()
    return inverse.T.tolist(), math.sqrt(float(np.dot(flat, flat)))


def _vector(vector: ArrayLike, width: int) -> list:
    """One sample's ``width`` velocities or efforts as floats (SetpointError: another
    shape; NaN or infinite ones are found in what is made of them, :func:`_times`)."""
    values: Any = vector.tolist() if isinstance(vector, np.ndarray) else vector
    if _real(values) and width == 1:
        values = [values]                       # one joint: a number, as positions take
    if not isinstance(values, (list, tuple)) or not (
            set(map(type, values)) <= _PLAIN or all(map(_real, values))):
        raise SetpointError(f'expected {width} real numbers (a list, tuple or float array), '
                            f'got {type(vector).__name__} {_short(vector)}')
    v = [float(x) for x in values]
    if len(v) != width:
        raise _shape(width, np.shape(vector))
    return v


def _times(rows: Any, vector: ArrayLike) -> np.ndarray:
    """rows @ vector for one sample (lists of floats, or an array), on floats."""
    v = _vector(vector, len(rows[0]) if len(rows) else 0)
    return _finite([sum(map(operator.mul, row, v)) for row in rows], v)


def _finite(out: list, v: Any) -> np.ndarray:
    """``out`` (made of the finite map's rows and ``v``) as an array; SetpointError where
    ``v`` is not finite (a NaN or infinite entry of v makes one of out so: one check)."""
    if not math.isfinite(sum(out)):
        raise _unmappable(list(v))
    return np.array(out, dtype=float)


def _unmappable(values: list, sample: Optional[int] = None) -> SetpointError:
    """The error for velocities or efforts ``values`` whose map is not finite: non_finite
    where they are not, else out_of_range (finite, but what they map to overflows)."""
    where = '' if sample is None else f'sample {sample}: '
    if not all(map(math.isfinite, values)):
        return SetpointError(f'{where}velocities and efforts must be finite, got {values}',
                             sample, 'non_finite')
    return SetpointError(f'{where}velocities or efforts {values} too large: what they map '
                         'to is beyond the range of a double', sample, 'out_of_range')


def _apply(matrices: np.ndarray, vectors: ArrayLike) -> np.ndarray:
    """matrices @ vectors, one sample ((R, C) @ (C,)) or N ((N, R, C) @ (N, C))."""
    try:
        v = np.asarray(vectors, dtype=float)
    except (TypeError, ValueError):
        raise SetpointError(f'expected real numbers, got {_short(vectors)}') from None
    if matrices.ndim == 2:
        if v.shape != matrices.shape[1:]:
            raise _shape(matrices.shape[1], v.shape)
        out = matrices @ v
    else:
        if v.shape != (matrices.shape[0], matrices.shape[2]):
            raise _shape(matrices.shape[2], v.shape, matrices.shape[0])
        out = np.einsum('nrc,nc->nr', matrices, v)
    bad = ~np.isfinite(np.atleast_2d(out)).all(axis=-1)
    if bad.any():                     # never a NaN or infinite result: say which sample
        i = int(np.argmax(bad))
        raise _unmappable(np.atleast_2d(v)[i].tolist(), None if out.ndim == 1 else i)
    return out


#: the types of a control loop's numbers (the fast check of :func:`_vector`)
_PLAIN = {float, int}


def _real(x: Any) -> bool:
    """Whether ``x`` is a real number (numpy's too), not a truth value."""
    return isinstance(x, numbers.Real) and not isinstance(x, (bool, np.bool_))


def _short(value: Any) -> str:
    """``value`` as text of 60 characters at most (an error message's)."""
    text = repr(value)
    return text if len(text) <= 60 else text[:57] + '...'


def _shape(width: int, got: tuple, samples: Optional[int] = None) -> Exception:
    want = f'({width},)' if samples is None else f'({samples}, {width})'
    return SetpointError(f'expected an array of shape {want}, got {got}')
