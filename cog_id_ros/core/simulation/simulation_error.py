"""The Simulation's error control and what it reports (simulation.py, docs/simulation.md).

**The error estimate of a step.** RK4's stages and the accelerations at the end of the step
(which the simulator evaluates anyway: they are the next step's first stage) make an
embedded pair: ``b* = (1/6, 1/3, 1/3, 0, 1/6)`` over (k1, k2, k3, k4, k5 = a(z', zd')) is
a third-order rule, so its difference from RK4's fourth-order one,

    dz  = h/6 (zd4 - zd')        dzd = h/6 (k4 - k5)

estimates the local error of a step at no extra evaluation (of the third-order rule: RK4's
own is smaller by a further power of h). It is measured where the mechanism moves, in every
joint (V' dz, V' dzd with V' the velocity basis at the end of the step), each joint in its
unit (``unit_scales``: 1 rad, the mechanism's length scale, half a quaternion turn): the
position error in those units, the velocity error relative to the fastest joint's speed
(plus :data:`SPEED_FLOOR`). Near a singular pose of the actuators the passive joints move
ever faster for the actuators' rates (V grows), and so does the estimate: a step is divided
there, and where even substeps of :data:`SHORTEST_SUBSTEP` do not meet the tolerance the
simulation stops, instead of stepping on with an energy it no longer keeps.

**The branch check.** Over a step every joint must move as its rates say: the motion of
each joint differs from the trapezoid of its rates at the two ends by an error of third
order in h, so a step whose passive joints came out on another assembly branch (where the
same actuator positions close the loops with other passive rates) differs by a share of
the step's motion. :func:`step_error` returns that difference and the motion; a step whose
difference exceeds :data:`BRANCH_RATIO` of its motion is divided as one whose error is too
large.

**The evaluations' rounding.** Near a singular pose the forward dynamics themselves lose
digits, about (s + eps) kappa^2 of the accelerations (:func:`rounding`); what that may
put into a step, weighted as RK4 weighs its stages, is added to the estimate
(:func:`judge`). A divided step's stages are closed to :data:`CAREFUL_CLOSURE` and may
pass poses up to :data:`PASS_CONDITION_LIMIT` (a change point, where the branches cross and
the motion goes on), and Simulation keeps a division only where its parts' estimates add
up to less than the whole's; a step that cannot get below :data:`STOP_ESTIMATE` stops it.

Both are computed by :func:`step_error`, :func:`acceleration_scale` and :func:`rounding`
in Python and by kernels_simulation.c in C with the same operations in the same order, so
the two steps decide alike, to the bit.
"""
import math
import sys
from typing import TYPE_CHECKING, Any, List, NamedTuple, Optional, Sequence, Tuple, cast

from ..closure.continuation import correction_ok, fits_one_step, joint_step_limits, wrapped_state
from ..dynamics.newton_euler import rotated_inertia_times
from ..errors import ClosureError, CogIdError, SingularConfigurationError
from ..kinematics.kinematics import forward_kinematics, link_twists
from ..linalg import spatial as sp
from ..solve.forward_solve import checked

if TYPE_CHECKING:
    from ..closure.continuation import State
    from ..model.mechanism import Mechanism
    from ..native.kernels import ForwardRecord
    from ..solve.sample_solve import SampleSolver

