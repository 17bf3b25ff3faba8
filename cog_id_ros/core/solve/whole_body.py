"""Whole-body inverse dynamics of a floating robot: efforts, contact wrenches, base wrench.

    the closed pose at theta           sample_solve.py, batch.py (warm-started, as torques)
    Q_b, tau, A, C                     dynamics/floating_base.py (the equations), run by
                                       native/whole_body_kernel.py on the solver's backend
    w = argmin sum_k weight_k w_k^2    among the wrenches with A w = Q_b     contact_wrenches
        (least squares in A w - Q_b where no wrench makes the motion: the rest is left)
    base_wrench = Q_b - A w,  efforts = tau - C w

Conventions (Pinocchio's free flyer): base_pose (x, y, z, qx, qy, qz, qw), world from base;
base_velocity (v, w) and base_acceleration (its time derivative) in the base frame; contact
wrenches (f, m) in world axes at the contact point, what the ground applies to the robot;
base_wrench (force, moment) in the base frame at its origin.
"""
from typing import Any, NamedTuple, Optional, Sequence

import numpy as np

from ..errors import MechanismConfigError, SetpointError
from ..native.whole_body_kernel import whole_body_kernel
from .inputs import check_values, out_of_range, setpoints

#: relative size below which a direction of the contact map counts as missing (pinv cutoff)
RANK_TOLERANCE = 1e-10


class WholeBodyEfforts(NamedTuple):
    """What :func:`whole_body_torques` returns; arrays gain a leading N for N samples."""

    efforts: np.ndarray            # (M,) actuator efforts, active_joints order
    wrenches: dict                 # contact name -> (6,) or (3,) world axes, at the point
    base_wrench: np.ndarray        # (6,) what the world must still apply at the root


def whole_body_torques(solver: Any, base_pose: Any, base_velocity: Any, base_acceleration: Any,
                       theta: Any, theta_dot: Any, theta_ddot: Any,
                       contacts: Optional[Sequence[str]], wrench_weights: Any
                       ) -> WholeBodyEfforts:
    """The efforts, wrenches and base wrench of a motion (docs/floating_base.md);
    ``solver``: an ActuatorSpaceSolver of a mechanism with floating_base."""
    mech = solver.mechanism
    if not mech.floating_base:
        raise MechanismConfigError('mechanism.floating_base', 'whole_body_torques needs a '
                                                              'floating base: set it true')
    solved = mech.solver_mechanism
    chosen = _chosen(solved, contacts)
    target, qd, qdd, single = setpoints(solved, solver._serial.wrapping, theta, theta_dot,
                                        theta_ddot, solver.check_position_limits)
    n = 1 if single else len(target)
    if not n:
        raise SetpointError('no sample: theta has 0 rows')
    pose, velocity, acceleration = _base_state(base_pose, base_velocity, base_acceleration, n,
                                               single)
    rotation = quaternion_rotations(pose[:, 3:])
    base = np.concatenate([velocity, acceleration], axis=1)
    kernel = whole_body_kernel(solved, solver.backend)
    if single:
        state = solver._serial.solve(solver._state, target)[1]
        record = _as_rows(kernel.one(state[0], qd, qdd, base[0].tolist(), rotation[0].tolist()))
    else:
        _, errors = check_values(solved, solver._serial.wrapping, target, qd, qdd, False)
        if errors:
            raise errors[min(errors)]
        with np.errstate(all='ignore'):
            _, positions, _, _, state = solver._batch.positions(solver._state, target, 'raise')
        record = kernel.many(positions, qd, qdd, base, rotation)
    k = sum(contact.size for contact in solved.contacts.values())
    picked = _columns(solved, chosen)
    a_map = np.asarray(record.base_map).reshape(n, 6, k)[:, :, picked]
    c_map = np.asarray(record.joint_map).reshape(n, -1, k)[:, :, picked]
    q_base, tau = np.asarray(record.base_forces), np.asarray(record.torques)
    w = contact_wrenches(a_map, q_base, _weights(chosen, wrench_weights))
    efforts = tau - np.einsum('nmk,nk->nm', c_map, w)
    base_wrench = q_base - np.einsum('nrk,nk->nr', a_map, w)
    _check_finite(np.concatenate([efforts, base_wrench, w], axis=1), qd, base, single)
    solver._state = state
    wrenches, start = {}, 0
    for contact in chosen:
        part = w[:, start:start + contact.size]
        wrenches[contact.name] = part[0] if single else part
        start += contact.size
    if single:
        return WholeBodyEfforts(efforts[0], wrenches, base_wrench[0])
    return WholeBodyEfforts(efforts, wrenches, base_wrench)


def _chosen(mech: Any, contacts: Optional[Sequence[str]]) -> list[Any]:
    """The Contacts named (all of them for None), checked."""
    if isinstance(contacts, str):
        raise SetpointError(f"contacts: a list of names, got the string {contacts!r} (write "
                            f"['{contacts}'])")
    names = list(mech.contacts) if contacts is None else list(contacts)
    for name in names:
        if name not in mech.contacts:
            raise SetpointError(f"contacts: '{name}' is not in mechanism.contacts "
                                f"({', '.join(mech.contacts) or 'none'})")
    if len(set(names)) != len(names):
        raise SetpointError(f'contacts: a contact named twice in {names}')
    return [mech.contacts[name] for name in names]


