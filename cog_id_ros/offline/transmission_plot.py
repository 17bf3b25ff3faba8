"""``cog_id_inspect --transmission FILE``: the map between actuator space and joint space
over the range of each joint-space joint, where the transmission gets weak.

Each joint of ``mechanism.joint_space`` is swept in turn, the others held at the assembled
pose: over its limits (``joints.<name>.lower`` / ``upper``, a URDF's ``<limit>``), or,
without limits, out from the assembled pose as far as the map stays non-singular (at most
:data:`FREE_RANGE` rad, or that many length scales for a prismatic joint). Each pose is
solved from the last (the transmission's warm starts, both directions from the assembled
pose), and at each the Jacobian J = dq/dtheta of the motors' positions is taken
(``Transmission.jacobian``). A sweep stops where the solver cannot go on (the loops close
no more, or one set of joints cannot drive the other: a rod in line with its crank), or
where the motors turn back (the motors' pose of q gives back another q: J went through
infinity between two poses of the sweep); the report says where.

The picture: per joint-space joint, the singular values of J (a single ratio dq/dtheta,
signed, for one motor and one joint) and the condition number of J (for a 1 x 1 map the
joint torque a unit motor torque makes, 1/|J|, instead): J large is fast and weak, tau_q =
K^T tau_m, and the weakest direction of the joint space gets 1/sigma_max(J) per unit motor
torque. Matplotlib's object API on the Agg canvas (no pyplot, no display).
"""

import math

import numpy as np

from . import figure_text

#: poses per sweep (both directions from the assembled pose together)
POINTS = 161
#: the half range swept from the assembled pose where a joint has no limits (rad; for a
#: prismatic joint, this many times the mechanism's length scale)
FREE_RANGE = math.pi
#: every joint-space joint has a picture row up to this many
MAX_ROWS = 8
#: the joint-space positions the motors' pose of a sweep's q gives back must be q to this
#: (rad or m): else the motors passed a singular pose and hold another pose there
SAME_POSE = 1e-6
#: halvings of the last step where the solver stops a sweep (the end closed in on)
REFINE = 8
#: how a stop the solver raised ends its line
SOLVER_STOP = ' (the solver)'
COLORS = ('#1f77b4', '#ff7f0e', '#2ca02c', '#9467bd', '#8c564b', '#e377c2')


class Sweep:
    """One joint-space joint swept: ``joint``, its index ``k``, ``grid`` (n,) positions
    solved, ``jacobians`` (n, D, M), ``range`` (lo, hi) asked for, ``limited`` (its own
    limits) and ``stops`` {'lower'|'upper': message} where the sweep ended early."""

    def __init__(self, joint, k, asked, limited):
        self.joint, self.k, self.range, self.limited = joint, k, asked, limited
        self.grid = np.zeros(0)
        self.jacobians = np.zeros((0, 0, 0))
        self.stops = {}
        self.unit = 'rad'

    @property
    def singular_values(self):
        return np.linalg.svd(self.jacobians, compute_uv=False) if len(self.grid) else \
            np.zeros((0, 0))

    @property
    def condition_numbers(self):
        s = self.singular_values
        with np.errstate(all='ignore'):
            return s[:, 0] / s[:, -1] if s.size else np.zeros(0)


def home(mech):
    """The joint-space positions of the assembled pose."""
    return np.array([mech.assembled_positions[mech.joint_index[name]]
                     for name in mech.joint_space])


def sweep_range(mech, name):
    """((lo, hi), limited): the joint's limits, or FREE_RANGE either side of its assembled
    position."""
    j = mech.joint_index[name]
    lo, hi = mech.position_limits[j]
    if math.isfinite(lo) and math.isfinite(hi):
        return (float(lo), float(hi)), True
    kind = joints_kind(mech, j)
    half = FREE_RANGE * (1.0 if kind.unit == 'rad' else getattr(mech, 'length_scale', 1.0))
    q0 = float(mech.assembled_positions[j])
    return (lo if math.isfinite(lo) else q0 - half, hi if math.isfinite(hi) else q0 + half), \
        False


def joints_kind(mech, j):
    return mech.joint_specs[j].kind


def sweep(transmission, points=POINTS):
    """[Sweep] of every joint of the joint space (:mod:`module docstring <.>`)."""
    mech = transmission.mechanism
    q0 = home(mech)
    result = []
    for k, name in enumerate(mech.joint_space):
        asked, limited = sweep_range(mech, name)
        s = Sweep(name, k, asked, limited)
        s.unit = joints_kind(mech, mech.joint_index[name]).unit
        lo, hi = asked
        step = (hi - lo) / (points - 1)
        start = min(max(q0[k], lo), hi)
        up = np.arange(start, hi + 0.5 * step, step)
        down = np.arange(start - step, lo - 0.5 * step, -step)
        grid, jacs = [], []
        for side, values in (('upper', up), ('lower', down)):
            solved, maps = _walk(transmission, q0, k, values, s, side)
            grid.extend(solved)
            jacs.extend(maps)
        order = np.argsort(grid)
        s.grid = np.asarray(grid)[order]
        s.jacobians = np.asarray(jacs).reshape(len(grid), len(mech.joint_space), -1)[order]
        result.append(s)
    return result


