"""The control-rate path: one sample of one mechanism as two straight-line functions.

``InverseDynamics.torques`` on one sample does, on Python floats: a first-order predictor
from the previous solution, Newton steps on the loop equations, then eqs. (1)-(7) at the
closed configuration. The lane code of those steps is traced once per mechanism
(straight_line.py) into

    newton(q, qd, qdd) -> closure residual, cosines of the loop frames, Newton step
    full(q, qd, qdd)   -> the same, then condition number, torques, velocity basis

and this module strings them together exactly as the general path does (same predictor,
same step limit, same checks), so the torques agree with it to the last bit. The usual
sample at control rate (one continuation goal, a Newton step or two) is strung together
by ``step()``, that same glue unrolled for the mechanism's sizes;
:meth:`SampleProgram.torques` is the glue for everything else. Anything out of the
ordinary (Newton not converging in a few steps, a singular or unclosable pose) returns
None and the general path, which raises the right error, takes over from the same state.

Redundantly actuated mechanisms keep the general path (their projection is iterative).
"""
import math

from . import closure
from .joint_motion import velocity_basis
from .straight_line import Graph, SymOps, compile_function

#: Newton steps tried here before handing over to the general path
MAX_NEWTON_STEPS = 4

#: Newton steps tried by the unrolled step() before handing over to the loops
UNROLLED_NEWTON_STEPS = 2


class SampleProgram:
    """newton() and full() of one non-redundant mechanism, and the glue between them.

    ``pipeline(sol, basis, condition, qd, qdd, ops)`` is the solver's eqs. (1)-(7) at a
    closure solution (InverseDynamics builds it); it is traced, never called on floats.
    """

    def __init__(self, mechanism, pipeline, max_step=0.5):
        m = self.mechanism = mechanism
        self.max_step = max_step
        n_joints, n_act = len(m.joints), len(m.active_joints)
        graph = Graph()
        q = graph.inputs('q', n_joints)
        sol = closure.evaluate(m.model, q, m.free_joints, SymOps)
        residual = [r for st in sol.loops for r in st.residual]
        cosines = [st.cosine for st in sol.loops]
        closure_outputs = residual + cosines + sol.lsq.solve(residual)
        self.n_residual, self.n_loops = len(residual), len(cosines)
        self.n_closure = len(closure_outputs)
        qd, qdd = graph.inputs('qd', n_act), graph.inputs('qdd', n_act)
        params = [('q', q), ('qd', qd), ('qdd', qdd)]
        self.newton, _, newton_ops = compile_function('newton', params, closure_outputs)

        basis = velocity_basis(m, sol)
        condition = sol.lsq.condition_number()
        tau = pipeline(sol, basis, condition, qd, qdd, SymOps)
        free_rows = [x for j in m.free_joints for x in basis[j]]
        self.full, _, full_ops = compile_function(
            'full', params, closure_outputs + [condition] + list(tau) + free_rows)
        self.operations = (newton_ops, full_ops)
        # the velocity basis rows of the primary actuators are constant unit rows
        self._unit_rows = {j: [1.0 if i == k else 0.0 for i in range(m.dof)]
                           for k, j in enumerate(m.primary_joints)}
        self.step = _compile_step(self)

    def solve(self, predicted, qd, qdd):
        """(torques, new state (q, basis)) at the closed pose nearest ``predicted`` (the
        continuation's prediction, primary actuators at their goal); None when the general
        path must decide (slow convergence, a singular or unclosable pose)."""
        m = self.mechanism
        q = list(predicted)
        tol, nr, nl, nc = m.closure_tolerance, self.n_residual, self.n_loops, self.n_closure
        free = m.free_joints
        evaluate = self.newton       # closure only, until the configuration is closed
        for _ in range(MAX_NEWTON_STEPS + 2):
            out = evaluate(q, qd, qdd)
            residual = max(map(abs, out[:nr])) if nr else 0.0
            if residual < tol and (not nl or min(out[nr:nr + nl]) > 0.0):
                if evaluate is self.full:
                    break
                evaluate = self.full    # closed where the predictor put it: evaluate all there
                continue
            step = out[nr + nl:nc]
            size = max(map(abs, step))
            if not size < math.inf or size < 1e-15 * (1.0 + max([abs(q[j]) for j in free])):
                return None
            factor = min(1.0, self.max_step / size)
            for k, j in enumerate(free):
                q[j] = q[j] - step[k] * factor
            evaluate = self.full        # most likely closed after this step: evaluate all
        else:
            return None
        condition = out[nc]
        n_act = len(m.active_joints)
        tau = out[nc + 1:nc + 1 + n_act]
        if not (condition <= m.max_condition_number and all(map(math.isfinite, tau))):
            return None
        rows = out[nc + 1 + n_act:]
        dof = m.dof
        new_basis = [None] * len(q)
        for j, row in self._unit_rows.items():
            new_basis[j] = row
        for i, j in enumerate(free):
            new_basis[j] = list(rows[i * dof:(i + 1) * dof])
        return tau, (q, new_basis)


