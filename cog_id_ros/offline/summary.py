"""The summary of a ``cog_id_torques`` run: per active joint the peak |effort|, the RMS
effort and the peak |power|, with where they occur; as a table, or as JSON (never NaN or
Infinity: a value beyond the range of a double is null, with a note).
"""

import math

import numpy as np

from . import derivatives

ROW_NUMBERING = ('data rows count from 1, the header does not count: '
                 'row r is line r+1 of the file')


def _units(mech):
    return [kind.effort_unit for kind in mech.active_kinds]


def _rms(values):
    """Root mean square without overflow or underflow: scaled by the largest |value|."""
    peak = float(np.max(np.abs(values)))
    if peak == 0.0 or not math.isfinite(peak):
        return peak
    scaled = values / peak
    return peak * math.sqrt(float(np.mean(scaled * scaled)))


def joint_statistics(time, effort, velocity, valid):
    """Peak |effort|, RMS effort and peak |power| of one joint over the valid samples.

    Rows in the result are 1-based data rows. Values are None when no sample is valid.
    The RMS is scaled by the peak, so it is finite whenever the efforts are; a power
    beyond the range of a double comes out as inf (its row is still the right one).
    """
    keys = ('peak_effort', 'peak_effort_signed', 'peak_effort_row', 'peak_effort_time',
            'rms_effort', 'peak_power', 'peak_power_signed', 'peak_power_row',
            'peak_power_time')
    index = np.flatnonzero(valid)
    if index.size == 0:
        return dict.fromkeys(keys)
    e = effort[index]
    with np.errstate(all='ignore'):
        p = e * velocity[index]
        k = int(np.argmax(np.abs(e)))
        kp = int(np.argmax(np.abs(p)))
        rms = _rms(e)
    return {
        'peak_effort': float(abs(e[k])),
        'peak_effort_signed': float(e[k]),
        'peak_effort_row': int(index[k]) + 1,
        'peak_effort_time': float(time[index[k]]),
        'rms_effort': rms,
        'peak_power': float(abs(p[kp])),
        'peak_power_signed': float(p[kp]),
        'peak_power_row': int(index[kp]) + 1,
        'peak_power_time': float(time[index[kp]]),
    }


def build_summary(args, mech, traj, estimated, efforts, valid, qd, skipped, elapsed,
                  unwrapped=None):
    units = _units(mech)
    joints = []
    for k, joint in enumerate(mech.active_joints):
        st = joint_statistics(traj.time, efforts[:, k], qd[:, k], valid)
        joints.append({'joint': joint, 'unit': units[k], 'power_unit': 'W', **st})
    reasons = {}
    types = {}
    for skip in skipped:
        reasons[skip.reason] = reasons.get(skip.reason, 0) + 1
        kind = type(skip.error).__name__ if skip.error is not None else 'TrajectoryJump'
        types[kind] = types.get(kind, 0) + 1
    n = len(traj)
    return {
        'mechanism': mech.name,
        'params_file': args.params_file,
        'input': args.input,
        'output': args.output,
        'plot': args.plot,
        'samples': n,
        'solved': int(np.count_nonzero(valid)),
        'skipped': len(skipped),
        'skipped_rows': [skip.row for skip in skipped],
        'skipped_row_reasons': [skip.reason for skip in skipped],
        'skipped_reasons': reasons,
        'skipped_error_types': types,
        'time_start': float(traj.time[0]),
        'time_end': float(traj.time[-1]),
        'estimated_columns': estimated,
        'derivative_scheme': derivatives.SCHEME if estimated else None,
        'unwrap': bool(getattr(args, 'unwrap', False)),
        'unwrapped': {col: {'rows': r, 'wraps': w} for col, (r, w) in (unwrapped or {}).items()},
        'max_step': {'revolute_rad_per_row': _json_limit(getattr(args, 'max_step', None)),
                     'prismatic_m_per_row': _json_limit(getattr(args, 'max_step_linear', None))},
        'row_numbering': ROW_NUMBERING,
        'active_joints': list(mech.active_joints),
        'joints': joints,
        'elapsed_seconds': elapsed,
        'samples_per_second': n / elapsed if elapsed > 0 else None,
        'notes': [],
    }


def _json_limit(value):
    return None if value is None or not math.isfinite(value) else value


def finite_for_json(summary):
    """Replace every non-finite number by None, adding a note per value to ``notes``.

    JSON has no NaN or Infinity (``json.dumps(allow_nan=False)`` is used on the result),
    so a value beyond the range of a double is written as null and the note says so.
    """
    notes = summary.setdefault('notes', [])

    def walk(value, where):
        if isinstance(value, float) and not math.isfinite(value):
            notes.append(f'{where}: beyond the range of a double ({value!r}): null in --json, '
                         'n/a in the table')
            return None
        if isinstance(value, dict):
            return {k: walk(v, f'{where}.{k}' if where else k) for k, v in value.items()}
        if isinstance(value, list):
            return [walk(v, f"{where}[{v['joint']}]" if isinstance(v, dict) and 'joint' in v
                         else f'{where}[{i}]') for i, v in enumerate(value)]
        return value

    clean = walk({k: v for k, v in summary.items() if k != 'notes'}, '')
    clean['notes'] = notes
    return clean


def _g(value, unit=''):
    if value is None:
        return 'n/a'
    if not math.isfinite(value):
        return 'n/a (beyond a double)'
    return f'{value:.6g}' + (f' {unit}' if unit else '')


def format_summary(summary):
    s = summary
    plural = '' if s['samples'] == 1 else 's'
    lines = [f"{s['mechanism']}: {s['samples']:,} sample{plural}, t = {s['time_start']:.6g} .. "
             f"{s['time_end']:.6g} s; {s['solved']:,} solved, {s['skipped']:,} skipped"]
    if s['estimated_columns']:
        lines.append('estimated from the samples: ' + ', '.join(s['estimated_columns']))
    if s.get('contacts') is not None:     # a floating base
        lines.append('contacts: ' + (', '.join(s['contacts']) or 'none') + ' (their wrenches '
                     'and the base wrench follow the efforts in the output)')
    if s.get('unwrap'):
        lines.append('unwrapped (--unwrap): ' + (', '.join(
            f"{col}: {u['rows']:,} row(s) shifted by a multiple of 2 pi ({u['wraps']:,} wrap(s))"
            for col, u in s['unwrapped'].items()) or 'no revolute active joint'))
    header = ('joint', 'peak |effort|', 'at', 'RMS effort', 'peak |power|', 'at')
    rows = [header]
    for j in s['joints']:
        at = (f"row {j['peak_effort_row']} (t = {j['peak_effort_time']:.6g} s)"
              if j['peak_effort'] is not None else 'n/a')
        at_p = (f"row {j['peak_power_row']} (t = {j['peak_power_time']:.6g} s)"
                if j['peak_power'] is not None else 'n/a')
        rows.append((j['joint'], _g(j['peak_effort'], j['unit']), at,
                     _g(j['rms_effort'], j['unit']), _g(j['peak_power'], 'W'), at_p))
    widths = [max(len(r[i]) for r in rows) for i in range(len(header))]
    for r in rows:
        lines.append('  '.join(c.ljust(w) for c, w in zip(r, widths)).rstrip())
    written = [s['output']] + ([s['plot']] if s['plot'] else [])
    lines.append('wrote ' + ', '.join(written)
                 + f"  ({s['elapsed_seconds']:.2f} s, "
                 + f"{s['samples_per_second'] or 0:,.0f} samples/s)")
    return '\n'.join(lines)
