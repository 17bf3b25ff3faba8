"""Source code from a traced graph (straight_line.py): the only place code is built as text.

A kernel is emitted as one function of plain float statements, one recorded operation a
line, that returns a named record (kernels.py)::

    def dynamics(q, target, qd, qdd):
        q_0, q_1, q_2, q_3 = q
        ...
        t17 = sin(q_1)
        t18 = 0.25 * t17
        ...
        return new(PoseRecord, (
            (t40, t41, t45),  # residual
            ...
        ))

Every expression is what spatial.ScalarOps computes for that operation, so the emitted
function returns exactly what the lane code returns on floats.
"""
import math

from .straight_line import Sym, leaves, live_operations

#: each operation as a Python expression ({0}, {1}: the operands); sqrt and recip as
#: spatial.ScalarOps defines them
PYTHON_EXPRESSIONS = {
    'neg': '-{0}',
    'sin': 'sin({0})',
    'cos': 'cos({0})',
    'sqrt': '(sqrt({0}) if {0} >= 0.0 else nan)',
    'recip': '(1.0 / {0} if {0} != 0.0 else inf)',
    'add': '{0} + {1}',
    'sub': '{0} - {1}',
    'mul': '{0} * {1}',
    'div': '{0} / {1}',
}


def python_source(name, params, record, fields):
    """Source of ``def name(*params)`` returning ``record(*fields)``.

    params: (parameter name, list of input Syms from ``graph.inputs``), each parameter a
    sequence unpacked into its inputs; record: the record type's name; fields: (field name,
    value) with value a Sym, a float or nested lists of them (emitted as tuples).
    Returns (source, number of operations).
    """
    outputs = [x for _, value in fields for x in leaves(value)]
    graph = next((o.graph for o in outputs if isinstance(o, Sym)), None) or \
        next((s.graph for _, syms in params for s in syms), None)
    names = {}
    lines = [f'def {name}({", ".join(p for p, _ in params)}):']
    for p, syms in params:
        for i, s in enumerate(syms):
            names[s.k] = f'{p}_{i}'
        if syms:
            comma = ',' if len(syms) == 1 else ''
            lines.append(f'    {", ".join(names[s.k] for s in syms)}{comma} = {p}')

    def operand(a):
        return names[a] if isinstance(a, int) else _literal(a)

    operations = live_operations(graph, outputs) if graph is not None else []
    for k in operations:
        op, args = graph.nodes[k]
        names[k] = f't{k}'
        lines.append(f'    t{k} = {PYTHON_EXPRESSIONS[op].format(*map(operand, args))}')

    def literal(value):
        if isinstance(value, (list, tuple)):
            items = [literal(x) for x in value]
            return '(' + ', '.join(items) + (',)' if len(items) == 1 else ')')
        return operand(value.k if isinstance(value, Sym) else value)

    lines.append(f'    return new({record}, (')     # tuple.__new__: a record without a Python call
    lines += [f'        {literal(value)},  # {field}' for field, value in fields]
    lines.append('    ))')
    return '\n'.join(lines) + '\n', len(operations)


def python_function(name, params, record_type, fields):
    """The function of :func:`python_source`, compiled; returns (function, source, count)."""
    source, count = python_source(name, params, record_type.__name__, fields)
    namespace = {'new': tuple.__new__, 'sin': math.sin, 'cos': math.cos, 'sqrt': math.sqrt,
                 'inf': math.inf, 'nan': math.nan, record_type.__name__: record_type}
    exec(compile(source, f'<kernel {name}>', 'exec'), namespace)   # noqa: S102
    return namespace[name], source, count


def _literal(x):
    x = float(x)
    if math.isnan(x):
        return 'nan'
    if math.isinf(x):
        return 'inf' if x > 0 else '-inf'
    text = repr(x)
    return f'({text})' if x < 0 or text.startswith('-') else text