#: the default local error tolerance of a step (Simulation(tolerance=...)): position error in
#: joint units (rad, or the mechanism's length scale), velocity error relative to the speed
DEFAULT_TOLERANCE = 1e-7
#: the tolerances Simulation accepts
TOLERANCE_RANGE = (1e-12, 1e-2)
#: the shortest substep, in time steps: a substep this short is not divided further
SHORTEST_SUBSTEP = 1.0 / 1024.0
#: units per second added to the fastest joint's speed in the velocity error's denominator
#: (so that a mechanism at rest is not held to a relative error of nothing)
SPEED_FLOOR = 1.0
#: the share of a step's motion by which its joints may move otherwise than their rates say
BRANCH_RATIO = 0.25
#: the closure Jacobian condition number a divided step's stages may have (an undivided one's
#: keep to mechanism.max_condition_number): a change point, where branches cross and the
#: mechanism passes on its own, is singular, and a time step may end within rounding of it.
#: What such a pose's accelerations lose (:func:`rounding`) goes into the estimate, and the
#: substeps beside it get shorter until it weighs within the tolerance, or no shorter one
#: does better (reported: ``Diagnostics.inaccurate_substeps``); beyond it the accelerations
#: keep no digit, and a stage there fails
PASS_CONDITION_LIMIT = 1e8
#: near a singular pose the forward dynamics lose up to about this times (s + eps) kappa^2
#: of their accelerations (:func:`rounding`; s the Newton increment left, kappa the closure
#: condition number). Measured on the paper four-bar's stages near its flat pose, against
#: its exact equation of motion: at most 0.9 (kappa 1e3), 0.5 (1e4), 2.3 (1e5), 6 (1e6)
#: times that; newton.py observed up to 0.24 for the torques
EVALUATION_FACTOR = 3.0
EPSILON = sys.float_info.epsilon
#: the largest estimate a step may end with (a share of the speed): a step whose divisions
#: cannot bring its estimate below it (its evaluations near a singular pose are off by
#: more than that much) is refused, and the simulation stops there
STOP_ESTIMATE = 1e-2
#: m or rad: the closure residual a divided step's stages are closed to (or closure_tolerance
#: where that is smaller; closure_tolerance where Newton's method cannot get below it: the
#: rounding of a large mechanism). Near a singular pose a residual r leaves the passive
#: joints off by up to r times the condition number, and the accelerations, which vary fast
#: there, carry that into the motion: the five-bar passing near its singular pose lost 5e-7
#: of its energy with stages closed to 1e-10, 1e-8 with 1e-11 or less. (An undivided step
#: keeps to closure_tolerance: on a fast motion closing further costs a Newton iteration a
#: stage, 50 % more on the Stewart platform falling)
CAREFUL_CLOSURE = 1e-13


class Point(NamedTuple):
    """Where a substep starts: the pose and basis, the primary rates, the primary
    accelerations there with the step's efforts (None: not known yet), and the rounding
    measure there (:func:`rounding`)."""
    state: 'State'
    zd: List[float]
    k1: Optional[List[float]]
    rounding: float


class Substep(NamedTuple):
    """One RK4 substep's result: the pose, the primary rates and the active accelerations at
    its end, the closure residual and condition numbers there, :func:`step_error`, the
    largest rounding measure (:func:`rounding`) of its evaluations at its ends (k1 when
    evaluated, k4, k5) and between them (k2, k3), and its largest primary acceleration in
    joint units (:func:`acceleration_scale`)."""
    state: 'State'
    zd: List[float]
    accelerations: List[float]
    worst: float
    condition: float
    inertia_condition: float
    error: float
    mismatch: float
    motion: float
    speed: float
    end_rounding: float
    inner_rounding: float
    acceleration_scale: float


class Diagnostics(NamedTuple):
    """What the last step did and where the simulation is (``Simulation.diagnostics``).

    The energies are of the model (kinetic of every link, potential in its gravity, zero at
    the base origin), in J where the parameters are SI; ``work`` is the efforts' since the
    last reset (exactly ``tau . delta theta`` per step, the efforts being held over it), and
    ``energy_drift`` = ``energy`` - the energy at the reset - ``work``: what the
    integration gained (or lost) on its own. The error estimates are in the tolerance's
    measure (simulation_error.py); ``substeps`` 1 is an undivided step, 0 none yet."""
    time: float
    steps: int
    substeps: int
    error_estimate: float
    tolerance: float
    divided_steps: int
    total_substeps: int
    largest_error_estimate: float
    total_error_estimate: float
    shortest_substep: float
    near_singular_substeps: int
    inaccurate_substeps: int
    closure_residual: float
    condition_number: float
    inertia_condition: float
    kinetic_energy: float
    potential_energy: float
    energy: float
    work: float
    energy_drift: float


