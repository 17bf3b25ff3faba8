"""Plots of the offline tools: ``cog_id_torques`` (one panel per active joint, effort
against time) and ``cog_id_simulate`` (positions against time, :func:`plot_motion`).

Matplotlib's object API on the Agg canvas: no pyplot, no display, no global backend
switch, so it works on a headless machine and inside other programs.
"""

import math
import warnings

import numpy as np

from . import figure_text

#: below this many samples the curve also shows the sample points
_MARKER_LIMIT = 60


def supported_formats():
    """File extensions matplotlib can write (png, pdf, svg, ...)."""
    from matplotlib.backend_bases import FigureCanvasBase
    return sorted(FigureCanvasBase.get_supported_filetypes())


def _fmt(value):
    return f'{value:.4g}'


def _quantity(unit):
    """('torque', 'tau') for N m, ('force', 'F') for N."""
    return ('force', 'F') if unit == 'N' else ('torque', '\u03c4')


def plot_efforts(path, time, efforts, valid, joints, stats, title, units, subtitle=None,
                 fmt='png', forces=None):
    """Draw and save the effort plot (see :func:`_plot`); when matplotlib cannot lay out
    the time axis (times near 1e308 s overflow its tick computation), the curves are
    drawn against the row number instead, and the axis label says why. ``forces``
    (a floating base): {contact: vertical force (N,)}, one more panel under the efforts."""
    with warnings.catch_warnings(), np.errstate(all='ignore'):
        warnings.simplefilter('ignore', RuntimeWarning)    # matplotlib's, on extreme data
        try:
            _plot(path, time, efforts, valid, joints, stats, title, units, subtitle, fmt, False,
                  forces)
        except (ValueError, OverflowError, FloatingPointError):
            _plot(path, time, efforts, valid, joints, stats, title, units, subtitle, fmt, True,
                  forces)


def _contact_panel(ax, time, forces, valid, marker):
    """The contacts' vertical forces (N, world z) in one panel; skipped rows are gaps."""
    ax.axhline(0.0, color='0.75', lw=0.8, zorder=0)
    for k, (name, fz) in enumerate(forces.items()):
        values = np.asarray(fz, dtype=float)
        factor, scaled = _scale(np.where(valid, values, 0.0))
        ax.plot(time, np.where(valid, values, np.nan) * factor, color=f'C{k % 10}', lw=1.4,
                marker=marker, ms=4, label=f'{name} fz{scaled}')
    if not forces:
        ax.text(0.5, 0.5, 'no contact (--contacts none)', transform=ax.transAxes,
                ha='center', va='center', color='0.4')
    ax.set_ylabel('vertical force  [N]')
    ax.grid(True, color='0.9', lw=0.6)
    if forces:
        ax.legend(loc='upper left', bbox_to_anchor=(1.01, 1.0), fontsize='small',
                  frameon=False, borderaxespad=0.0)
    ax.set_title('contacts: vertical force fz (world z, on the robot)', loc='left',
                 fontsize='medium', fontweight='bold')


def _scale(values):
    """(factor, label) for drawing values beyond 1e250 in units of a power of ten (matplotlib
    cannot lay out an axis near the largest double); (1.0, '') otherwise."""
    finite = np.abs(values[np.isfinite(values)])
    largest = float(finite.max()) if finite.size else 0.0
    if largest <= 1e250:
        return 1.0, ''
    power = int(math.floor(math.log10(largest)))
    return 10.0 ** -power, f' \u00d7 1e{power}'


