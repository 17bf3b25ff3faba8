"""Lanes and arrays: the lane code's values to and from numpy arrays.

The lane code (spatial.py's ops) computes on lanes: a Python float for one sample, an (N,)
array for N samples. Arrays of N samples (N, k) come in as k lanes and the lane code's
nested results go out as arrays again; these helpers are the only ones that do either.
"""
from typing import Any, Iterable

import numpy as np

from ..value_types import FloatArray, Lane


def columns(array: FloatArray) -> list[FloatArray]:
    """(N, k) array -> list of k lanes of shape (N,)."""
    return [array[:, a] for a in range(array.shape[1])]


def stacked(nested: Any) -> FloatArray:
    """Nested lists of lanes (floats, or (N,) arrays) -> an array (...) or (N, ...)."""
    n = next((x.shape[0] for x in leaves(nested) if isinstance(x, np.ndarray) and x.ndim),
             None)
    return np.array(nested, dtype=float) if n is None else _stacked(nested, n)


def _stacked(nested: Any, n: int) -> FloatArray:
    if isinstance(nested, (list, tuple)):
        return np.stack([_stacked(x, n) for x in nested], axis=1)
    return np.broadcast_to(np.asarray(nested, dtype=float), (n,))


def flat(record: Iterable[Any], n: int) -> FloatArray:
    """A record of lanes (kernels.py) -> its flat outputs (n, outputs), its leaves in order
    (a lane that is a plain number is the same in every row)."""
    values = leaves(list(record))
    if not values:
        return np.zeros((n, 0))
    return np.column_stack([np.broadcast_to(np.asarray(v, dtype=float), (n,)) for v in values])


def leaves(value: Any) -> list[Lane]:
    """The Syms and floats of a nested list/tuple structure, depth first."""
    if isinstance(value, (list, tuple)):
        return [x for item in value for x in leaves(item)]
    return [value]