class Totals:
    """The counts behind the diagnostics: of the last step and since the reset."""

    __slots__ = ('substeps', 'error_estimate', 'divided_steps', 'total_substeps',
                 'largest_error_estimate', 'total_error_estimate', 'shortest_substep',
                 'near_singular_substeps', 'inaccurate_substeps')

    def __init__(self) -> None:
        self.substeps = self.divided_steps = self.total_substeps = 0
        self.near_singular_substeps = self.inaccurate_substeps = 0
        self.error_estimate = self.largest_error_estimate = self.total_error_estimate = 0.0
        self.shortest_substep = math.inf

    def add(self, counts: Sequence[Any]) -> None:
        """One more step: ``counts`` = [substeps, summed estimate, shortest substep, near
        singular, inaccurate]."""
        substeps, estimate, shortest, near, inaccurate = counts
        self.substeps, self.error_estimate = substeps, estimate
        self.divided_steps += substeps > 1
        self.total_substeps += substeps
        if not estimate <= self.largest_error_estimate:
            self.largest_error_estimate = estimate
        self.total_error_estimate += estimate
        if shortest < self.shortest_substep:
            self.shortest_substep = shortest
        self.near_singular_substeps += near
        self.inaccurate_substeps += inaccurate


def unit_scales(mechanism: 'Mechanism') -> List[float]:
    """Per coordinate, 1 / its unit in the error norm: 1 rad, the mechanism's length scale
    (continuation.length_scale) for a length, half a turn's share for a quaternion's
    component (continuation.joint_step_limits at a step of 1)."""
    return [1.0 / limit for limit in joint_step_limits(mechanism, 1.0)]


def _dot(row: Sequence[float], v: Sequence[float]) -> float:
    s = row[0] * v[0]
    for k in range(1, len(v)):
        s = s + row[k] * v[k]
    return s


def _larger(x: float, acc: float) -> float:
    """The larger of x and acc; NaN once NaN (C: sim_larger)."""
    return x if x > acc or x != x else acc


def step_error(h: float, start: 'State', zd: Sequence[float], end: 'State',
               zd_end: Sequence[float], zd4: Sequence[float], k4: Sequence[float],
               k5: Sequence[float], scales: Sequence[float]
               ) -> Tuple[float, float, float, float]:
    """(error estimate, branch mismatch, motion, speed) of an RK4 step of length h from
    ``start`` (pose, basis) with primary rates zd to ``end`` with zd_end; zd4, k4 the fourth
    stage's rates and accelerations, k5 the accelerations at the end (primary actuators).
    The operations of kernels_simulation.c's sim_error, in its order."""
    sixth, half = h / 6.0, 0.5 * h
    dz = [sixth * (a - b) for a, b in zip(zd4, zd_end)]
    dv = [sixth * (a - b) for a, b in zip(k4, k5)]
    position = velocity = speed = mismatch = motion = 0.0
    q0, basis0 = start
    q1, basis1 = end
    for j, u in enumerate(scales):
        row0, row1 = basis0[j], basis1[j]
        r0, r1 = _dot(row0, zd), _dot(row1, zd_end)
        position = _larger(abs(_dot(row1, dz)) * u, position)
        velocity = _larger(abs(_dot(row1, dv)) * u, velocity)
        speed = _larger(abs(r0) * u, speed)
        speed = _larger(abs(r1) * u, speed)
        d = q1[j] - q0[j]
        motion = _larger(abs(d) * u, motion)
        mismatch = _larger(abs(d - half * (r0 + r1)) * u, mismatch)
    return _larger(velocity / (speed + SPEED_FLOOR), position), mismatch, motion, speed


def acceleration_scale(stages: Sequence[Sequence[float]], scales: Sequence[float],
                       joints: Sequence[int]) -> float:
    """The largest primary acceleration of an RK4 step's five evaluations (k1 ... k5), each
    in its joint's units (``joints``: the primary actuators' coordinates); C: in rk4_step."""
    largest = 0.0
    for k in stages:
        for a, j in zip(k, joints):
            largest = _larger(abs(a) * scales[j], largest)
    return largest