def _plot(path, time, efforts, valid, joints, stats, title, units, subtitle, fmt, by_row,
          forces=None):
    """Draw and save the effort plot.

    ``time`` (N,), ``efforts`` (N, M), ``valid`` (N,) bool (False: skipped sample, drawn
    as a gap with a red tick under it), ``joints`` M names, ``stats`` M dicts with
    ``peak_effort``, ``peak_effort_signed``, ``peak_effort_time``, ``peak_effort_row``,
    ``rms_effort`` (values ``None`` when no sample of the joint was solved), ``units``
    M unit strings (``'N m'`` or ``'N'``), ``title`` the figure title (the mechanism
    name), ``subtitle`` an optional second line. ``path`` may be a temporary name:
    ``fmt`` says the format; ``forces``: see :func:`plot_efforts`.
    """
    from matplotlib.figure import Figure

    time = np.asarray(time, dtype=float)
    if by_row:       # rows count from 1, like every message of the tool
        time = np.arange(1.0, time.size + 1.0)
    efforts = np.asarray(efforts, dtype=float).reshape(time.size, -1)
    valid = np.ones(time.size, bool) if valid is None else np.asarray(valid, bool)
    n_joints = efforts.shape[1]
    panels = n_joints + (forces is not None)
    fig = Figure(figsize=(10.0, 1.3 + 2.7 * panels), layout='constrained')
    axes = fig.subplots(panels, 1, sharex=True, squeeze=False)[:, 0]
    skipped = ~valid
    t_skipped = time[skipped]
    marker = '.' if time.size <= _MARKER_LIMIT else None
    for k, (ax, joint, st, unit) in enumerate(zip(axes, joints, stats, units)):
        quantity, symbol = _quantity(unit)
        factor, scaled = _scale(np.where(valid, efforts[:, k], 0.0))
        curve = np.where(valid, efforts[:, k], np.nan) * factor
        ax.axhline(0.0, color='0.75', lw=0.8, zorder=0)
        ax.plot(time, curve, color='C0', lw=1.4, marker=marker, ms=4,
                label=f'{joint} {quantity}')
        if st.get('peak_effort') is not None:
            x_peak = float(st['peak_effort_row']) if by_row else st['peak_effort_time']
            ax.plot([x_peak], [st['peak_effort_signed'] * factor], 'o', color='C3',
                    ms=7, mfc='none', mew=1.8,
                    label=f"peak |{symbol}| = {_fmt(st['peak_effort'])} {unit}  "
                          f"(t = {_fmt(st['peak_effort_time'])} s, row {st['peak_effort_row']})")
            rms = st['rms_effort']
            ax.axhline(rms * factor, color='C2', ls='--', lw=1.0,
                       label=f'RMS = {_fmt(rms)} {unit}  (dashed: \u00b1RMS)')
            ax.axhline(-rms * factor, color='C2', ls='--', lw=1.0)
        if t_skipped.size:
            ax.plot(t_skipped, np.zeros_like(t_skipped), '|', color='red', ms=12, mew=1.2,
                    transform=ax.get_xaxis_transform(), clip_on=False,
                    label=f'skipped rows ({t_skipped.size}): not solved')
        ax.set_ylabel(f'{quantity}  [{unit}{scaled}]')
        ax.grid(True, color='0.9', lw=0.6)
        ax.legend(loc='upper left', bbox_to_anchor=(1.01, 1.0), fontsize='small',
                  frameon=False, borderaxespad=0.0)
        ax.set_title(f'{joint}', loc='left', fontsize='medium', fontweight='bold')
    if forces is not None:
        _contact_panel(axes[-1], time, forces, valid, marker)
    axes[-1].set_xlabel('row  (the times are too large to draw an axis of)' if by_row
                        else 'time  [s]')
    if time.size:
        axes[-1].set_xlim(time[0], time[-1] if time[-1] > time[0] else time[0] + 1.0)
    kinds = sorted({_quantity(u)[0] for u in units})
    head = f"{title}: actuator {' and '.join(k + 's' for k in kinds)}" + (
        '' if forces is None else ', contact forces')
    if subtitle:
        head += '\n' + subtitle
    figure_text.suptitle(fig, head, 12)       # 'large', wrapped to the figure's width
    fig.savefig(path, format=fmt, dpi=110)


def plot_motion(path, time, positions, joints, units, title, subtitle=None, reference=None,
                fmt='png'):
    """The plot of ``cog_id_simulate``: one row per active joint, its simulated position
    against time; with ``reference`` (same shape, NaN where it has no value) the reference
    dashed beside it and a second column with the difference simulated - reference."""
    from matplotlib.figure import Figure

    time = np.asarray(time, dtype=float)
    positions = np.asarray(positions, dtype=float).reshape(time.size, -1)
    n_joints = positions.shape[1]
    columns = 1 if reference is None else 2
    fig = Figure(figsize=(6.0 + 4.5 * (columns - 1), 1.3 + 2.5 * n_joints),
                 layout='constrained')
    axes = fig.subplots(n_joints, columns, sharex=True, squeeze=False)
    for k, (joint, unit) in enumerate(zip(joints, units)):
        ax = axes[k, 0]
        ax.plot(time, positions[:, k], color='C0', lw=1.6, label='simulated')
        if reference is not None:
            ax.plot(time, reference[:, k], color='k', lw=1.0, ls='--', label='reference')
            diff = axes[k, 1]
            diff.axhline(0.0, color='0.75', lw=0.8, zorder=0)
            diff.plot(time, positions[:, k] - reference[:, k], color='C3', lw=1.2)
            diff.set_ylabel(f'simulated \u2212 reference  [{unit}]')
            diff.set_title(f'{joint}: difference', loc='left', fontsize='medium')
            diff.grid(True, color='0.9', lw=0.6)
            diff.ticklabel_format(axis='y', style='sci', scilimits=(-3, 3))
        ax.set_ylabel(f'position  [{unit}]')
        ax.set_title(f'{joint}', loc='left', fontsize='medium', fontweight='bold')
        ax.grid(True, color='0.9', lw=0.6)
        ax.legend(loc='best', fontsize='small', frameon=False)
    for ax in axes[-1]:
        ax.set_xlabel('time  [s]')
        if time.size > 1:
            ax.set_xlim(time[0], time[-1])
    head = f'{title}: simulated motion'
    if subtitle:
        head += '\n' + subtitle
    figure_text.suptitle(fig, head, 10)       # 'medium', wrapped likewise
    with warnings.catch_warnings(), np.errstate(all='ignore'):
        warnings.simplefilter('ignore', RuntimeWarning)
        fig.savefig(path, format=fmt, dpi=110)
