"""What the solver accepts: setpoints checked and turned into floats before any maths.

The input contract (docs/api.md): ``q`` is required, ``qd`` and ``qdd`` default to
zeros; one sample is (M,) (a plain number when M = 1), a batch (N, M); anything else is a
SetpointError with reason 'malformed'; NaN or infinity 'non_finite'; a revolute actuator
beyond +-MAX_ANGLE rad, or torques that overflow, 'out_of_range'; an actuator outside its
position limits (``joints.<name>.lower`` / ``upper``, from a URDF's ``<limit>``) 'limit'.
"""
import math
from typing import TYPE_CHECKING, Any, Iterable, Sequence

import numpy as np

from ..closure.continuation import MAX_ANGLE
from ..errors import SetpointError
from ..value_types import FloatArray

if TYPE_CHECKING:
    from ..model.mechanism import Mechanism

#: the types of a control loop's setpoints (the fast path of setpoints)
_FLOAT = {float}

#: what the three inputs are called in messages: torques' (forward dynamics: q, qd, tau)
LABELS = ('q', 'qd', 'qdd')


def setpoints(mechanism: 'Mechanism', wrapping: Sequence[int], q: Any, qd: Any, qdd: Any,
              limits: bool = True, labels: Sequence[str] = LABELS
              ) -> tuple[Any, Any, Any, bool]:
    """The one way setpoints come in: (q, qd, qdd, single).

    One sample: three lists of M floats, checked: SetpointError for a value not finite, a
    revolute actuator of ``wrapping`` (indices into active_joints) beyond +-MAX_ANGLE, or
    (with ``limits``) an actuator outside its position limits. A batch: float arrays (N, M),
    not checked here (the batch marks its bad samples, :func:`check_values`). SetpointError
    'malformed' for anything else. The ways in, fastest first: a control loop's lists of
    floats, taken as they are after one pass of checks; other sequences of M numbers and
    float rows, converted; anything else as arrays (:func:`setpoint_arrays`), which also
    says what is wrong."""
    m = len(mechanism.active_joints)
    if type(q) is list and type(qd) is list and type(qdd) is list and \
            len(q) == len(qd) == len(qdd) == m:  # what a control loop passes: checked at once
        every = q + qd + qdd        # floats (their types' set: one pass in C), finite, in range
        if set(map(type, every)) == _FLOAT and all(map(math.isfinite, every)) \
                and all(-MAX_ANGLE <= q[a] <= MAX_ANGLE for a in wrapping) \
                and (not limits or within_limits(mechanism, q)):
            return q, qd, qdd, True
    sample: list[list[float]] = []
    for value in (q, qd, qdd):
        if value is None and sample:             # qd, qdd: zeros (q is required)
            sample.append([0.0] * m)
        elif type(value) is np.ndarray and value.ndim == 1 and value.dtype.kind == 'f':
            sample.append(value.tolist())        # a row of a float array: one C call
        elif (type(value) is list or type(value) is tuple) and \
                all(type(x) is float or type(x) is int for x in value):
            try:
                sample.append([float(x) for x in value])
            except OverflowError:
                break
        else:
            break
    else:
        q_, qd_, qdd_ = sample
        if len(q_) == len(qd_) == len(qdd_) == m and all(map(math.isfinite, q_ + qd_ + qdd_)) \
                and all(-MAX_ANGLE <= q_[a] <= MAX_ANGLE for a in wrapping) \
                and (not limits or within_limits(mechanism, q_)):
            return q_, qd_, qdd_, True
    q, qd, qdd, single = setpoint_arrays(mechanism, q, qd, qdd, labels)
    if not single:
        return q, qd, qdd, False
    q, qd, qdd = checked_sample(mechanism, wrapping, q, qd, qdd, limits, labels)
    return q, qd, qdd, True


def checked_sample(mechanism: 'Mechanism', wrapping: Sequence[int], q: FloatArray, qd: FloatArray,
                   qdd: FloatArray, limits: bool = True, labels: Sequence[str] = LABELS
                   ) -> tuple[list[float], list[float], list[float]]:
    """One sample given as arrays (1, M) as three lists of floats, or the SetpointError
    :func:`check_values` finds."""
    _, errors = check_values(mechanism, wrapping, q, qd, qdd, True, limits, labels)
    if errors:
        raise errors[0]
    return q[0].tolist(), qd[0].tolist(), qdd[0].tolist()


def rates(mechanism: 'Mechanism', qd: Any) -> list[float]:
    """One sample of rates ``qd`` alone (M) as a list of floats, checked as :func:`setpoints`
    checks rates."""
    zeros = [0.0] * len(mechanism.active_joints)
    return setpoints(mechanism, (), zeros, qd, zeros, limits=False)[1]


def setpoint_arrays(mechanism: 'Mechanism', q: Any, qd: Any, qdd: Any,
                    labels: Sequence[str] = LABELS
                    ) -> tuple[FloatArray, FloatArray, FloatArray, bool]:
    """(q, qd, qdd) as float arrays of shape (N, M), and whether it was one sample.

    ``q`` is required; ``qd`` and ``qdd`` default to zeros. One sample is (M,), or a
    plain number when M = 1. Raises SetpointError (reason 'malformed') for anything else.
    """
    names = mechanism.active_joints
    m = len(names)
    if q is None:
        raise SetpointError(f'q: required, one position per active joint {names}')
    arrays: list[Any] = [_float_array(label, value, m) if value is not None else None
                         for label, value in zip(labels, (q, qd, qdd))]
    single = arrays[0].ndim == 1
    out: list[FloatArray] = []
    for label, array in zip(labels, arrays):
        if array is None:
            out.append(np.zeros((1 if single else arrays[0].shape[0], m)))
            continue
        if array.ndim != (1 if single else 2) or array.shape[-1] != m or \
                (not single and array.shape[0] != arrays[0].shape[0]):
            expected = f'({m},)' if single else f'({arrays[0].shape[0]}, {m})'
            raise SetpointError(
                f'{label}: expected shape {expected} (active joints {names}), got {array.shape}')
        out.append(array.reshape(1, -1) if single else array)
    return out[0], out[1], out[2], single