def _columns(mech: Any, chosen: Sequence[Any]) -> list[int]:
    """The kernel's map columns of the chosen contacts' components, in their order."""
    first, start = {}, 0
    for contact in mech.contacts.values():
        first[contact.name] = start
        start += contact.size
    return [first[c.name] + i for c in chosen for i in range(c.size)]


def _as_rows(record: Any) -> Any:
    """A one-sample record (lists) as a record of (1, k) arrays."""
    return type(record)(*(np.array([list(field)], dtype=float) for field in record))


def _check_finite(values: np.ndarray, qd: Any, base: np.ndarray, single: bool) -> None:
    """SetpointError (out_of_range) naming the first sample whose outputs are not finite:
    the base's velocity or acceleration where it holds the largest number, else the
    actuators' rates (out_of_range's message)."""
    bad = np.flatnonzero(~np.isfinite(values).all(axis=1))
    if not bad.size:
        return
    k = int(bad[0])
    rates = np.abs(np.asarray(qd, dtype=float).reshape(len(base), -1)[k])
    if np.abs(base[k]).max() > rates.max(initial=0.0):
        where = '' if single else f'sample {k}: '
        raise SetpointError(f'{where}the base velocity and acceleration (largest magnitude '
                            f'{np.abs(base[k]).max():.6g}) are too large to compute with',
                            reason='out_of_range', sample=None if single else k)
    raise out_of_range(rates.tolist(), [0.0] * len(rates), None if single else k)


def contact_wrenches(a_map: np.ndarray, q_base: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """(N, k): per sample the wrenches w of least sum weight w^2 with A w = Q_b, or, where no
    w makes it, those of least weighted norm among the ones nearest to it (least squares):
    w = W^-1/2 pinv(A W^-1/2) Q_b."""
    if a_map.shape[2] == 0:
        return np.zeros((len(q_base), 0))
    scale = 1.0 / np.sqrt(weights)
    scaled = a_map * scale
    return scale * np.einsum('nkr,nr->nk', np.linalg.pinv(scaled, rcond=RANK_TOLERANCE),
                             q_base)


def _base_state(pose: Any, velocity: Any, acceleration: Any, n: int, single: bool
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    out = []
    for label, value, size in (('base_pose', pose, 7), ('base_velocity', velocity, 6),
                               ('base_acceleration', acceleration, 6)):
        if value is None:
            if label == 'base_pose':
                raise SetpointError('base_pose: required, (x, y, z, qx, qy, qz, qw)')
            value = np.zeros((size,) if single else (n, size))
        try:
            array = np.array(value, dtype=float)
        except (TypeError, ValueError):
            raise SetpointError(f'{label}: {size} numbers per sample, got {value!r}') from None
        if array.shape != ((size,) if single else (n, size)):
            raise SetpointError(f'{label}: shape {(size,) if single else (n, size)} expected '
                                f'(as theta), got {array.shape}')
        array = array.reshape(n, size)
        bad = np.flatnonzero(~np.isfinite(array).all(axis=1))
        if bad.size:
            raise SetpointError(f'{"" if single else f"sample {bad[0]}: "}{label} is not '
                                f'finite: {array[bad[0]].tolist()}')
        out.append(array)
    norms = np.linalg.norm(out[0][:, 3:], axis=1)
    bad = np.flatnonzero(np.abs(norms - 1.0) > 1e-6)
    if bad.size:
        raise SetpointError(f'{"" if single else f"sample {bad[0]}: "}base_pose: the '
                            f'quaternion (qx, qy, qz, qw) must be a unit one, its norm is '
                            f'{norms[bad[0]]:.9g}')
    return out[0], out[1], out[2]


def quaternion_rotations(quaternion: np.ndarray) -> np.ndarray:
    """(N, 9) row-major world-from-base rotations of unit quaternions (qx, qy, qz, qw)."""
    x, y, z, w = quaternion.T
    return np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w),
                     2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w),
                     2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], axis=1)


def _weights(contacts: Sequence[Any], given: Any) -> np.ndarray:
    """Per wrench component, its weight: all 1 by default; one positive number for all;
    per contact (a dict by name, or a list in the contacts' order) ``size`` positive
    numbers, or one. SetpointError naming what is wrong (a name not among the contacts, a
    list of another length)."""
    names = [contact.name for contact in contacts]
    if given is None or isinstance(given, (int, float)) and not isinstance(given, bool):
        per = [given] * len(contacts)
    elif isinstance(given, dict):
        unknown = [key for key in given if key not in names]
        if unknown:
            raise SetpointError(f'wrench_weights: {unknown} not among the contacts of this '
                                f'call ({", ".join(names) or "none"})')
        per = [given.get(name) for name in names]
    elif isinstance(given, (list, tuple)) and len(given) == len(contacts):
        per = list(given)
    else:
        raise SetpointError(f'wrench_weights: one number, a dict by contact name, or a list '
                            f'of {len(contacts)} (one per contact: {", ".join(names)}), got '
                            f'{given!r}')
    out = []
    for contact, value in zip(contacts, per):
        try:
            w = np.ones(contact.size) if value is None else np.broadcast_to(
                np.array(value, dtype=float), (contact.size,)) if np.size(value) in (
                1, contact.size) else None
        except (TypeError, ValueError):
            w = None
        if w is None or not (np.isfinite(w) & (w > 0.0)).all():
            raise SetpointError(f"wrench_weights of '{contact.name}': {contact.size} positive "
                                f'numbers (or one), got {value!r}')
        out.append(w)
    return np.concatenate(out) if out else np.zeros(0)
