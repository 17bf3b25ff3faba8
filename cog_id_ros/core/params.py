"""Reading mechanism parameters: ROS 2 parameter files and dicts of dotted names.

A parameter file is the one ``--ros-args --params-file`` reads: node entries (the node's
name, optionally with its namespace, or the wildcard ``/**``) each holding
``ros__parameters``. As in rclpy, the wildcard entries apply first and the node's own entry
overrides them. Nested mappings become dotted names (``links.link1.mass``), exactly the
names rclpy gives the node, so the same dict feeds ``Mechanism.from_parameters``.

The typed getters below turn anything a user can write (YAML integers where floats are
meant, tuples, numpy arrays) into plain Python values, and raise MechanismConfigError naming
the parameter for anything else.

Whatever the file or dict holds, only MechanismConfigError comes out of here: nulls, numbers
too large for a float, text that is not UTF-8, recursive or exponentially nested YAML aliases
(a "billion laughs" document) and nesting deeper than ``MAX_DEPTH`` are refused with the
parameter's name (or ``params_file``), in time proportional to the size of the file. Values
are quoted in messages with a bounded ``show`` so that no message can grow without limit.
"""
import math
import os
import re
import reprlib
import stat

import yaml

from .errors import MechanismConfigError

DEFAULT_NODE_NAME = 'cog_id_node'

#: most parameters a file or dict may expand to (far above any mechanism within the size
#: limits of mechanism.py); more is refused before anything is built from them
MAX_PARAMETERS = 100_000
#: deepest nesting of mappings (the mechanism's parameters are three levels deep)
MAX_DEPTH = 16
#: most entries of one list value (the longest lists are one entry per joint)
MAX_LIST_LENGTH = 100_000
#: largest parameter file read (characters); a mechanism within the size limits of
#: mechanism.py takes well under 100 kB, and 512 kB load in about 1.5 s on a small machine
MAX_FILE_CHARS = 512 * 1024
#: deepest nesting of YAML flow collections ([...] and {...}) read; PyYAML's scanner takes
#: time quadratic in it before its recursion gives up, and libyaml's parser crashes the
#: process on deeply nested input (so does a line of many nested block entries, "- - - x")
MAX_FLOW_DEPTH = 32
_BRACKETS = re.compile(r'[\[\]{}]')
_BLOCK_ENTRIES = re.compile(r'^[ \t]*((?:[-?:][ \t]+){33,})', re.MULTILINE)

_SHOW = reprlib.Repr()
_SHOW.maxstring = 60
_SHOW.maxother = 60
_SHOW.maxlevel = 3
_SHOW.maxlist = _SHOW.maxtuple = _SHOW.maxdict = _SHOW.maxset = 8


def show(value):
    """A bounded repr for messages: never expands a huge, nested or recursive value."""
    try:
        return _SHOW.repr(value)
    except Exception:  # noqa: BLE001 -- a value whose repr fails is still shown somehow
        return f'<{type(value).__name__}>'


def flatten(tree, prefix='', source='parameters'):
    """{'a': {'b': 1}} -> {'a.b': 1}; dotted keys that are already flat pass through.

    Keys must be strings. A mapping that contains itself (a recursive YAML alias), nesting
    deeper than MAX_DEPTH or more than MAX_PARAMETERS names (aliases nested inside each
    other expand exponentially) raise MechanismConfigError naming ``source`` or the
    parameter, after at most MAX_PARAMETERS steps.
    """
    flat = {}
    stack = [(iter(tree.items()), prefix, 0)]
    open_ids = [id(tree)]
    steps = 0
    while stack:
        items, pre, depth = stack[-1]
        item = next(items, None)
        if item is None:
            stack.pop()
            open_ids.pop()
            continue
        key, value = item
        steps += 1
        if steps > MAX_PARAMETERS:
            raise MechanismConfigError(
                source, f'expands to more than {MAX_PARAMETERS} parameters (nested YAML '
                        f'aliases?); write each parameter out once')
        if not isinstance(key, str) or not key:
            raise MechanismConfigError(
                pre.rstrip('.') or source,
                f'parameter names must be non-empty strings, got {show(key)}')
        name = f'{pre}{key}'
        if isinstance(value, dict) and not value:
            flat[name] = value       # an empty mapping is a value (refused by its getter),
        elif isinstance(value, dict):  # not silently "no parameter" (the default)
            if id(value) in open_ids:
                raise MechanismConfigError(
                    name, 'contains itself (a recursive YAML alias); write the values out')
            if depth + 1 >= MAX_DEPTH:
                raise MechanismConfigError(
                    name, f'nested more than {MAX_DEPTH} levels deep; the mechanism '
                          f'parameters are three levels deep (e.g. links.link1.mass)')
            stack.append((iter(value.items()), name + '.', depth + 1))
            open_ids.append(id(value))
        else:
            flat[name] = value
    return flat


