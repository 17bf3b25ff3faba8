"""Source code from a traced graph (straight_line.py): the only place code is built as text.

A kernel is emitted as one function of plain float statements that returns a named record
(kernels.py). In C every recorded operation is a line; in Python an operation used only once
is written into the expression that uses it (a store and a load fewer per operation, about
half the time of the Python kernels; the same operations on the same operands, so the same
numbers)::

    def dynamics(q, target, qd, qdd):
        q_0, q_1, q_2, q_3 = q
        ...
        t17 = sin(q_1)
        t19 = (0.25 * t17) + (t17 * q_0)
        ...
        return new(PoseRecord, (
            (t40, t41, t45),  # residual
            ...
        ))

Every expression is what spatial.ScalarOps computes for that operation, so the emitted
function returns exactly what the lane code returns on floats.
"""
from importlib import resources
import math
from typing import Any, Callable, Sequence

from ..linalg.lanes import leaves
from ..value_types import Lane
from .straight_line import Graph, Sym, live_operations

#: a kernel's parameters: (name, its input Syms, nested for rows)
Params = Sequence[tuple[str, Any]]
#: a kernel's record fields: (name, a Sym, a float or nested lists of them)
Fields = Sequence[tuple[str, Any]]

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
    'abs': 'abs({0})',
    'max': '({0} if {0} > {1} or {0} != {0} else {1})',     # spatial.larger: keeps a NaN
    'min': '({0} if {0} < {1} or {0} != {0} else {1})',     # spatial.smaller
    # spatial.ScalarOps.acos: acos(min(1.0, max(-1.0, x))), a NaN taken as -1.0
    'acos': 'acos(({0} if {0} < 1.0 else 1.0) if {0} > -1.0 else -1.0)',
    'atan2': 'atan2({0}, {1})',
    'mod': '{0} % {1}',
    # ScalarOps.select(a < b, x, y) and the other comparisons (straight_line.Condition)
    'lt_select': '({2} if {0} < {1} else {3})',
    'le_select': '({2} if {0} <= {1} else {3})',
    'gt_select': '({2} if {0} > {1} else {3})',
    'ge_select': '({2} if {0} >= {1} else {3})',
}


def python_source(name: str, params: Params, record: str, fields: Fields) -> tuple[str, int]:
    """Source of ``def name(*params)`` returning ``record(*fields)``.

    params: (parameter name, list of input Syms from ``graph.inputs``), each parameter a
    sequence unpacked into its inputs; record: the record type's name; fields: (field name,
    value) with value a Sym, a float or nested lists of them (emitted as tuples).
    Returns (source, number of operations).
    """
    outputs, graph, operations = _program(params, fields)
    names: dict[int, str] = {}
    lines = [f'def {name}({", ".join(p for p, _ in params)}):']
    for p, syms in params:
        if syms:
            lines.append(f'    {_unpacking(p, syms, names)} = {p}')

    def operand(a: int | float) -> str:
        return names[a] if isinstance(a, int) else _literal(a)

    inline = _inlined(graph, operations, outputs)
    depth: dict[int, int] = {}
    for k in operations:
        op, args = graph.nodes[k]
        text = PYTHON_EXPRESSIONS[op].format(*map(operand, args))
        deepest = 1 + max((depth.get(a, 0) for a in args if isinstance(a, int)), default=0)
        if k in inline and deepest <= INLINE_DEPTH:
            names[k], depth[k] = f'({text})', deepest    # written where its one use is
        else:
            names[k] = f't{k}'
            lines.append(f'    t{k} = {text}')

    def literal(value: Any) -> str:
        if isinstance(value, (list, tuple)):
            items = [literal(x) for x in value]
            return '(' + ', '.join(items) + (',)' if len(items) == 1 else ')')
        return operand(value.k if isinstance(value, Sym) else value)

    lines.append(f'    return new({record}, (')     # tuple.__new__: a record without a Python call
    lines += [f'        {literal(value)},  # {field}' for field, value in fields]
    lines.append('    ))')
    return '\n'.join(lines) + '\n', len(operations)


#: how deep single-use operations are written into the expression that uses them
INLINE_DEPTH = 12


