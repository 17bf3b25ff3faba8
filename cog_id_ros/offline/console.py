"""What the offline console tools (``cog_id_torques``, ``cog_id_inspect``) share: their exit
statuses, errors as one line, the argument parser's manners, loading the mechanism, the
checks of an output path, and the frame of ``main`` (:func:`run_main`) that turns every way
a run can end into a status.
"""

import argparse
import os
import sys

from . import atomic_files
from .stop_signals import Interrupted, StopSignals, signal_name

EXIT_OK = 0
EXIT_INPUT = 1        # the trajectory was rejected: bad CSV, or a sample cannot be solved
EXIT_USAGE = 2        # command line: bad option, unreadable input, unwritable output path
EXIT_PARAMS = 3       # the parameter file cannot be read or honoured
EXIT_WRITE = 4        # writing an output file failed
EXIT_INTERNAL = 70    # a bug: reported in one line, never as a traceback
EXIT_INTERRUPTED = 130  # 128 + SIGINT; SIGTERM gives 143, SIGHUP 129
EXIT_BROKEN_PIPE = 141  # stdout closed before the summary was printed (outputs are complete)


class ToolError(Exception):
    """An error the tool reports as one line, with its exit status (and, for a parameter
    file that cannot be honoured, the parameter it names)."""

    def __init__(self, message, status, parameter=None):
        self.status, self.parameter = status, parameter
        super().__init__(message)


def one_line(exc: BaseException) -> str:
    """The message of ``exc`` on one line (whitespace runs become one space): the tools'
    and the nodes' errors alike."""
    return ' '.join(str(exc).split())


class Parser(argparse.ArgumentParser):
    """argparse, with a usage mistake reported as one line (not the whole usage block)."""

    def error(self, message):
        self.exit(EXIT_USAGE, f'{self.prog}: error: {message} (see {self.prog} --help)\n')


def _number(text, convert, what):
    try:
        return convert(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f'not {what}: {text!r}') from None


def positive_int(text):
    value = _number(text, int, 'an integer')
    if value < 1:
        raise argparse.ArgumentTypeError(f'must be >= 1, got {value}')
    return value


def positive_float(text):
    value = _number(text, float, 'a number')
    if not value > 0:       # also NaN
        raise argparse.ArgumentTypeError(f'must be > 0 (inf for no limit), got {text!r}')
    return value


def load_mechanism(args, solver=True, overrides=None):
    """(Mechanism, InverseDynamics) of the parameter file, node name and backend the command
    line gave (without ``solver``: (Mechanism, None)), the parameters ``overrides`` (dotted
    names) changed; ToolError (exit EXIT_PARAMS) saying why it cannot be used."""
    import cog_id_ros

    from ..description.params_file import DEFAULT_NODE_NAME, load_params_file
    try:
        params = load_params_file(args.params_file, args.node_name or DEFAULT_NODE_NAME)
        params.update(overrides or {})
        mech = cog_id_ros.Mechanism.from_parameters(
            params, base_dir=os.path.dirname(os.path.abspath(args.params_file)))
        return mech, (cog_id_ros.InverseDynamics(mech, backend=args.backend) if solver else None)
    except cog_id_ros.CogIdError as exc:
        raise ToolError(f'{args.params_file}: {one_line(exc)}', EXIT_PARAMS,
                        getattr(exc, 'parameter', None)) from None
    except OSError as exc:
        raise ToolError(f'{args.params_file}: cannot read: {exc.strerror or exc}',
                        EXIT_PARAMS) from None
    except UnicodeDecodeError as exc:
        raise ToolError(f'{args.params_file}: not UTF-8 text (byte {exc.start}); a parameter '
                        'file is YAML text', EXIT_PARAMS) from None
    except (ValueError, TypeError, KeyError, AttributeError, RecursionError) as exc:
        raise ToolError(f'{args.params_file}: cannot be used as a parameter file: '
                        f'{type(exc).__name__}: {one_line(exc)[:200]}', EXIT_PARAMS) from None


def output_target(option, path):
    """The file that writing ``path`` (given as ``option``) replaces, and its directory;
    ToolError (EXIT_USAGE) where it cannot be written (a special file, a link loop, a
    directory that does not exist)."""
    try:
        target = atomic_files.output_target(path)
    except atomic_files.OutputPathError as exc:
        raise ToolError(f'{option} {path}: {exc}', EXIT_USAGE) from None
    directory = os.path.dirname(os.path.abspath(target))
    if not os.path.isdir(directory):
        raise ToolError(f'{option} {path}: directory {directory} does not exist', EXIT_USAGE)
    return target, directory


def plot_format(path, formats):
    """The image format of --plot ``path``, by its extension: one of ``formats``, or
    ToolError (EXIT_USAGE)."""
    fmt = os.path.splitext(path)[1].lstrip('.').lower()
    if fmt not in formats:
        raise ToolError(f'--plot {path}: unknown image format {fmt!r} (use one of '
                        + ', '.join(formats) + ')', EXIT_USAGE)
    return fmt


def run_main(prog, traceback_env, work, stopped, memory_hint=None):
    """A tool's ``main`` around ``work(signals)`` (its run, the stop signals installed):
    returns the exit status, and never prints a traceback.

    Every error is one line on stderr; an internal error's traceback only with the
    environment variable ``traceback_env`` set. ``stopped``: what a stop signal leaves
    behind ('no output written'); ``memory_hint``: what to do when memory runs out (without
    one, running out is an internal error)."""
    signals = StopSignals().install()
    try:
        return work(signals)
    except ToolError as exc:
        print(f'{prog}: error: {exc}', file=sys.stderr)
        return exc.status
    except Interrupted as exc:
        what = ('the outputs are complete, the summary was not printed' if exc.outputs_written
                else stopped)
        print(f'{prog}: interrupted by {signal_name(exc.signum)}; {what}', file=sys.stderr)
        return 128 + exc.signum
    except KeyboardInterrupt:
        print(f'{prog}: interrupted by SIGINT; {stopped}', file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError:
        # the reader of stdout went away (e.g. `| head`): silence the flush at exit
        if sys.stdout is not None:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        return EXIT_BROKEN_PIPE
    except Exception as exc:    # a bug: one line, the traceback only on request
        if memory_hint and isinstance(exc, MemoryError):
            print(f'{prog}: error: out of memory ({memory_hint})', file=sys.stderr)
            return EXIT_INTERNAL
        if os.environ.get(traceback_env):
            raise
        print(f'{prog}: internal error: {type(exc).__name__}: {one_line(exc)[:300]} '
              f'(a bug; please report it with the command; {traceback_env}=1 shows the '
              'traceback)', file=sys.stderr)
        return EXIT_INTERNAL
    finally:
        signals.restore()
