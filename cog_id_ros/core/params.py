"""Reading mechanism parameters: ROS 2 parameter files and dicts of dotted names.

A parameter file is the one ``--ros-args --params-file`` reads: node entries (the node's
name, optionally with its namespace, or the wildcard ``/**``) each holding
``ros__parameters``. As in rclpy, the wildcard entries apply first and the node's own entry
overrides them. Nested mappings become dotted names (``links.link1.mass``), exactly the
names rclpy gives the node, so the same dict feeds ``Mechanism.from_parameters``.

The typed getters below turn anything a user can write (YAML integers where floats are
meant, tuples, numpy arrays) into plain Python values, and raise MechanismConfigError naming
the parameter for anything else.
"""
import math

import yaml

from .errors import MechanismConfigError

DEFAULT_NODE_NAME = 'cog_id_node'


def flatten(tree, prefix=''):
    """{'a': {'b': 1}} -> {'a.b': 1}; dotted keys that are already flat pass through."""
    flat = {}
    for key, value in tree.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            flat.update(flatten(value, name + '.'))
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
    try:
        with open(path, encoding='utf-8') as stream:
            document = yaml.safe_load(stream)
    except OSError as exc:
        raise MechanismConfigError('params_file', f'cannot read {path}: {exc.strerror}') from exc
    except yaml.YAMLError as exc:
        raise MechanismConfigError('params_file', f'{path} is not valid YAML: {exc}') from exc
    if not isinstance(document, dict):
        raise MechanismConfigError('params_file', f'{path} holds no node entries')
    wildcard, own = {}, {}
    for entry, body in document.items():
        kind = _entry_matches(str(entry), node_name)
        if kind is None:
            continue
        if not isinstance(body, dict) or not isinstance(body.get('ros__parameters'), dict):
            raise MechanismConfigError(
                'params_file', f'{path}: entry {entry!r} has no ros__parameters mapping')
        (wildcard if kind == 'wildcard' else own).update(flatten(body['ros__parameters']))
    if not wildcard and not own:
        raise MechanismConfigError(
            'params_file', f"{path} has no entry for node '{node_name}' or '/**'")
    merged = dict(wildcard)
    merged.update(own)
    return merged


class ParameterReader:
    """Typed access to a dotted-name dict; every error names the parameter."""

    def __init__(self, params):
        self.params = flatten(params) if any(isinstance(v, dict) for v in params.values()) \
            else dict(params)
        self.used = set()

    def has(self, name):
        return name in self.params

    def raw(self, name, default=None, required=False):
        if name not in self.params:
            if required:
                raise MechanismConfigError(name, 'missing')
            return default
        self.used.add(name)
        return self.params[name]

    def string(self, name, default=None, required=False):
        value = self.raw(name, default, required)
        if value is not None and not isinstance(value, str):
            raise MechanismConfigError(name, f'must be a string, got {value!r}')
        return value

    def number(self, name, default=None, required=False):
        value = self.raw(name, default, required)
        return None if value is None else as_float(name, value)

    def string_list(self, name, required=False):
        value = self.raw(name, None, required)
        if value is None:
            return None
        if isinstance(value, str) or not _is_sequence(value):
            raise MechanismConfigError(name, f'must be a list of names, got {value!r}')
        names = []
        for item in value:
            if not isinstance(item, str) or not item:
                raise MechanismConfigError(name, f'must be a list of names, got {item!r} in it')
            if item in names:
                raise MechanismConfigError(name, f"duplicate name '{item}'")
            names.append(item)
        return names

    def vector(self, name, length=None, default=None, required=False):
        value = self.raw(name, None, required)
        if value is None:
            return None if default is None else tuple(float(x) for x in default)
        if isinstance(value, str) or not _is_sequence(value):
            raise MechanismConfigError(name, f'must be a list of numbers, got {value!r}')
        numbers = tuple(as_float(name, x) for x in value)
        if length is not None and len(numbers) != length:
            raise MechanismConfigError(name, f'must have {length} entries, got {len(numbers)}')
        return numbers

    def unused(self, prefix):
        return sorted(k for k in self.params if k.startswith(prefix) and k not in self.used)


def _is_sequence(value):
    return isinstance(value, (list, tuple)) or (hasattr(value, '__len__') and hasattr(value, '__iter__'))


def as_float(name, value):
    if isinstance(value, bool) or not isinstance(value, (int, float)) and not _is_number_like(value):
        raise MechanismConfigError(name, f'must be a number, got {value!r}')
    number = float(value)
    if not math.isfinite(number):
        raise MechanismConfigError(name, f'must be finite, got {number!r}')
    return number


def _is_number_like(value):
    try:
        import numpy as np
        return isinstance(value, np.number) and not isinstance(value, np.bool_)
    except ImportError:  # pragma: no cover
        return False
