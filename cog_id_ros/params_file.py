"""The ROS 2 parameter-file reader: what ``--ros-args --params-file`` would give a node.

A parameter file holds node entries (the node's name, optionally with its namespace, or
the wildcard ``/**``) each holding ``ros__parameters``. As in rclpy, the wildcard entries
apply first and the node's own entry overrides them. Nested mappings become dotted names
(``links.link1.mass``), exactly the names rclpy gives the node, so the dict this returns
feeds ``Mechanism.from_parameters`` (which is what ``Mechanism.from_params_file`` does).

The file is read as strictly as rcl reads it (a key written twice is an error, floats may
be written without a dot) and defensively: only regular files of at most
``MAX_FILE_CHARS``, no FIFOs, no deeply nested flow collections, no recursive aliases.
Whatever the file holds, only MechanismConfigError comes out of here, naming the parameter
or ``params_file``, in time proportional to the size of the file.
"""
import os
import re
import stat

import yaml

from .core.errors import MechanismConfigError
from .core.parameters import flatten, show

#: the node entry read when none is named (the node's default name)
DEFAULT_NODE_NAME = 'cog_id_node'

#: largest parameter file read (characters); a mechanism within the size limits of
#: mechanism.py takes well under 100 kB, and 512 kB load in about 1.5 s on a small machine
MAX_FILE_CHARS = 512 * 1024
#: deepest nesting of YAML flow collections ([...] and {...}) read; PyYAML's scanner takes
#: time quadratic in it before its recursion gives up, and libyaml's parser crashes the
#: process on deeply nested input (so does a line of many nested block entries, "- - - x")
MAX_FLOW_DEPTH = 32
_BRACKETS = re.compile(r'[\[\]{}]')
_BLOCK_ENTRIES = re.compile(r'^[ \t]*((?:[-?:][ \t]+){33,})', re.MULTILINE)


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