def _inlined(graph: Graph, operations: Sequence[int], outputs: Sequence[Lane]) -> set[int]:
    """The operations the Python emitter writes into their only user's expression instead of
    a variable of their own (a store and a load fewer, the same operations in an order
    that gives the same numbers: every operation is a pure function of its operands).
    Those used once, by an operation whose expression names that operand once (not the
    conditional ones, sqrt, recip, max, min), and not an output."""
    uses: dict[int, int] = {}
    for k in operations:
        op, args = graph.nodes[k]
        for a in args:
            if isinstance(a, int):
                uses[a] = uses.get(a, 0) + (1 if PYTHON_EXPRESSIONS[op].count('{') ==
                                            len(args) else 2)
    for o in outputs:
        if isinstance(o, Sym):
            uses[o.k] = uses.get(o.k, 0) + 2
    return {k for k in operations if uses.get(k) == 1}


def _program(params: Params, fields: Fields) -> tuple[list[Lane], Any, list[int]]:
    """What both emitters write: the kernel's outputs (leaves of ``fields``), their graph and
    the operations they depend on, in recording order."""
    outputs = [x for _, value in fields for x in leaves(value)]
    graph = next((o.graph for o in outputs if isinstance(o, Sym)), None) or \
        next((s.graph for _, syms in params for s in leaves(syms)), None)
    operations = live_operations(graph, outputs) if graph is not None else []
    return outputs, graph, operations


def _unpacking(prefix: str, syms: Sequence[Any], names: dict[int, str]) -> str:
    """The target list that unpacks a parameter (nested lists: rows) into its inputs."""
    items = []
    for i, s in enumerate(syms):
        if isinstance(s, (list, tuple)):
            items.append('(' + _unpacking(f'{prefix}_{i}', s, names) + ')')
        else:
            names[s.k] = f'{prefix}_{i}'
            items.append(names[s.k])
    return ', '.join(items) + (',' if len(items) == 1 else '')


def python_function(name: str, params: Params, record_type: type,
                    fields: Fields) -> tuple[Callable[..., Any], str, int]:
    """The function of :func:`python_source`, compiled; returns (function, source, count)."""
    source, count = python_source(name, params, record_type.__name__, fields)
    namespace: dict[str, Any] = {
        'new': tuple.__new__, 'sin': math.sin, 'cos': math.cos, 'sqrt': math.sqrt,
        'acos': math.acos, 'atan2': math.atan2,
        'inf': math.inf, 'nan': math.nan, record_type.__name__: record_type}
    exec(compile(source, f'<kernel {name}>', 'exec'), namespace)   # noqa: S102
    return namespace[name], source, count


def _literal(x: float) -> str:
    x = float(x)
    if math.isnan(x):
        return 'nan'
    if math.isinf(x):
        return 'inf' if x > 0 else '-inf'
    text = repr(x)
    return f'({text})' if x < 0 or text.startswith('-') else text


# --- C ---------------------------------------------------------------------------------

#: each operation as a C expression, with the same special cases as PYTHON_EXPRESSIONS
C_EXPRESSIONS = {
    'neg': '-{0}',
    'sin': 'sin({0})',
    'cos': 'cos({0})',
    'sqrt': '({0} >= 0.0 ? sqrt({0}) : NAN)',
    'recip': '({0} != 0.0 ? 1.0 / {0} : INFINITY)',
    'add': '{0} + {1}',
    'sub': '{0} - {1}',
    'mul': '{0} * {1}',
    'div': '{0} / {1}',
    'abs': 'fabs({0})',
    'max': '({0} > {1} || {0} != {0} ? {0} : {1})',
    'min': '({0} < {1} || {0} != {0} ? {0} : {1})',
    'acos': 'acos({0} > -1.0 ? ({0} < 1.0 ? {0} : 1.0) : -1.0)',
    'atan2': 'atan2({0}, {1})',
    'mod': 'py_mod({0}, {1})',
    'lt_select': '({0} < {1} ? {2} : {3})',
    'le_select': '({0} <= {1} ? {2} : {3})',
    'gt_select': '({0} > {1} ? {2} : {3})',
    'ge_select': '({0} >= {1} ? {2} : {3})',
}

#: C functions an expression above calls, written into a module whose kernels call them
#: (py_mod: the lane code's divisors are nonzero constants, where Python's % would raise)
C_FUNCTIONS = {
    'py_mod': """/* Python's float a % b (float_rem): fmod, then the sign of b */
static double py_mod(double a, double b)
{
    double mod = fmod(a, b);
    if (mod != 0.0) {
        if ((b < 0.0) != (mod < 0.0))
            mod += b;
    }
    else
        mod = copysign(0.0, b);
    return mod;
}
""",
}

#: the C every kernel module starts with (package data beside this module): reading Python
#: sequences, writing records and checking the buffers of the *_many kernels, and
#: set_record_types; ``N_KERNELS`` in it stands for the number of kernels
C_PRELUDE = 'kernels_prelude.c'