def _entry_matches(entry, node_name):
    if entry in ('/**', '**'):
        return 'wildcard'
    bare = entry.strip('/')
    if bare == node_name.strip('/') or bare.split('/')[-1] == node_name.strip('/').split('/')[-1]:
        return 'node'
    if entry.endswith('/**') or entry.startswith('/**/'):
        return 'wildcard'
    return None


def load_params_file(path, node_name=DEFAULT_NODE_NAME):
    """Dotted-name dict of the parameters a node called ``node_name`` gets from ``path``."""
    if not isinstance(path, (str, os.PathLike)):    # an int would be taken as a descriptor
        raise MechanismConfigError(
            'params_file', f'must be a path to a file, got {type(path).__name__} {show(path)}')
    if not isinstance(node_name, str):
        raise MechanismConfigError('node_name', f'must be a string, got {show(node_name)}')
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):     # a FIFO would block the reader
            raise MechanismConfigError('params_file', f'{path} is not a regular file')
        with open(path, encoding='utf-8') as stream:
            text = stream.read(MAX_FILE_CHARS + 1)
        if len(text) > MAX_FILE_CHARS:
            raise MechanismConfigError(
                'params_file', f'{path} is larger than the supported {MAX_FILE_CHARS // 1024} kB; '
                               f'a mechanism within the size limits (docs/mechanism.md) takes '
                               f'far less: keep the mechanism in a file of its own')
        _check_flow_depth(path, text)
        document = yaml.load(text, Loader=ParamsLoader)   # noqa: S506 (a safe loader)
    except MechanismConfigError:
        raise
    except OSError as exc:
        raise MechanismConfigError(
            'params_file', f'cannot read {path}: {exc.strerror or exc}') from exc
    except UnicodeDecodeError as exc:
        raise MechanismConfigError(
            'params_file', f'{path} is not UTF-8 text (byte 0x{exc.object[exc.start]:02x} at '
                           f'offset {exc.start}); save it with UTF-8 encoding') from None
    except yaml.YAMLError as exc:
        raise MechanismConfigError('params_file', f'{path} is not valid YAML: {exc}') from exc
    except RecursionError:
        raise MechanismConfigError(
            'params_file', f'{path} is nested too deeply to read; the mechanism parameters '
                           f'are three levels deep under ros__parameters') from None
    except (ValueError, OverflowError) as exc:   # e.g. a YAML timestamp out of range
        raise MechanismConfigError(
            'params_file', f'{path} holds a value YAML cannot represent: {exc}') from None
    if not isinstance(document, dict):
        raise MechanismConfigError('params_file', f'{path} holds no node entries')
    wildcard, own = {}, {}
    for entry, body in document.items():
        kind = _entry_matches(str(entry), node_name)
        if kind is None:
            continue
        if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
            raise MechanismConfigError(
                'params_file', f'{path}: entry {show(entry)} has no ros__parameters mapping')
        (wildcard if kind == 'wildcard' else own).update(
            flatten(body['ros__parameters'], source='params_file'))
    if not wildcard and not own:
        raise MechanismConfigError(
            'params_file', f"{path} has no entry for node '{node_name}' or '/**'")
    merged = dict(wildcard)
    merged.update(own)
    return merged


def _check_flow_depth(path, text):
    """Refuse flow collections nested deeper than MAX_FLOW_DEPTH, in one linear scan
    (brackets inside strings and comments count too: only absurd files are refused), and
    lines of more than MAX_FLOW_DEPTH nested block entries."""
    deep = _BLOCK_ENTRIES.search(text)
    if deep:
        line = text.count('\n', 0, deep.start()) + 1
        raise MechanismConfigError(
            'params_file', f'{path} nests block entries ("- - - ...") more than '
                           f'{MAX_FLOW_DEPTH} deep on line {line}; a mechanism needs none')
    depth = 0
    for match in _BRACKETS.finditer(text):
        if match.group() in '[{':
            depth += 1
            if depth > MAX_FLOW_DEPTH:
                line = text.count('\n', 0, match.start()) + 1
                raise MechanismConfigError(
                    'params_file', f'{path} nests [...] or {{...}} more than {MAX_FLOW_DEPTH} '
                                   f'deep (line {line}); a mechanism needs one level (lists of '
                                   f'numbers or names)')
        else:
            depth = max(0, depth - 1)


_SafeBase = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)   # libyaml's parser when built


