"""Straight-line code for one sample: the lane pipeline traced once per mechanism.

The per-sample path runs the lane code of spatial.py and friends on Python floats, and
Python charges for every call, tuple and multiplication by a constant zero a planar
mechanism written in 3-D is full of. Here the same code runs once, at load time, on
*symbolic* lanes (``Sym``) that record the float operations instead of doing them:

* constants fold (``0 * x``, ``1 * x``, ``x + 0``, products of numbers) as they are met;
* equal operations on equal operands are recorded once (common subexpressions);
* operations no output depends on are dropped;

and emitter.py writes what is left as one function of plain float statements. The
operations that remain are those the float path would do, in the same order, so the
results agree with it to the last bit (up to the sign of a zero).

Only branch-free lane code can be traced: a comparison of a ``Sym`` is a :class:`Condition`,
which ``SymOps.select`` records as a choice and which raises TypeError where it would be
taken as a truth value (an ``if``, ``and``, ``min``).
"""
import math
from typing import Any, Callable, NoReturn, Sequence

from ..linalg.spatial import larger, smaller
from ..value_types import Lane


class Graph:
    """The recorded operations: node k is (op, operands); operands are node ids or floats."""

    def __init__(self) -> None:
        self.nodes: list[tuple[str, tuple[Any, ...]]] = []
        self._index: dict[tuple[Any, ...], Sym] = {}

    def node(self, op: str, args: Sequence[Any]) -> 'Sym':
        key = (op,) + tuple(a.k if isinstance(a, Sym) else ('c', a) for a in args)
        sym = self._index.get(key)
        if sym is None:
            sym = self._index[key] = Sym(self, len(self.nodes))
            self.nodes.append((op, tuple(a.k if isinstance(a, Sym) else a for a in args)))
        return sym

    def inputs(self, name: str, n: int) -> list['Sym']:
        """n symbolic inputs called name[0] .. name[n-1]."""
        return [self.node('in', (f'{name}[{i}]',)) for i in range(n)]


def _is_const(x: Lane) -> bool:
    return not isinstance(x, Sym)


def _add(a: Lane, b: Lane) -> Lane:
    if _is_const(a):
        if _is_const(b):
            return a + b
        if a == 0:
            return b
        return b.graph.node('add', (float(a), b))
    if _is_const(b) and b == 0:
        return a
    return a.graph.node('add', (a, b if isinstance(b, Sym) else float(b)))


def _sub(a: Lane, b: Lane) -> Lane:
    if _is_const(b):
        if _is_const(a):
            return a - b
        if b == 0:
            return a
        return a.graph.node('sub', (a, float(b)))
    if _is_const(a) and a == 0:
        return _neg(b)
    if a is b:
        return 0.0
    return b.graph.node('sub', (a if isinstance(a, Sym) else float(a), b))


def _mul(a: Lane, b: Lane) -> Lane:
    if _is_const(a):
        if _is_const(b):
            return a * b
        a, b = b, a
    if _is_const(b):
        if b == 0:
            return 0.0
        if b == 1:
            return a
        if b == -1:
            return _neg(a)
        return a.graph.node('mul', (a, float(b)))
    return a.graph.node('mul', (a, b))


def _div(a: Lane, b: Lane) -> Lane:
    if _is_const(b):
        if _is_const(a):
            return a / b
        if b == 1:
            return a
        return a.graph.node('div', (a, float(b)))
    if _is_const(a) and a == 0:
        return 0.0
    return b.graph.node('div', (a if isinstance(a, Sym) else float(a), b))


def _neg(a: Lane) -> Lane:
    if _is_const(a):
        return -a
    op, args = a.graph.nodes[a.k]
    if op == 'neg':
        return Sym(a.graph, args[0])
    return a.graph.node('neg', (a,))


class Sym:
    """A symbolic lane: node ``k`` of ``graph``."""
    __slots__ = ('graph', 'k')
    __array_ufunc__ = None    # numpy scalars defer to the reflected operators below

    def __init__(self, graph: Graph, k: int) -> None:
        self.graph, self.k = graph, k

    def __add__(self, other: Lane) -> Lane:
        return _add(self, other)

    def __radd__(self, other: Lane) -> Lane:
        return _add(other, self)

    def __sub__(self, other: Lane) -> Lane:
        return _sub(self, other)

    def __rsub__(self, other: Lane) -> Lane:
        return _sub(other, self)

    def __mul__(self, other: Lane) -> Lane:
        return _mul(self, other)

    def __rmul__(self, other: Lane) -> Lane:
        return _mul(other, self)

    def __truediv__(self, other: Lane) -> Lane:
        return _div(self, other)

    def __rtruediv__(self, other: Lane) -> Lane:
        return _div(other, self)

    def __mod__(self, other: Lane) -> Lane:
        return _mod(self, other)

    def __rmod__(self, other: Lane) -> Lane:
        return _mod(other, self)

    def __neg__(self) -> Lane:
        return _neg(self)

    def __pos__(self) -> 'Sym':
        return self

    def __abs__(self) -> Lane:
        return _abs(self)

    def __bool__(self) -> NoReturn:
        raise TypeError('a symbolic lane has no truth value: only branch-free code can be traced')

    def __lt__(self, other: Lane) -> 'Condition':
        return Condition('lt', self, other)

    def __le__(self, other: Lane) -> 'Condition':
        return Condition('le', self, other)

    def __gt__(self, other: Lane) -> 'Condition':
        return Condition('gt', self, other)

    def __ge__(self, other: Lane) -> 'Condition':
        return Condition('ge', self, other)