def rounding(records: Sequence[Any], largest: float = 0.0) -> float:
    """The largest rounding measure of ``records`` and ``largest``, in their order (C:
    sim_rounding): (s + eps) kappa^2 + eps kappa_H of each, s the Newton increment left at
    its pose (``largest_step``), kappa its closure condition number, kappa_H its inertia's.
    About what the accelerations there lose of themselves, up to EVALUATION_FACTOR."""
    for record in records:
        kappa = record.condition
        largest = _larger((record.largest_step + EPSILON) * kappa * kappa +
                          EPSILON * record.inertia_condition, largest)
    return largest


def judged(sub: Substep, h: float, time_step: float, tolerance: float, start: float
           ) -> Tuple[bool, bool, float, float]:
    """(accepted, passable, its estimate, the evaluations' rounding in it): :func:`judge`
    of a substep of length h from a pose of rounding measure ``start``."""
    return judge(h, time_step, tolerance, start, *sub[6:])


def judge(h: float, time_step: float, tolerance: float, start: float, error: float,
          mismatch: float, motion: float, speed: float, end_rounding: float,
          inner_rounding: float, scale: float) -> Tuple[bool, bool, float, float]:
    """(accepted, passable, its estimate, the evaluations' rounding in it) of a substep of
    length h (its Substep fields from ``error`` on). Passable: the truncation estimate
    within the tolerance's share h / time_step of it (plus the evaluations' rounding, which
    it holds too) and the branch check met; accepted: also the rounding within the
    tolerance (Simulation divides a passable substep, and keeps the parts where they lower
    the estimate). False for NaN.

    The rounding: near a singular pose the accelerations lose about EVALUATION_FACTOR times
    :func:`rounding`'s measure of themselves (``start``: the measure at the substep's
    start); k1 and k4 (at its ends) weigh h/6 each in the rates, k2 and k3 (between them)
    h/3; relative to the speed, as the velocity error."""
    weight = EVALUATION_FACTOR * scale / (speed + SPEED_FLOOR)
    ends = h / 3.0 * weight * max(end_rounding, start)
    lost = ends + 2.0 * h / 3.0 * weight * inner_rounding
    passable = (error <= tolerance * (h / time_step) + lost and
                mismatch <= BRANCH_RATIO * motion + tolerance)
    return passable and lost <= tolerance, passable, error + lost, lost


def at_shortest(exc: CogIdError, h: float, at: float) -> CogIdError:
    """``exc``, met by a substep of the shortest length h (from time ``at``), said again with
    where: the pose the motion reaches there is one the simulation cannot go past."""
    where = (f' (in a substep of {h:.3g} s, the shortest, from t = {at:.9g} s: the motion '
             f'reaches a pose the simulation cannot go past, a singular pose or a dead centre '
             f'beyond which the loops do not close)')
    if isinstance(exc, SingularConfigurationError):
        return SingularConfigurationError(f'{exc}{where}', exc.condition_number)
    if isinstance(exc, ClosureError):
        return ClosureError(f'{exc}{where}', exc.residual, reason=exc.reason or 'closure')
    return exc


def not_evaluated(estimate: float, at: float, conditions: Tuple[float, float],
                  start: Tuple[float, float]) -> CogIdError:
    """SingularConfigurationError for a step (from time ``at``) whose estimate stays above
    STOP_ESTIMATE: the accelerations cannot be evaluated near the singular pose it ends or
    passes at (``conditions``: the closure and inertia condition numbers at its end;
    ``start``: at its start)."""
    worst = max(conditions)
    return SingularConfigurationError(
        f'the motion cannot be evaluated accurately enough: the step from t = {at:.9g} s '
        f'passes so near a singular pose that its error estimate stays at {estimate:.3g} '
        f'(more than {STOP_ESTIMATE:g} of the speed) however it is divided; the closure '
        f'Jacobian condition number is {conditions[0]:.3g} at its end and the inertia '
        f'condition {conditions[1]:.3g} (at its start: {start[0]:.3g} and {start[1]:.3g}). '
        f'Where the branches cross there (a change point) a time_step whose steps do not end '
        f'as near it passes it', worst if worst == worst else math.inf)


def careful_tolerance(mechanism: 'Mechanism') -> float:
    """The closure residual the simulation's stages are closed to: :data:`CAREFUL_CLOSURE`,
    or closure_tolerance where that is smaller."""
    return min(mechanism.closure_tolerance, CAREFUL_CLOSURE)


