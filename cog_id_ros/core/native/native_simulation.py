"""The Simulation step compiled with the kernels: kernels_simulation.c, sized for a mechanism.

simulation.py's RK4 step calls the kernels about fifteen times and decides in Python between
the calls; for a small mechanism the deciding costs more than the kernels. With compiled
kernels the library of the forward kernel (kernels.NativeKernels, loaded on first use)
also holds ``rk4_step``, the same (sub)step in C for the case the Python step
takes most often (every stage one continuation step away, closed by Newton, not singular),
with its error estimate (simulation_error.step_error), the same operations in the same
order; otherwise it returns None and the Python step runs. The Python step divides a time
step into substeps and calls it once per substep.
This module writes the constants it is compiled with: the mechanism's sizes and joint
indices, where each field sits in the kernels' flat outputs (kernels.layouts), and
the Newton constants (newton.py).
"""
from importlib import resources
from typing import Dict, List, Optional, Sequence, Tuple

from ..closure import newton
from ..closure.continuation import TWO_PI, wrapping_actuators
from ..model.mechanism import Mechanism

#: the C of the step (package data beside this module)
C_SIMULATION = 'kernels_simulation.c'

#: the module function it adds: (name, doc)
METHODS = [('rk4_step', 'one Simulation substep and its error estimate, or None where the '
                         'Python step must take it')]


def offsets(layout: Sequence[Tuple[str, tuple]]) -> Dict[str, int]:
    """Where each field of a kernel's flat output starts (and 'width': the whole)."""
    out, at = {}, 0
    for name, shape in layout:
        out[name] = at
        size = 1
        for n in shape:
            size *= n
        at += size
    out['width'] = at
    return out


def _int_array(name: str, values: Sequence[int]) -> str:
    body = ', '.join(str(int(v)) for v in values) or '0'
    return f'static const int {name}[{max(len(values), 1)}] = {{{body}}};'


def simulation_source(mechanism: Mechanism, layouts: Dict[str, List[Tuple[str, tuple]]]
                      ) -> str:
    """The C of ``rk4_step`` for ``mechanism``'s kernels (after their bodies in a module)."""
    m = mechanism
    closing, forward = offsets(layouts['closure']), offsets(layouts['forward'])
    defines = {
        'SIM_N': m.n_coordinates, 'SIM_DOF': m.dof, 'SIM_M': len(m.active_joints),
        'SIM_FREE': len(m.free_joints), 'SIM_REDUNDANT': int(m.is_redundant),
        'SIM_WRAPPING': len(wrapping_actuators(m)),
        'SIM_CLOSURE_WIDTH': closing['width'], 'SIM_FORWARD_WIDTH': forward['width'],
        'SIM_OFF_INC': closing['increment'], 'SIM_OFF_WORST': closing['worst'],
        'SIM_OFF_LEAST': closing['least_cosine'], 'SIM_OFF_LARGEST': closing['largest_step'],
        'SIM_OFF_COND': forward['condition'], 'SIM_OFF_ACC': forward['accelerations'],
        'SIM_OFF_BASIS': forward['basis'], 'SIM_OFF_INERTIA': forward['inertia_condition'],
        'SIM_NEWTON_ITERATIONS': newton.NEWTON_ITERATIONS,
        'SIM_NEWTON_MAX_INCREMENT': repr(float(newton.NEWTON_MAX_INCREMENT)),
        'SIM_LIKELY_CLOSED': repr(float(newton.LIKELY_CLOSED)),
        'SIM_STAGNATION': repr(float(newton.STAGNATION)),
        'SIM_TWO_PI': repr(TWO_PI),
    }
    assert closing['worst'] == forward['worst'] and closing['increment'] == forward['increment']
    lines = [f'#define {name} {value}' for name, value in defines.items()]
    lines += [_int_array('sim_free', m.free_joints),
              _int_array('sim_active', m.active_index),
              _int_array('sim_primary_active', m.primary),
              _int_array('sim_primary_joint', m.primary_joints),
              _int_array('sim_wrapping', wrapping_actuators(m))]
    text = resources.files(__package__).joinpath(C_SIMULATION).read_text(encoding='ascii')
    return '\n'.join(lines) + '\n\n' + text


def step_config(time_step: float, mechanism: Mechanism, inertia_limit: float,
                limits: Sequence[float], bounds: Sequence[float], scales: Sequence[float],
                speed_floor: float, closure_tolerance: float,
                condition_limit: Optional[float] = None) -> List[float]:
    """The ``cfg`` argument of rk4_step: [h, ``closure_tolerance``, the condition number
    accepted (``condition_limit``, else the mechanism's max_condition_number), inertia
    limit, joint step limits (n), Newton correction bounds (n), the error norm's unit
    scales (n), its speed floor (simulation_error.py)]."""
    m = mechanism
    condition = m.max_condition_number if condition_limit is None else condition_limit
    return ([float(time_step), float(closure_tolerance), float(condition),
             float(inertia_limit)] + [float(x) for x in limits] +
            [float(x) for x in bounds] + [float(x) for x in scales] + [float(speed_floor)])