def within_limits(mechanism: 'Mechanism', q: Sequence[float]) -> bool:
    """Every limited actuator of one sample (a list of floats) within its position limits."""
    return all(lo <= q[a] <= hi for a, lo, hi in mechanism.limited_actuators)


def check_values(mechanism: 'Mechanism', wrapping: Sequence[int], q: FloatArray, qd: FloatArray,
                 qdd: FloatArray, single: bool, limits: bool = True,
                 labels: Sequence[str] = LABELS) -> tuple[Any, dict[int, SetpointError]]:
    """SetpointError for the first non-finite entry, revolute position beyond MAX_ANGLE,
    or actuator outside its position limits (unless not ``limits``); returns (per-sample
    bool array, {sample: error})."""
    finite = (np.isfinite(q).all(axis=1) & np.isfinite(qd).all(axis=1) &
              np.isfinite(qdd).all(axis=1))
    in_range = (np.abs(q[:, wrapping]) <= MAX_ANGLE).all(axis=1) if wrapping else finite
    for k, lo, hi in mechanism.limited_actuators if limits else ():
        in_range = in_range & (q[:, k] >= lo) & (q[:, k] <= hi)
    errors: dict[int, SetpointError] = {}
    for i in np.flatnonzero(~(finite & in_range)):
        where = '' if single else f'sample {i}: '
        for label, array in zip(labels, (q, qd, qdd)):
            bad = np.flatnonzero(~np.isfinite(array[i]))
            if bad.size:
                joint = mechanism.active_joints[bad[0]]
                errors[int(i)] = SetpointError(
                    f'{where}{label} of {joint} is {array[i, bad[0]]}: must be finite',
                    sample=int(i), reason='non_finite')
                break
        else:
            a = next((a for a in wrapping if not abs(q[i, a]) <= MAX_ANGLE), None)
            if a is None:
                a, lo, hi = next(x for x in mechanism.limited_actuators
                                 if not x[1] <= q[i, x[0]] <= x[2])
                name = mechanism.active_joints[a]
                errors[int(i)] = SetpointError(
                    f'{where}{labels[0]} of {name} is {q[i, a]:.6g}, outside its position limits '
                    f'[{lo:.6g}, {hi:.6g}] (joints.{name}.lower and upper, or the URDF '
                    f'<limit>)', sample=int(i), reason='limit')
                continue
            errors[int(i)] = SetpointError(
                f'{where}{labels[0]} of {mechanism.active_joints[a]} is {q[i, a]:.6g} rad, beyond '
                f'+-{MAX_ANGLE:g} rad (there a float no longer holds an angle to better than '
                f'1e-7 rad): wrap or offset the angle', sample=int(i), reason='out_of_range')
    return finite & in_range, errors


def _float_array(label: str, value: Any, m: int) -> FloatArray:
    """``value`` as a float array; a plain number is one sample when m == 1. SetpointError
    (reason 'malformed') for strings, mappings, booleans, ragged or non-numeric input."""
    if isinstance(value, (str, bytes, dict, bool, np.bool_)) or (
            not isinstance(value, np.ndarray) and not hasattr(value, '__len__') and
            not isinstance(value, (int, float, np.number))):
        raise SetpointError(f'{label}: must be numbers (one per active joint), got '
                            f'{type(value).__name__}')
    if isinstance(value, (list, tuple)) and any(
            isinstance(x, (bool, np.bool_)) or
            (isinstance(x, (list, tuple)) and any(isinstance(y, (bool, np.bool_)) for y in x))
            for x in value):
        raise SetpointError(f'{label}: must be numbers (one per active joint), not booleans')
    try:
        raw = np.asarray(value)
        if raw.dtype.kind not in 'iufO':
            raise TypeError(f'{raw.dtype} values')
        if raw.dtype.kind == 'O' and any(x is None for x in raw.ravel().tolist()):
            raise TypeError('None values')
        with np.errstate(over='raise'):
            array = raw.astype(float)
    except FloatingPointError:
        raise SetpointError(f'{label}: a value beyond the range of a double',
                            reason='out_of_range') from None
    except Exception as exc:   # noqa: BLE001 (whatever a strange object's __float__ raises)
        raise SetpointError(f'{label}: must be numbers (one per active joint), not '
                            f'{type(exc).__name__}: {exc}') from None
    if array.ndim == 0:
        if m != 1:
            raise SetpointError(f'{label}: a single number is a setpoint for one active joint; '
                                f'this mechanism has {m}: give one number per active joint')
        array = array.reshape(1)
    return array


def out_of_range(qd: Iterable[float], qdd: Iterable[float], sample: int | None) -> SetpointError:
    """SetpointError(reason='out_of_range') for finite input whose torques overflow."""
    where = '' if sample is None else f'sample {sample}: '
    largest = max([abs(x) for x in list(qd) + list(qdd)] or [0.0])
    return SetpointError(
        f'{where}the torques are not finite at this setpoint: the velocities or '
        f'accelerations (largest magnitude {largest:.3g}) are too large to compute with',
        sample=sample, reason='out_of_range')