def relaxed_stage(serial: 'SampleSolver', state: 'State', target: Sequence[float],
                  qd: Sequence[float], tau: Sequence[float], limit: float
                  ) -> Optional[Tuple['ForwardRecord', 'State']]:
    """A stage of a divided step closed as SampleSolver.solve closes one continuation step
    (prediction, Newton to ``serial``'s tolerance, the correction within its bounds), with
    closure condition numbers up to ``limit`` accepted; None where that does not apply
    (more than one continuation step, a turn to take off, Newton not closing, a larger
    condition or correction: the solver's own continuation then decides, and raises).
    kernels_simulation.c's sim_stage with ``limit`` in its configuration."""
    m = serial.mechanism
    if wrapped_state(m, serial.wrapping, state, target) is not state:
        return None
    predicted, moved = serial.kernels.prediction(state[0], state[1], target)
    if not fits_one_step(m, serial.limits, state, target, moved):
        return None
    q, record, _, ok = serial.close(predicted, target, qd, tau)
    if not ok or not record.condition <= limit or \
            not correction_ok(q, predicted, serial.bounds):
        return None
    return checked(m, cast('ForwardRecord', record), qd, tau, None), (q, serial.basis(record))


def energy(mechanism: 'Mechanism', q: Sequence[float], qdot: Sequence[float]
           ) -> Tuple[float, float]:
    """(kinetic, potential) energy of the solver's model at coordinates q with rates qdot:
    1/2 (m v.v + w.I w) of every link at its COG, and -m g.c (zero at the base origin)."""
    frames = forward_kinematics(mechanism.model, q, sp.ScalarOps)
    twists = link_twists(mechanism.model, frames, qdot)
    kinetic = potential = 0.0
    gravity = tuple(mechanism.gravity)
    for i, (mass, com, inertia) in enumerate(zip(mechanism.link_mass, mechanism.link_com,
                                                 mechanism.link_inertia)):
        rot = frames.rot[i]
        c = sp.add(frames.pos[i], sp.mat_vec(rot, com))
        w, v0 = twists[i]
        v = sp.add(v0, sp.cross(w, c))
        kinetic += 0.5 * (mass * sp.dot(v, v) + sp.dot(w, rotated_inertia_times(rot, inertia,
                                                                                   w)))
        potential -= mass * sp.dot(gravity, c)
    return kinetic, potential


def not_followed(sub: Substep, h: float, at: float, tolerance: float,
                 start: Tuple[float, float], met: Optional[CogIdError] = None) -> CogIdError:
    """SingularConfigurationError for a substep of length h (at time ``at``) that no
    division meets the tolerance (or the branch check) in: where the equations of motion in
    the actuators' coordinates stop being smooth, at a singular pose ahead. ``start``: the
    closure and inertia condition numbers at the start of the time step; ``met``: the first
    error a longer substep's stages met (beyond the singular pose), said too."""
    if sub.mismatch <= BRANCH_RATIO * sub.motion + tolerance:
        what = f'its error estimate is {sub.error:.3g} (tolerance {tolerance:.3g} a time step)'
    else:
        what = (f'its joints move otherwise than their rates say by {sub.mismatch:.3g} (of a '
                f'motion of {sub.motion:.3g}, joint units): the closure would put the passive '
                f'joints on another assembly branch')
    worst = max(sub.condition, sub.inertia_condition)
    return SingularConfigurationError(
        f'the motion cannot be followed to the tolerance: even in a substep of {h:.3g} s '
        f'(the shortest, {SHORTEST_SUBSTEP:.3g} time step), from t = {at:.9g} s, {what}. The '
        f'closure Jacobian condition number reaches {sub.condition:.3g} there and the inertia '
        f'condition {sub.inertia_condition:.3g} (at the start of the step: {start[0]:.3g} '
        f'and {start[1]:.3g}): a singular pose ahead, where the actuators stop being coordinates '
        f'of the mechanism (its motion could only go on into another assembly mode, which '
        f'the simulation does not follow)' + ('' if met is None else
                                              f'; a longer substep met this beyond it: {met}'),
        worst if worst == worst else math.inf)