class Condition:
    """``a < b`` (``op`` 'lt'; 'le', 'gt', 'ge') of lanes, one a Sym: what SymOps.select
    chooses by. It has no truth value (TypeError): only branch-free code can be traced."""
    __slots__ = ('op', 'a', 'b')

    def __init__(self, op: str, a: Lane, b: Lane) -> None:
        self.op, self.a, self.b = op, a, b

    def __bool__(self) -> NoReturn:
        raise TypeError('a comparison of symbolic lanes has no truth value: only branch-free '
                        'code can be traced (ops.select chooses by it)')

    def select(self, x: Lane, y: Lane) -> Lane:
        """x where the comparison holds, else y (NaN: y), as one operation."""
        operands = (self.a, self.b, x, y)
        graph = next(o for o in operands if isinstance(o, Sym)).graph
        return graph.node(self.op + '_select', tuple(o if isinstance(o, Sym) else float(o)
                                                     for o in operands))


def _mod(a: Lane, b: Lane) -> Lane:
    """Python's float a % b (the remainder with the sign of b)."""
    if _is_const(a) and _is_const(b):
        return a % b
    graph = (a if isinstance(a, Sym) else b).graph
    return graph.node('mod', (a if isinstance(a, Sym) else float(a),
                              b if isinstance(b, Sym) else float(b)))


def _unary(op: str, fold: Callable[[float], float]) -> Any:
    def apply(x: Lane) -> Lane:
        return fold(x) if _is_const(x) else x.graph.node(op, (x,))
    return staticmethod(apply)


def _pick(op: str, fold: Callable[[Any, Any], Any]) -> Callable[[Lane, Lane], Lane]:
    """A NaN-keeping max or min of two lanes (spatial.larger, spatial.smaller); also any
    other function of two lanes (``op``, ``fold`` on constants)."""
    def apply(a: Lane, b: Lane) -> Lane:
        if _is_const(a) and _is_const(b):
            return fold(a, b)
        graph = (a if isinstance(a, Sym) else b).graph
        return graph.node(op, (a if isinstance(a, Sym) else float(a),
                               b if isinstance(b, Sym) else float(b)))
    return apply


_larger = _pick('max', larger)
_smaller = _pick('min', smaller)
_abs = _unary('abs', abs).__func__


class SymOps:
    """Lane functions for symbolic lanes (the counterpart of spatial.ScalarOps)."""
    sin = _unary('sin', math.sin)
    cos = _unary('cos', math.cos)
    sqrt = _unary('sqrt', lambda x: math.sqrt(x) if x >= 0.0 else math.nan)
    recip = _unary('recip', lambda x: 1.0 / x if x != 0.0 else math.inf)
    # arccos of x clipped to [-1, 1] (a NaN to -1), as spatial.ScalarOps.acos
    acos = _unary('acos', lambda x: math.acos(min(1.0, max(-1.0, x))))
    atan2 = staticmethod(_pick('atan2', math.atan2))

    @staticmethod
    def select(condition: Any, a: Lane, b: Lane) -> Lane:
        """a where ``condition`` (a Condition, or a bool of constants) holds, else b."""
        if isinstance(condition, Condition):
            return condition.select(a, b)
        return a if condition else b

    @staticmethod
    def maxabs(lanes: Sequence[Lane]) -> Lane:
        """spatial.ScalarOps.maxabs, traced: abs and a NaN-keeping max, branch-free (a max
        with a constant 0.0 start is the other operand, an abs being at least 0 or NaN)."""
        out = 0.0
        for x in lanes:
            a = _abs(x)
            if _is_const(a) and a == 0.0:
                continue                  # max(out, 0.0) is out: out is at least 0, or NaN
            out = a if _is_const(out) and out == 0.0 and not _is_const(a) else _larger(out, a)
        return out

    @staticmethod
    def least(lanes: Sequence[Lane]) -> Lane:
        """spatial.ScalarOps.least, traced (every cosine is at most 1.0, the start)."""
        out = 1.0
        for x in lanes:
            out = _smaller(out, x)
        return out


def live_operations(graph: Graph, outputs: Sequence[Lane]) -> list[int]:
    """Node ids of the operations ``outputs`` depend on, in recording order (inputs excluded);
    what no output depends on is dropped."""
    live = [False] * len(graph.nodes)
    for o in outputs:
        if isinstance(o, Sym):
            live[o.k] = True
    for k in range(len(graph.nodes) - 1, -1, -1):
        if live[k]:
            for a in graph.nodes[k][1]:
                if isinstance(a, int):
                    live[a] = True
    return [k for k, (op, _) in enumerate(graph.nodes) if live[k] and op != 'in']