def c_prelude(n_kernels: int) -> str:
    """The C prelude of a module of ``n_kernels`` kernels."""
    text = resources.files(__package__).joinpath(C_PRELUDE).read_text(encoding='ascii')
    return text.replace('N_KERNELS', str(n_kernels))


def _c_literal(x: float) -> str:
    x = float(x)
    if math.isnan(x):
        return 'NAN'
    if math.isinf(x):
        return 'INFINITY' if x > 0 else '(-INFINITY)'
    text = repr(x)
    return f'({text})' if x < 0 or text.startswith('-') else text


def _field_shape(value: Any) -> tuple[Any, ...]:
    """('scalar',) | ('vector', n) | ('rows', n_rows, width) of a record field's value."""
    if not isinstance(value, (list, tuple)):
        return ('scalar',)
    if value and isinstance(value[0], (list, tuple)):
        return ('rows', len(value), len(value[0]))
    return ('vector', len(value))


def c_kernel_source(index: int, name: str, params: Params, fields: Fields) -> tuple[str, int, int]:
    """C source of one kernel ``name(*params)`` returning record type ``index``'s instance
    of ``fields`` (as :func:`python_source`), and of ``name_many``, the same kernel over N
    samples at once (see :func:`c_module_source`). Returns (source, number of operations,
    number of outputs)."""
    outputs, graph, operations = _program(params, fields)
    names: dict[int, str] = {}
    for p, syms in params:
        for k, s in enumerate(leaves(syms)):
            names[s.k] = f'{p}[{k}]'
    for k in operations:
        names[k] = f't{k}'

    def operand(a: int | float) -> str:
        return names[a] if isinstance(a, int) else _c_literal(a)

    sizes = [len(leaves(syms)) for _, syms in params]
    declared = ', '.join(f'const double *restrict {p}' for p, _ in params)
    # the arithmetic, once
    lines = [f'static void body_{name}({declared}, double *restrict out)', '{']
    for k in operations:
        op, args = graph.nodes[k]
        lines.append(f'    const double t{k} = {C_EXPRESSIONS[op].format(*map(operand, args))};')
    for i, o in enumerate(outputs):
        lines.append(f'    out[{i}] = {operand(o.k if isinstance(o, Sym) else o)};')
    lines += ['}', '']
    lines += _c_one_sample(index, name, params, fields, sizes, len(outputs))
    lines += _c_many(name, params, sizes, len(outputs))
    return '\n'.join(lines) + '\n', len(operations), len(outputs)


def _c_one_sample(index: int, name: str, params: Params, fields: Fields, sizes: Sequence[int],
                  n_out: int) -> list[str]:
    """Lines of ``kernel_name``: one sample, Python sequences in, a record out."""
    lines = [f'static PyObject *kernel_{name}(PyObject *self, PyObject *const *args, '
             f'Py_ssize_t nargs)', '{',
             f'    if (nargs != {len(params)}) {{',
             f'        PyErr_SetString(PyExc_TypeError, "{name}() takes {len(params)} '
             f'arguments");',
             '        return NULL;',
             '    }']
    for i, (p, syms) in enumerate(params):
        shape = _field_shape(syms)
        reader = (f'read_rows(args[{i}], {p}, {shape[1]}, {shape[2]}, "{p}")'
                  if shape[0] == 'rows' else f'read_doubles(args[{i}], {p}, {sizes[i]}, "{p}")')
        lines += [f'    double {p}[{max(sizes[i], 1)}];',
                  f'    if ({reader} < 0)',
                  '        return NULL;']
    lines += [f'    double out[{max(n_out, 1)}];',
              f'    body_{name}({", ".join(p for p, _ in params)}, out);']
    built: list[str] = []
    offset = 0
    for field, value in fields:
        shape = _field_shape(value)
        if shape[0] == 'scalar':
            built.append(f'PyFloat_FromDouble(out[{offset}])')
            offset += 1
        elif shape[0] == 'vector':
            built.append(f'floats(out + {offset}, {shape[1]})')
            offset += shape[1]
        else:
            built.append(f'rows(out + {offset}, {shape[1]}, {shape[2]})')
            offset += shape[1] * shape[2]
    n = len(built)
    return lines + [f'    PyObject *f[{n}] = {{{", ".join(built)}}};',
                    f'    PyObject *fields = PyTuple_New({n});',
                    f'    for (int i = 0; i < {n}; i++)',
                    '        if (f[i] == NULL || fields == NULL) {',
                    f'            for (int j = 0; j < {n}; j++)',
                    '                Py_XDECREF(f[j]);',
                    '            Py_XDECREF(fields);',
                    '            return NULL;',
                    '        }',
                    f'    for (int i = 0; i < {n}; i++)',
                    '        PyTuple_SET_ITEM(fields, i, f[i]);',
                    f'    return record({index}, fields);',
                    '}', '']


