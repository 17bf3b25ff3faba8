"""The command line of the package's nodes: ``--params-file`` checks and rcl's messages,
and the modes cog_id_node's ``--help`` lists (:func:`modes_help`).

rcl refuses a params file with a message that names a line, not the parameter, and logs a
second line of its own. These helpers say how to give parameters when none are
(:func:`no_parameters_problem`: a ``--params-file`` before ``--ros-args`` is not one), read
the files first (:func:`params_file_problem`),
turn what rcl still refuses into one line that names the parameter (:func:`rcl_message`,
with rcl's own log line held back meanwhile: :class:`StderrHeld`), and say which file a
relative ``mechanism.urdf_file`` is relative to (:func:`urdf_base_dir`).
"""
import os
import re
import sys
import tempfile
from typing import Any, Literal, Sequence

import yaml

from ..core import MechanismConfigError
from ..description import params_file, yaml_guard
from ..offline.console import one_line
from .parameters import NODE_PARAMETERS

#: the parameters that choose what kind of node cog_id_node is, listed by its --help
MODE_PARAMETERS = ('control_mode', 'managed')


def node_arguments(args: Sequence[str] | None) -> list[str]:
    """The arguments after the program name (``args`` as rclpy takes them, None: sys.argv)."""
    return sys.argv[1:] if args is None else list(args[1:])


def wants_help(argv: Sequence[str]) -> bool:
    """``-h`` or ``--help`` before ``--ros-args``."""
    own = argv[:argv.index('--ros-args')] if '--ros-args' in argv else argv
    return '-h' in own or '--help' in own


def modes_help() -> str:
    """The lines cog_id_node's ``--help`` adds to its usage: its modes (MODE_PARAMETERS),
    each with the values that choose it, its default and what it is, from the node's
    parameter table (``parameters.NODE_PARAMETERS``)."""
    lines = ['', 'Modes (-p NAME:=VALUE after --ros-args, or in the parameter file):']
    for name in MODE_PARAMETERS:
        param = NODE_PARAMETERS[name]
        if param.kind == 'choice':
            values, default = '|'.join(param.choices), param.default
        else:                               # a bool: what turns the mode on
            values, default = str(not param.default).lower(), str(param.default).lower()
        what = param.ros_description.split(': ', 1)[0]
        lines += [f'  {name}:={values}', f'      {what}; default {default}']
    return '\n'.join(lines) + '\n'


def split_ros_arguments(argv: Sequence[str]) -> tuple[list[str], list[str]]:
    """(ROS arguments, the others): the ROS ones are those after a ``--ros-args`` up to
    the next ``--`` or the end (rcl's rule; there may be several such sections)."""
    ros: list[str] = []
    other: list[str] = []
    inside = False
    for arg in argv:
        if arg == '--ros-args':
            inside = True
        elif inside and arg == '--':
            inside = False
        else:
            (ros if inside else other).append(arg)
    return ros, other


def no_parameters_problem(argv: Sequence[str], program: str) -> str | None:
    """A sentence saying how to give the node its parameters when the command line gives
    none (no ``--params-file``, no ``-p`` among its ROS arguments), or None.

    rcl reads only ROS arguments: a ``--params-file`` before ``--ros-args`` is ignored, and
    the node would stop at the first mechanism parameter it misses (``mechanism.links:
    missing``), which says nothing about the cause.
    """
    ros, other = split_ros_arguments(argv)
    if any(arg in ('--params-file', '-p', '--param') for arg in ros):
        return None
    text = f'no mechanism parameters given: run {program} --ros-args --params-file FILE'
    if other:
        text += ('; arguments before --ros-args are not ROS arguments: '
                 f"got '{' '.join(other)}'")
    return text


def params_file_problem(argv: Sequence[str]) -> str | None:
    """A sentence naming the first parameter of a ``--params-file`` rcl would refuse, or None.

    rcl's own message names a line of the file, not the parameter, and comes with a
    second log line; the files are read here first, by the API's reader and its one rule of
    what rcl refuses (:mod:`cog_id_ros.description.params_file`: ``read_document``, numbers
    read as rcl reads them, and ``check_rcl_values``: arrays that mix integers and doubles or other
    types), so the node and ``Mechanism.from_params_file`` refuse the same files with the
    same message. Keys written twice are left to rcl (the last one wins).
    """
    for path in _params_files(argv):
        try:
            params_file.check_rcl_values(params_file.read_document(path, duplicate_keys=True),
                                         path)
        except MechanismConfigError as exc:
            text = one_line(exc)
            if exc.parameter == 'params_file':      # the file itself: say it as given
                text = '--params-file' + text[len('params_file'):]
            return text
    return None