def _compile_step(program):
    """``step(state, target, qd, qdd, limits, bounds)`` -> (torques, new state) or None.

    The glue of :meth:`SampleProgram.solve` and the continuation rules of the solver
    (continuation.py) written out for this mechanism's sizes, for the case that covers
    nearly every sample at control rate: ``target`` within one continuation step (no
    actuator and no predicted joint motion beyond its limit in ``limits``), closed after
    at most ``UNROLLED_NEWTON_STEPS`` Newton steps, with a Newton correction within
    ``bounds`` (CORRECTOR_RATIO times the limits). Every expression is the one the loops
    evaluate, in the same order, so the result is the same to the last bit; any other case
    returns None before anything is changed, and the loops take over.
    """
    m = program.mechanism
    n = len(m.joints)
    nr, nl, nc, dof = program.n_residual, program.n_loops, program.n_closure, m.dof
    n_act = len(m.active_joints)
    if not n or not nr:
        return None
    qs = [f'q{i}' for i in range(n)]
    vector = '[' + ', '.join(qs) + ']'
    lines = ['def step(state, target, qd, qdd, limits, bounds):',
             f'    ({", ".join(qs)},), basis = state' if n == 1 else
             f'    ({", ".join(qs)}), basis = state']
    # one continuation step: no actuator moves by more than its step limit ...
    gaps = [f'abs(target[{a}] - q{j}) <= limits[{j}]' for a, j in enumerate(m.active_index)]
    lines += [f'    if not ({" and ".join(gaps)}):',
              '        return None']
    # ... the predictor q + basis (target - q) on the primary actuators, then the targets ...
    lines += [f'    d{k} = target[{a}] - q{j}'
              for k, (a, j) in enumerate(zip(m.primary, m.primary_joints))]
    for i in range(n):
        terms = [f'basis[{i}][{k}] * d{k}' for k in range(len(m.primary))]
        moved = terms[0] if len(terms) == 1 else '(0 + ' + ' + '.join(terms) + ')'
        lines.append(f'    m{i} = {moved}')
    # ... and no joint is predicted to move by more than its limit
    lines += [f'    if not ({" and ".join(f"abs(m{i}) <= limits[{i}]" for i in range(n))}):',
              '        return None']
    lines += [f'    q{i} = q{i} + m{i}' for i in range(n)]
    lines += [f'    q{j} = target[{a}]' for a, j in zip(m.primary, m.primary_joints)]
    free = m.free_joints
    lines += [f'    p{j} = q{j}' for j in free]

    def closed(out):
        residual = (f'abs({out}[0])' if nr == 1 else
                    'max(' + ', '.join(f'abs({out}[{r}])' for r in range(nr)) + ')')
        test = f'{residual} < {m.closure_tolerance!r}'
        if nl:
            cosine = (f'{out}[{nr}]' if nl == 1 else
                      'min(' + ', '.join(f'{out}[{nr + c}]' for c in range(nl)) + ')')
            test += f' and {cosine} > 0.0'
        return test

    size = ('abs(o[{}])'.format(nr + nl) if len(free) == 1 else
            'max(' + ', '.join(f'abs(o[{nr + nl + k}])' for k in range(len(free))) + ')')
    largest = (f'abs(q{free[0]})' if len(free) == 1 else
               'max(' + ', '.join(f'abs(q{j})' for j in free) + ')')
    lines += [f'    o = newton({vector}, qd, qdd)',
              f'    if {closed("o")}:',
              f'        o = full({vector}, qd, qdd)',
              f'        if not ({closed("o")}):',
              '            return None',
              '    else:',
              f'        for _ in range({UNROLLED_NEWTON_STEPS}):',
              f'            size = {size}',
              f'            if not size < inf or size < 1e-15 * (1.0 + {largest}):',
              '                return None',
              f'            factor = min(1.0, {program.max_step!r} / size)']
    lines += [f'            q{j} = q{j} - o[{nr + nl + k}] * factor' for k, j in enumerate(free)]
    lines += [f'            o = full({vector}, qd, qdd)',
              f'            if {closed("o")}:',
              '                break',
              '        else:',
              '            return None']
    # the Newton correction stayed small: the step stayed on its branch
    if free:
        kept = ' and '.join(f'abs(q{j} - p{j}) <= bounds[{j}]' for j in free)
        lines += [f'    if not ({kept}):',
                  '        return None']
    tau = [f'o[{nc + 1 + a}]' for a in range(n_act)]
    finite = ' and '.join(f'isfinite({t})' for t in tau)
    lines += [f'    if not (o[{nc}] <= {m.max_condition_number!r} and {finite}):',
              '        return None']
    rows = {j: f'unit{j}' for j in m.primary_joints}
    first = nc + 1 + n_act
    for k, j in enumerate(free):
        rows[j] = '[' + ', '.join(f'o[{first + k * dof + i}]' for i in range(dof)) + ']'
    lines.append(f'    return [{", ".join(tau)}], ({vector}, '
                 f'[{", ".join(rows[j] for j in range(n))}])')
    namespace = {'newton': program.newton, 'full': program.full, 'inf': math.inf,
                 'isfinite': math.isfinite}
    namespace.update({f'unit{j}': row for j, row in program._unit_rows.items()})
    program.step_source = source = '\n'.join(lines) + '\n'
    exec(compile(source, '<sample_program step>', 'exec'), namespace)   # noqa: S102
    return namespace['step']