class ParamsLoader(_SafeBase):
    """YAML's safe loader (libyaml's parser where available: 50x faster), as strict as a
    ROS parameter file should be read: a key written twice in one mapping is an error (not
    "the last wins"), and floats may be written without a dot (``1e9``, ``-1e-4``), as rcl
    reads them."""

    def construct_mapping(self, node, deep=False):
        seen = set()
        for key_node, _ in node.value:
            if isinstance(key_node, yaml.ScalarNode) and key_node.tag != 'tag:yaml.org,2002:merge':
                key = key_node.value
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        'while reading a mapping', node.start_mark,
                        f'the key {show(key)} is written twice', key_node.start_mark)
                seen.add(key)
        return super().construct_mapping(node, deep)


ParamsLoader.yaml_implicit_resolvers = {
    first: list(resolvers) for first, resolvers in _SafeBase.yaml_implicit_resolvers.items()}
ParamsLoader.add_implicit_resolver(
    'tag:yaml.org,2002:float', re.compile(r'^[-+]?[0-9][0-9_]*(?:\.[0-9_]*)?[eE][-+]?[0-9]+$'),
    list('-+0123456789'))


class ParameterReader:
    """Typed access to a dotted-name dict; every error names the parameter."""

    def __init__(self, params):
        self.params = flatten(params)
        self.used = set()

    def has(self, name):
        return name in self.params

    def raw(self, name, default=None, required=False):
        if name not in self.params:
            if required:
                raise MechanismConfigError(name, 'missing')
            return default
        self.used.add(name)
        value = self.params[name]
        if value is None:
            raise MechanismConfigError(
                name, 'has no value (~ or null); give a value or delete the line'
                      + ('' if required else ' to use the default'))
        return value

    def string(self, name, default=None, required=False):
        value = self.raw(name, default, required)
        if value is not None and not isinstance(value, str):
            raise MechanismConfigError(name, f'must be a string, got {show(value)}')
        return value

    def number(self, name, default=None, required=False):
        value = self.raw(name, default, required)
        return None if value is None else as_float(name, value)

    def string_list(self, name, required=False):
        value = self.raw(name, None, required)
        if value is None:
            return None
        if isinstance(value, str) or not _is_sequence(value):
            raise MechanismConfigError(name, f'must be a list of names, got {show(value)}')
        _check_length(name, value)
        names, seen = [], set()
        for item in value:
            if not isinstance(item, str) or not item:
                raise MechanismConfigError(
                    name, f'must be a list of names, got {show(item)} in it')
            if item in seen:
                raise MechanismConfigError(name, f"duplicate name '{item}'")
            seen.add(item)
            names.append(item)
        return names

    def vector(self, name, length=None, default=None, required=False):
        value = self.raw(name, None, required)
        if value is None:
            return None if default is None else tuple(float(x) for x in default)
        if isinstance(value, str) or not _is_sequence(value):
            raise MechanismConfigError(name, f'must be a list of numbers, got {show(value)}')
        _check_length(name, value)
        numbers = tuple(as_float(name, x) for x in value)
        if length is not None and len(numbers) != length:
            raise MechanismConfigError(name, f'must have {length} entries, got {len(numbers)}')
        return numbers

    def unused(self, prefix):
        return sorted(k for k in self.params if k.startswith(prefix) and k not in self.used)


def _is_sequence(value):
    if isinstance(value, (list, tuple)):
        return True
    if isinstance(value, (dict, set, frozenset, bytes, bytearray)):
        return False
    return hasattr(value, '__len__') and hasattr(value, '__iter__')


def _check_length(name, value):
    try:
        length = len(value)
    except Exception:  # noqa: BLE001 -- e.g. a 0-d numpy array
        raise MechanismConfigError(name, f'must be a list, got {show(value)}') from None
    if length > MAX_LIST_LENGTH:
        raise MechanismConfigError(
            name, f'has {length} entries, more than the supported {MAX_LIST_LENGTH}')


def as_float(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) and not _is_number_like(value):
        raise MechanismConfigError(name, f'must be a number, got {show(value)}')
    try:
        number = float(value)
    except OverflowError:
        digits = int(value.bit_length() * math.log10(2)) + 1
        raise MechanismConfigError(
            name, f'must be a finite number, got an integer of about {digits} digits, too '
                  f'large for a float') from None
    if not math.isfinite(number):
        if math.isinf(number) and _is_number_like(value) and _finite_in_own_type(value):
            raise MechanismConfigError(
                name, f'must be a finite number, got {show(value)}, too large for a float')
        raise MechanismConfigError(name, f'must be a finite number, got {number!r}')
    return number


def _finite_in_own_type(value):
    try:
        import numpy as np
        return bool(np.isfinite(value))
    except (ImportError, TypeError):  # pragma: no cover
        return False


def _is_number_like(value):
    try:
        import numpy as np
        return isinstance(value, np.number) and not isinstance(value, np.bool_)
    except ImportError:  # pragma: no cover
        return False