def _params_files(argv: Sequence[str]) -> list[str]:
    """The ``--params-file`` arguments of ``argv``, in order."""
    return [argv[i + 1] for i, arg in enumerate(argv[:-1]) if arg == '--params-file']


def other_nodes_hint(argv: Sequence[str], node: str) -> str:
    """'; <file> gives parameters to <entries>, not to this node ...' for each
    ``--params-file`` none of whose entries rcl gives the node (``node``: its default
    name; the remaps of ``argv`` give its full name): a file written for another node name
    or namespace, which the node would only report as the first parameter it missed.
    '' when every file has an entry for it."""
    namespace, name = _remapped(argv, '__ns', '/', node), _remapped(argv, '__node', node)
    full = f"{namespace.rstrip('/')}/{name}"
    hints = []
    for path in _params_files(argv):
        entries = params_file.other_nodes(path, full)
        if entries is None:
            hints.append(f'; {path} holds no node entries: put the parameters under /**: and '
                         'ros__parameters:')
        elif entries:
            way = _remaps_to(entries[0], namespace, node)
            own = full.lstrip('/') if namespace == '/' else full
            hints.append(f"; {path} gives parameters to {', '.join(entries)}, not to this node "
                         f"('{full}'): name its entry {own}: or /**:"
                         f"{', or ' + way if way else ''}")
    return ''.join(hints)


def _remaps_to(entry: str, namespace: str, default: str) -> str:
    """How to start the node (now in ``namespace``; ``default``: its name without remaps)
    as the node of the params-file ``entry``: 'start it as /arm/my_robot (-r __ns:=/arm -r
    __node:=my_robot)'; '' for a pattern other than /**/<name> or <ns>/*."""
    path = '/' + entry.strip('/')
    ns: str | None
    if path.startswith('/**/'):
        ns, node = None, path[4:]
    else:
        ns, node = path.rsplit('/', 1)
        ns = ns or '/'
    if '*' in node and node != '*' or ns is not None and '*' in ns:
        return ''
    rules = [f'-r __ns:={ns}'] if ns not in (None, '/') else []
    rules += [f'-r __node:={node}'] if node not in ('*', default) else []
    said = ' '.join(rules)
    if ns == '/' and namespace != '/':
        said = f'{said}, no __ns remap' if said else 'no __ns remap'
    what = f'in {ns}' if node == '*' else node if ns is None else path
    return f"start it as {what} ({said or 'no remap'}) instead"


def _remapped(argv: Sequence[str], which: str, default: str, node: str | None = None) -> str:
    """What the node's ``which`` ('__node' or '__ns') is after the ``-r`` rules of ``argv``
    (``default`` without one): the first rule for it counts (rcl's); a rule
    ``<name>:__node:=...`` applies only to the node whose default name is ``<name>``
    (``node``; for '__node', ``default``)."""
    node = default if node is None else node
    aliases = ('__node', '__name') if which == '__node' else ('__ns',)
    for arg, value in zip(argv, argv[1:]):
        if arg not in ('-r', '--remap') or ':=' not in value:
            continue
        key, target = value.split(':=', 1)
        only, _, key = key.rpartition(':')
        if key in aliases and (not only or only == node):
            return target
    return default


def urdf_base_dir(command_line: Sequence[str] | None, node_name: str,
                  parameter: str = 'mechanism.urdf_file') -> str | None:
    """The directory a relative ``mechanism.urdf_file`` (or another file parameter,
    ``mechanism.loop_closure_file``) is relative to: that of the ``--params-file`` that
    gives it to the node called ``node_name`` (rcl applies the files and ``-p`` rules in
    their order on the command line: the last one that gives it counts); None (the working
    directory) when a ``-p`` rule gives it, or nothing does."""
    base = None
    args = list(command_line or ())
    for arg, value in zip(args, args[1:]):
        if arg == '--params-file':
            try:
                given = parameter in params_file.load_params_file(value, node_name)
            except MechanismConfigError:
                given = False
            if given:
                base = os.path.dirname(os.path.abspath(value))
        elif arg in ('-p', '--param') and \
                value.split(':=', 1)[0].rsplit(':', 1)[-1] == parameter:
            base = None
    return base