def _c_many(name: str, params: Params, sizes: list[int], n_out: int) -> list[str]:
    """Lines of ``kernel_name_many``: N samples, C-contiguous float64 buffers (N, width)
    in, one (N, outputs) written."""
    widths = ', '.join(str(w) for w in sizes + [n_out])
    pointers = ', '.join(f'(const double *)view[{i}].buf + i * {w}'
                         for i, w in enumerate(sizes))
    return [f'static PyObject *kernel_{name}_many(PyObject *self, PyObject *const *args, '
            f'Py_ssize_t nargs)', '{',
            f'    static const Py_ssize_t width[{len(params) + 1}] = {{{widths}}};',
            f'    Py_buffer view[{len(params) + 1}];',
            f'    Py_ssize_t n = many_buffers(args, nargs, {len(params) + 1}, width, view, '
            f'"{name}_many");',
            '    if (n < 0)',
            '        return NULL;',
            '    Py_BEGIN_ALLOW_THREADS',
            '    for (Py_ssize_t i = 0; i < n; i++)',
            f'        body_{name}({pointers}, (double *)view[{len(params)}].buf + i * {n_out});',
            '    Py_END_ALLOW_THREADS',
            f'    for (int k = 0; k < {len(params) + 1}; k++)',
            '        PyBuffer_Release(&view[k]);',
            '    Py_RETURN_NONE;',
            '}']


def c_module_source(module: str, kernels: Sequence[tuple[str, Params, str, Fields]],
                    extra: str = '', extra_methods: Sequence[tuple[str, str, str]] = ()
                    ) -> tuple[str, dict[str, int]]:
    """C source of a CPython extension module ``module`` with one function per kernel.

    kernels: list of (name, params, record type name, fields) as for :func:`python_source`.
    The module's ``set_record_types(*types)`` must be called once, with the record types in
    the order of ``kernels``, before a kernel is. Each kernel ``name`` also comes as
    ``name_many(*arrays, out)``: C-contiguous float64 arrays of shape (N, inputs of the
    parameter) and a writable (N, outputs) array that receives the outputs of every sample
    in the order of ``fields``, flattened. ``extra``: C that follows the kernels (and may call
    their ``body_<name>`` functions), its module functions ``extra_methods`` ((name, C
    function, doc), METH_FASTCALL). Returns (source, {name: operations}).
    """
    counts: dict[str, int] = {}
    sources = []
    for index, (name, params, _, fields) in enumerate(kernels):
        source, counts[name], _ = c_kernel_source(index, name, params, fields)
        sources.append(source)
    parts = [c_prelude(len(kernels))]
    parts += [text for function, text in C_FUNCTIONS.items()
              if any(f'{function}(' in source for source in sources)]
    parts += sources
    if extra:
        parts.append(extra)
    methods = [f'    {{"{name}{many}", (PyCFunction)(void (*)(void))kernel_{name}{many}, '
               f'METH_FASTCALL, "{text}"}},'
               for name, _, record, _ in kernels
               for many, text in (('', f'{record} of the mechanism '
                                       '(cog_id_ros.core.native.kernels)'),
                                  ('_many', f'{name} over N samples: (N, width) float64 '
                                            f'arrays in, the (N, outputs) array written'))]
    methods += [f'    {{"{name}", (PyCFunction)(void (*)(void)){function}, METH_FASTCALL, '
                f'"{doc}"}},' for name, function, doc in extra_methods]
    parts.append('static PyMethodDef methods[] = {\n'
                 '    {"set_record_types", set_record_types, METH_VARARGS, NULL},\n'
                 + '\n'.join(methods) + '\n    {NULL, NULL, 0, NULL}\n};\n')
    parts.append(f'static struct PyModuleDef module_def = {{PyModuleDef_HEAD_INIT, "{module}", '
                 f'NULL, -1, methods}};\n\n'
                 f'PyMODINIT_FUNC PyInit_{module}(void)\n{{\n'
                 f'    return PyModule_Create(&module_def);\n}}\n')
    return '\n'.join(parts), counts