def _walk(transmission, q0, k, values, s, side):
    """([q_k], [J]) at ``values`` of joint k from the assembled pose on, until one fails;
    then the end is closed in on by bisection (:data:`REFINE` halvings)."""
    for solver in (transmission.actuators, transmission.joints):
        solver.reset()
    q = q0.copy()
    grid, out = [], []
    for value in values:
        why = _one(transmission, q, k, value, s, out)
        if why is None:
            grid.append(value)
            continue
        s.stops[side] = why
        good = grid[-1] if grid else None
        for _ in range(REFINE if good is not None and why.endswith(SOLVER_STOP) else 0):
            mid = 0.5 * (good + value)
            if _one(transmission, q, k, mid, s, out) is None:
                grid.append(mid)
                good = mid
            else:
                value = mid
        break
    return grid, out


def _one(transmission, q, k, value, s, out):
    """J at q with q[k] = value appended to ``out``; else why not (a line)."""
    import cog_id_ros
    q[k] = value
    try:
        theta = transmission.to_actuator_space(q)
        back = transmission.to_joint_space(theta)
        if not np.allclose(back, q, rtol=0.0, atol=SAME_POSE):
            return (f'{s.joint} = {value:.4g}: the motors turn back here (J unbounded: a '
                    'singular pose of the transmission); past it, the same motor positions '
                    'hold another pose')
        out.append(transmission.jacobian(theta))
    except cog_id_ros.CogIdError as exc:
        text = ' '.join(str(exc).split())
        return f'{s.joint} = {value:.4g}: {text.split(". ")[0][:200]}{SOLVER_STOP}'
    return None


def format_sweeps(sweeps):
    """Lines for the report: per joint the range solved, the ratio and conditioning."""
    lines = ['transmission (J = dq/dtheta of the motors over each joint-space joint, the '
             'others at the assembled pose):']
    for s in sweeps:
        if not len(s.grid):
            lines.append(f'  {s.joint}: no pose solved ({"; ".join(s.stops.values())})')
            continue
        sv = s.singular_values
        where = 'its limits' if s.limited else 'no limits: swept out from the assembled pose'
        if s.jacobians.shape[1:] == (1, 1):
            what = f'ratio dq/dtheta {s.jacobians.min():.4g} .. {s.jacobians.max():.4g}'
        else:
            what = (f'singular values of J {sv.min():.4g} .. {sv.max():.4g}; condition '
                    f'number <= {np.nanmax(s.condition_numbers):.4g}')
        lines.append(f'  {s.joint}: {s.grid[0]:.4g} .. {s.grid[-1]:.4g} {s.unit} ({where}); '
                     + what)
        for side, why in s.stops.items():
            lines.append(f'    stopped at the {side} end: {why}')
    return lines


def draw_transmission(path, mech, sweeps, fmt='png', title=None):
    """The picture of :func:`sweep`'s result (module docstring) into ``path``."""
    from matplotlib.figure import Figure
    shown = sweeps[:MAX_ROWS]
    fig = Figure(figsize=(10.0, 1.2 + 2.6 * len(shown)), dpi=90, layout='constrained')
    axes = fig.subplots(len(shown), 2, squeeze=False)
    one = all(s.jacobians.shape[1:] == (1, 1) for s in sweeps if len(s.grid))
    for s, (left, right) in zip(shown, axes):
        _panel(s, left, right, one)
    heading = title or (f'{mech.name}: transmission between actuator space '
                        f"({', '.join(mech.active_joints)}) and joint space "
                        f"({', '.join(mech.joint_space)})\neach joint swept with the others "
                        'at the assembled pose; the weakest direction of the joint space '
                        'gets 1/\u03c3max(J) per unit motor torque')
    figure_text.suptitle(fig, heading, 11)
    fig.savefig(path, format=fmt, dpi=90)


def _panel(s, left, right, one):
    unit = s.unit
    for ax in (left, right):
        ax.grid(True, alpha=0.3)
        ax.set_xlabel(f'{s.joint} [{unit}]')
        if s.stops:
            for side, why in s.stops.items():
                edge = s.grid[-1] if side == 'upper' else s.grid[0]
                ax.axvline(edge, color='#d62728', ls=':', lw=1.2)
    if not len(s.grid):
        left.set_title(f'{s.joint}: no pose solved', fontsize=9)
        return
    if one:
        ratio = s.jacobians[:, 0, 0]
        left.plot(s.grid, ratio, color=COLORS[0], label='dq/d\u03b8 (the ratio)')
        left.set_ylabel('dq/d\u03b8')
        with np.errstate(all='ignore'):
            right.plot(s.grid, 1.0 / np.abs(ratio), color=COLORS[1])
        right.set_ylabel('joint torque per motor torque\n1/|J|')
    else:
        sv = s.singular_values
        for i in range(sv.shape[1]):
            left.plot(s.grid, sv[:, i], color=COLORS[i % len(COLORS)],
                      label=f'\u03c3{i + 1}(J)')
        left.set_ylabel('singular values of\nJ = dq/d\u03b8')
        cond = s.condition_numbers
        right.plot(s.grid, cond, color=COLORS[3])
        if np.nanmax(cond) > 10.0 * np.nanmin(cond):
            right.set_yscale('log')
        right.set_ylabel('condition number of J\n(\u03c3max / \u03c3min)')
    left.legend(fontsize=8, loc='best')
    ends = ', '.join(f'{side} end: stopped (red dotted)' for side in s.stops)
    left.set_title(f'{s.joint}: the ratio' + (f' ({ends})' if ends else ''), fontsize=9)
    right.set_title(f'{s.joint}: where it gets weak' if not one else
                    f'{s.joint}: strength (low: weak)', fontsize=9)
