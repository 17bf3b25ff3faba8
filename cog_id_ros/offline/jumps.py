"""Jumps of the active positions from one sample to the next, and angles that wrap.

An active position that moves by more than a limit from one sample to the next is a jump:
``cog_id_torques`` refuses or skips that row (:func:`find_jumps`), the node rejects that
setpoint (``max_setpoint_step``); both limit it by :data:`DEFAULT_MAX_STEP` unless told
otherwise. An encoder of a continuous joint reports +pi then -pi: :func:`unwrap_positions`
takes each angle as the 2 pi equivalent nearest the previous one.
"""

import math
from typing import Sequence

import numpy as np

from .trajectory_io import Trajectory, joint_column

#: the largest change of an active position from one sample to the next, by the unit of
#: the joint's coordinate (its kind's ``unit``: an angle, a length), when none is given:
#: cog_id_torques' --max-step and --max-step-linear, the node's max_setpoint_step. Per
#: sample, not per second: a crank wrapping from +pi to -pi jumps by ~2 pi in one sample at
#: any sample rate, and the solver follows the mechanism from sample to sample, which is a
#: per-sample matter too
DEFAULT_MAX_STEP = {'rad': 1.0, 'm': 0.1}


def unwrap_positions(traj: Trajectory, joints: Sequence[str]) -> dict[str, tuple[int, int]]:
    """Unwrap the position columns of ``joints`` (revolute ones) in place.

    Each position is replaced by its 2 pi equivalent nearest the previous row's (already
    unwrapped) position, as an encoder of a continuous joint that reports angles in
    (-pi, pi] needs. A step too large for that to mean anything (2^50 or more) is left as
    it is (the jump check reports it). Returns ``{column: (rows shifted, wraps)}``: how
    many rows now differ from the file and at how many rows a wrap was undone.
    """
    result = {}
    for joint in joints:
        name = joint_column(joint, 'position')
        q = traj.columns[name]
        with np.errstate(all='ignore'):
            d = np.diff(q)
            turns = np.round(d / (2.0 * math.pi))
            turns[~(np.abs(d) < 2.0 ** 50)] = 0.0
            total = np.cumsum(turns)
            shifted = np.flatnonzero(total != 0.0) + 1
            if shifted.size:
                q = q.copy()
                q[shifted] = q[shifted] - (2.0 * math.pi) * total[shifted - 1]
                traj.columns[name] = q
        result[name] = (int(shifted.size), int(np.count_nonzero(turns)))
    return result


def find_jumps(q: np.ndarray, limits: np.ndarray,
               block: int = 4096) -> list[tuple[int, int, float, int]]:
    """Rows whose position jumps from the last accepted row by more than ``limits``.

    ``q`` (N, M) positions, ``limits`` (M,) the largest step per row of each column.
    A row is compared with the last row that was not itself a jump, so one wild row is
    one jump (not two) and everything after an unwrapped 2 pi step is one. Returns
    ``[(row, k, step, ref_row)]``, rows 1-based: column ``k`` of ``row`` is
    ``step`` away from ``ref_row`` (the column with the largest step relative to its limit).
    """
    q = np.asarray(q, dtype=float)
    limits = np.asarray(limits, dtype=float)
    n = q.shape[0]
    jumps = []
    if n < 2:
        return jumps
    with np.errstate(all='ignore'):
        flagged = np.flatnonzero(~np.all(np.abs(np.diff(q, axis=0)) <= limits, axis=1))
        i = 1                     # next row to check; its predecessor is accepted
        while i < n:
            at = np.searchsorted(flagged, i - 1)
            if at == flagged.size:
                break
            ref = int(flagged[at])  # accepted; row ref + 1 jumps from it
            j = ref + 1
            accepted = None
            while j < n and accepted is None:
                part = np.abs(q[j:j + block] - q[ref])
                ok = np.all(part <= limits, axis=1)
                stop = j + int(np.argmax(ok)) if ok.any() else min(j + block, n)
                ratio = part[:stop - j] / limits
                ratio[np.isnan(ratio)] = np.inf
                for r, k in zip(range(j, stop), np.argmax(ratio, axis=1).tolist()):
                    jumps.append((r + 1, k, float(q[r, k] - q[ref, k]), ref + 1))
                if ok.any():
                    accepted = stop
                j = stop
            if accepted is None:
                break
            i = accepted + 1
    return jumps