def node_name(command_line: Sequence[str] | None, default: str) -> str:
    """The node's name: ``default``, or what the first ``-r __node:=NAME`` (``__name``,
    ``<default>:__node``) rule makes it (rcl's rule: the first match counts)."""
    return _remapped(list(command_line or ()), '__node', default)


def given_value(command_line: Sequence[str] | None, node_name: str, name: str,
                default: Any = None) -> Any:
    """The value of parameter ``name`` the command line gives the node ``node_name``
    (``--params-file`` and ``-p`` rules in their order: the last one counts), read before
    rclpy does (e.g. ``managed``, which decides what kind of node to build); ``default``
    when none gives it, or a file cannot be read (rcl will say why)."""
    value = default
    args = list(command_line or ())
    for arg, rule in zip(args, args[1:]):
        if arg == '--params-file':
            try:
                value = params_file.load_params_file(rule, node_name).get(name, value)
            except MechanismConfigError:
                pass
        elif arg in ('-p', '--param') and ':=' in rule and \
                rule.split(':=', 1)[0].rsplit(':', 1)[-1] == name:
            try:
                value = yaml_guard.load(rule.split(':=', 1)[1], yaml.SafeLoader, name, '-p')
            except (yaml.YAMLError, MechanismConfigError):
                pass
    return value


def rcl_message(exc: BaseException) -> str:
    """rcl's message for a command line it refused, in one line without its source lines;
    a parse error in a params file names the parameter at the line rcl names."""
    text = one_line(exc)
    text = text.replace('failed to initialize rcl: ', '')
    text = re.sub(r',? at /\S+:\d+', '', text)
    found = re.search(r"params file: '--params-file (.+?)'.*?line(?:_num)? (\d+)", text)
    if found:
        name = _parameter_at_line(found.group(1), int(found.group(2)))
        if name:
            return f'{name}: {text}'
    return text


def _parameter_at_line(path: str, line: int) -> str | None:
    """The dotted name (below ros__parameters) of the entry at ``line`` (1-based) of a
    params file, or None."""
    try:
        with open(path, encoding='utf-8') as stream:
            root = yaml_guard.compose(stream.read(), 'params_file', path)
    except (OSError, ValueError, yaml.YAMLError, MechanismConfigError):
        return None
    best = None

    def walk(node: Any, prefix: str) -> None:
        nonlocal best
        if not isinstance(node, yaml.MappingNode):
            return
        for key, value in node.value:
            name = f'{prefix}{key.value}'
            if key.start_mark.line + 1 <= line <= max(value.end_mark.line + 1,
                                                     key.start_mark.line + 1):
                best = name
                walk(value, name + '.')

    if isinstance(root, yaml.MappingNode):
        for _, body in root.value:
            if isinstance(body, yaml.MappingNode):
                for key, params in body.value:
                    if key.value == 'ros__parameters':
                        walk(params, '')
    return best


class StderrHeld:
    """Holds what C code writes to file descriptor 2 (rcl's "Failed to parse global
    arguments" log line) until replay(); dropped when the block raises."""

    def __enter__(self) -> 'StderrHeld':
        self._saved: int | None = None
        self._file = tempfile.TemporaryFile()
        try:
            sys.stderr.flush()
            self._saved = os.dup(2)
            os.dup2(self._file.fileno(), 2)
        except OSError:
            self._saved = None
        return self

    def __exit__(self, *exc_info: Any) -> Literal[False]:
        if self._saved is not None:
            os.dup2(self._saved, 2)
            os.close(self._saved)
            self._saved = None
        return False

    def replay(self) -> None:
        self._file.seek(0)
        text = self._file.read()
        self._file.close()
        if text:
            sys.stderr.buffer.write(text)
            sys.stderr.flush()
