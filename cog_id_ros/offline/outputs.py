"""The output files of ``cog_id_torques``: their paths checked before anything is solved
(:func:`check_paths`), then the efforts CSV and the plot written to temporary files and
renamed together, the stop signals held back meanwhile (:func:`write_outputs`); an error
names the option (--output or --plot) it is about.
"""

import contextlib
import os

from . import atomic_files, trajectory_io
from .console import (
    EXIT_PARAMS,
    EXIT_USAGE,
    EXIT_WRITE,
    ToolError,
    one_line,
    output_target,
    plot_format,
)
from .stop_signals import Interrupted


def check_paths(args):
    """Fail fast (before any solving) on paths that cannot work; returns the plot format."""
    if not os.path.isfile(args.input):
        what = 'no such file' if not os.path.exists(args.input) else 'not a regular file'
        raise ToolError(f'--input {args.input}: {what}', EXIT_USAGE)
    if not os.access(args.input, os.R_OK):
        raise ToolError(f'--input {args.input}: not readable', EXIT_USAGE)
    if not os.path.isfile(args.params_file):
        what = 'no such file' if not os.path.exists(args.params_file) else 'not a regular file'
        raise ToolError(f'--params-file {args.params_file}: {what}', EXIT_PARAMS)
    outputs = [('--output', args.output)]
    if args.plot is not None:
        outputs.append(('--plot', args.plot))
    targets = {}
    for option, path in outputs:
        if not path:
            raise ToolError(f'{option}: the path is empty', EXIT_USAGE)
        if path.endswith(('/', os.sep)):
            raise ToolError(f'{option} {path}: ends with {path[-1]}, so it names a directory; '
                            'give a file name', EXIT_USAGE)
        target, directory = output_target(option, path)
        if not os.access(directory, os.W_OK):
            raise ToolError(f'{option} {path}: directory {directory} is not writable', EXIT_USAGE)
        if os.path.exists(target) and os.path.samefile(target, args.input):
            raise ToolError(f'{option} {path}: is the input file', EXIT_USAGE)
        if os.path.exists(target) and os.path.samefile(target, args.params_file):
            raise ToolError(f'{option} {path}: is the parameter file', EXIT_USAGE)
        targets[option] = os.path.abspath(target)
    if args.plot and targets['--plot'] == targets['--output']:
        raise ToolError(f'--plot {args.plot}: is the same file as --output', EXIT_USAGE)
    if not args.plot:
        return None
    from . import plotting
    return plot_format(args.plot, plotting.supported_formats())


class _Outputs:
    """Which user path (--output or --plot) a write error is about, from its file names."""

    def __init__(self):
        self.paths = {}     # file name (temporary or target) -> (option, user path)

    def add(self, option, user_path, *names):
        for name in names:
            self.paths[os.path.abspath(name)] = (option, user_path)

    def which(self, exc, default):
        for name in (getattr(exc, 'filename', None), getattr(exc, 'filename2', None)):
            if isinstance(name, (str, bytes, os.PathLike)):
                found = self.paths.get(os.path.abspath(os.fsdecode(name)))
                if found:
                    return found
        return default


def write_outputs(args, signals, traj, efforts, valid, active, summary, mech, skipped,
                   plot_format, extra_columns=(), forces=None):
    """Write the CSV and the plot to temporary files, then rename both (signals held back).
    ``extra_columns``: the names of the columns of ``efforts`` after the active joints' (a
    floating base's wrenches; not plotted); ``forces``: {contact: vertical force (N,)} drawn
    in a panel of their own."""
    n = len(traj)
    outputs = _Outputs()
    current = ('--output', args.output)
    try:
        with contextlib.ExitStack() as stack:
            tmp_csv = stack.enter_context(atomic_files.atomic_output(args.output))
            outputs.add('--output', args.output, tmp_csv,
                        atomic_files.output_target(args.output))
            with open(tmp_csv, 'w', encoding='utf-8', newline='') as f:
                for block in trajectory_io.format_efforts(traj.time, efforts, valid, active,
                                                          extra_columns=extra_columns):
                    f.write(block)
            if args.plot:
                from . import plotting
                current = ('--plot', args.plot)
                tmp_plot = stack.enter_context(atomic_files.atomic_output(args.plot))
                outputs.add('--plot', args.plot, tmp_plot, atomic_files.output_target(args.plot))
                try:
                    plotting.plot_efforts(
                        tmp_plot, traj.time, efforts[:, :len(active)], valid, active,
                        summary['joints'],
                        title=mech.name, units=[j['unit'] for j in summary['joints']],
                        subtitle=f'{os.path.basename(args.input)}: {n:,} samples'
                                 + (f', {len(skipped):,} skipped' if skipped else ''),
                        fmt=plot_format, forces=forces)
                except (OSError, MemoryError):
                    raise
                except Exception as exc:     # matplotlib refusing the data
                    raise ToolError(f'--plot {args.plot}: cannot draw the plot: '
                                    f'{type(exc).__name__}: {one_line(exc)[:200]}',
                                    EXIT_WRITE) from None
            current = ('--output', args.output)
            signals.deferring = True        # the renames (at the end of the with) go together
    except atomic_files.OutputPathError as exc:
        signals.deferring = False
        option, path = current
        raise ToolError(f'{option} {path}: {exc}', EXIT_WRITE) from None
    except OSError as exc:
        signals.deferring = False
        option, path = outputs.which(exc, current)
        raise ToolError(f'{option} {path}: cannot write: {exc.strerror or one_line(exc)}',
                        EXIT_WRITE) from None
    finally:
        signals.deferring = False
    if signals.pending:
        raise Interrupted(signals.pending, outputs_written=True)
