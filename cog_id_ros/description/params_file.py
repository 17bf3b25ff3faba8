"""The ROS 2 parameter-file reader: what ``--ros-args --params-file`` would give a node.

A parameter file holds node entries (the node's name, optionally with its namespace, or
the wildcard ``/**``) each holding ``ros__parameters``. As in rclpy, the wildcard entries
apply first and the node's own entry overrides them. Nested mappings become dotted names
(``links.link1.mass``), exactly the names rclpy gives the node, so the dict this returns
feeds ``Mechanism.from_parameters`` (which is what ``Mechanism.from_params_file`` does).

The file is read as strictly as rcl reads it (numbers as rcl reads them: floats may be
written without a dot, and 1_0 or 1:30 are text, not numbers; a key written twice is an
error here, where rcl lets the last one win) and defensively: only
regular files of at most ``MAX_FILE_CHARS`` (not counting a ``robot_description``, which
the URDF reader bounds), no FIFOs, no collections nested more than
``yaml_guard.MAX_DEPTH`` deep (:mod:`.yaml_guard`, which every YAML the package reads
goes through), no recursive aliases. An array rcl's parser refuses makes the file an error
here too, naming the parameter (:func:`rcl_value_problem`: an array that mixes integers
and doubles, ``[0, -9.81, 0]``, or other types), in any node entry, as rcl refuses the whole file:
cog_id_node and the API accept the same files (the node checks its ``--params-file``s with
:func:`check_rcl_values` before rcl reads them). Only files: a dict given to
``Mechanism.from_parameters`` may mix integers and floats freely. Whatever the file holds,
only MechanismConfigError comes out of here, naming the parameter or ``params_file``, in
time proportional to the size of the file.
"""
import fnmatch
import os
import re
import stat

import yaml

from ..core.errors import MechanismConfigError
from ..core.kinematics.parameters import flatten, show
from . import yaml_guard
from .urdf_xml import MAX_URDF_SIZE

#: the node entry read when none is named (the node's default name)
DEFAULT_NODE_NAME = 'cog_id_node'

#: largest parameter file read (characters), not counting the values of its
#: robot_description parameters: a URDF has one limit however it arrives, the URDF reader's
#: (urdf_xml.MAX_URDF_SIZE). A mechanism within the size limits of mechanism.py takes well
#: under 100 kB, and 512 kB of YAML load in about 1.5 s on a small machine (what costs is
#: YAML's structure: a long string is read in no time)
MAX_FILE_CHARS = 512 * 1024
#: most characters ever read from a parameter file: MAX_FILE_CHARS and a robot_description,
#: with room for twice the URDF limit as written in YAML (a block's indentation, a quoted
#: string's escapes), so that the URDF reader, not this one, refuses a URDF over its limit
_MAX_READ = MAX_FILE_CHARS + 2 * MAX_URDF_SIZE
#: deepest nesting of YAML collections read (yaml_guard.MAX_DEPTH): PyYAML's C loader
#: crashes the process on deeper ones
MAX_FLOW_DEPTH = yaml_guard.MAX_DEPTH


def _entry_matches(entry, node_name):
    if entry in ('/**', '**'):
        return 'wildcard'
    bare = entry.strip('/')
    if bare == node_name.strip('/') or bare.split('/')[-1] == node_name.strip('/').split('/')[-1]:
        return 'node'
    if entry.endswith('/**') or entry.startswith('/**/'):
        return 'wildcard'
    return None


def other_nodes(path, full_name):
    """The entries of the parameter file ``path`` when rcl gives the node of full name
    ``full_name`` ('/ns/name') none of them: the nodes it gives parameters to instead; []
    when one is for it (or the file cannot be read: that is said elsewhere); None when
    the file holds no node entries at all. rcl's rule: an entry is the node's full name
    (a leading '/' implied), '/**', or a pattern whose '*' matches any text ('/**/name'
    also at the root)."""
    try:
        document = read_document(path, duplicate_keys=True)
    except MechanismConfigError:
        return []
    if not isinstance(document, dict):
        return None
    entries = [str(entry) for entry in document]
    for entry in entries:
        pattern = '/' + entry.lstrip('/')
        if pattern == full_name or fnmatch.fnmatchcase(full_name, pattern) or (
                pattern.startswith('/**/') and fnmatch.fnmatchcase(full_name, pattern[3:])):
            return []
    return entries


def load_params_file(path, node_name=DEFAULT_NODE_NAME):
    """Dotted-name dict of the parameters a node called ``node_name`` gets from ``path``."""
    if not isinstance(node_name, str):
        raise MechanismConfigError('node_name', f'must be a string, got {show(node_name)}')
    document = read_document(path)
    check_rcl_values(document, path)
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


def read_document(path, duplicate_keys=False):
    """The YAML document of the parameter file ``path``, read defensively (see the module
    docstring), numbers as rcl reads them. A key written twice in one mapping is an error
    unless ``duplicate_keys`` (rcl lets the last one win: the node's check of its files).
    MechanismConfigError('params_file', ...) when it cannot be read."""
    if not isinstance(path, (str, os.PathLike)):    # an int would be taken as a descriptor
        raise MechanismConfigError(
            'params_file', f'must be a path to a file, got {type(path).__name__} {show(path)}')
    loader = RclLoader if duplicate_keys else ParamsLoader
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):     # a FIFO would block the reader
            raise MechanismConfigError('params_file', f'{path} is not a regular file')
        with open(path, encoding='utf-8') as stream:
            text = stream.read(_MAX_READ + 1)
        if len(text) > _MAX_READ:
            raise _too_large(path)
        if len(text) > MAX_FILE_CHARS:
            yaml_guard.check_nesting(text, 'params_file', path)   # before it is parsed here
            if _beyond_cap(text, loader):
                raise _too_large(path)
        return yaml_guard.load(text, loader, 'params_file', path)
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


def _too_large(path):
    return MechanismConfigError(
        'params_file', f'{path} is larger than the supported {MAX_FILE_CHARS // 1024} kB, not '
                       f'counting its robot_description (a URDF of up to '
                       f'{MAX_URDF_SIZE // (1024 * 1024)} MB); a mechanism within the size limits '
                       f'(docs/mechanism.md) takes far less: keep the mechanism in a file of its '
                       f'own')


def _beyond_cap(text, loader):
    """Whether ``text`` holds more than MAX_FILE_CHARS characters outside the values of its
    robot_description parameters (``<node entry>: ros__parameters: robot_description:``, a
    string, with its quotes, escapes or block indentation).

    Told from YAML's parse events, which cost little next to building the document, and
    only up to the first event that ends beyond MAX_FILE_CHARS plus what robot_description
    values took so far: the rest of an oversized file is never parsed."""
    excluded = 0
    open_ = []      # per open collection: [is a mapping, expects a key, its current key]
    for event in yaml.parse(text, Loader=loader):
        if isinstance(event, (yaml.MappingEndEvent, yaml.SequenceEndEvent)):
            open_.pop()
        elif isinstance(event, yaml.NodeEvent):       # scalar, alias, collection start
            parent = open_[-1] if open_ else None
            if parent is not None and parent[0]:
                if parent[1]:                          # a key
                    parent[2] = event.value if isinstance(event, yaml.ScalarEvent) else None
                else:                                  # a value
                    if isinstance(event, yaml.ScalarEvent) and len(open_) == 3 and \
                            all(frame[0] for frame in open_) and \
                            open_[1][2] == 'ros__parameters' and \
                            open_[2][2] == 'robot_description':
                        excluded += event.end_mark.index - event.start_mark.index
                parent[1] = not parent[1]
            if isinstance(event, yaml.CollectionStartEvent):
                open_.append([isinstance(event, yaml.MappingStartEvent), True, None])
        if event.end_mark.index - excluded > MAX_FILE_CHARS:
            return True
    return False


def check_rcl_values(document, path):
    """MechanismConfigError naming the first parameter, in any node entry of ``document``
    (from :func:`read_document`), whose value rcl's parameter-file parser refuses
    (:func:`rcl_value_problem`); rcl refuses the whole file for it, whichever node the
    entry is for. Entries rcl would refuse for their shape are left to the caller."""
    if not isinstance(document, dict):
        return
    for body in document.values():
        params = body.get('ros__parameters') if isinstance(body, dict) else None
        if not isinstance(params, dict):
            continue
        try:
            flat = flatten(params, source='params_file')   # (bounded: aliases, depth)
        except MechanismConfigError:
            continue        # refused by whoever reads this entry (load_params_file, rclpy)
        for name, value in flat.items():
            problem = rcl_value_problem(value)
            if problem:
                raise MechanismConfigError(name, f'{problem} (in {path})')
        _check_dotted_mappings(params, '', path)


def _check_dotted_mappings(tree, prefix, path):
    """A key holding '.' whose value is a mapping, followed by another key of its mapping,
    is refused: rcl's parameter-file parser then files the keys after it under a wrong
    name (``links: {"link.one": {mass: 1.0}, link2: ...}`` gives ``links.link.link2.mass``;
    checked with rcl, Jazzy). Its entries are written as flat keys instead."""
    keys = list(tree)
    for k, key in enumerate(keys):
        value = tree[key]
        if not isinstance(value, dict):
            continue
        if isinstance(key, str) and '.' in key and k + 1 < len(keys) and value:
            first = next(iter(value))
            raise MechanismConfigError(
                f'{prefix}{key}',
                f"the key {key!r} holds '.' and a mapping, and {keys[k + 1]!r} follows it: "
                f"ROS 2's parameter-file parser would read {keys[k + 1]!r} as "
                f"'{prefix}{key.rsplit('.', 1)[0]}.{keys[k + 1]}'. Write its entries as flat "
                f'quoted keys instead, e.g. "{key}.{first}": ... (docs/mechanism.md, "Names '
                f'of links and joints"; in {path})')
        _check_dotted_mappings(value, f'{prefix}{key}.', path)


def rcl_value_problem(value):
    """Why rcl's parameter-file parser refuses ``value`` (as read from YAML), or None.

    The one rule, for cog_id_node and the API alike: an array is one type. rcl refuses an
    array that mixes integers and doubles (``[0, -9.81, 0]``) or other types; arrays of
    integers alone are fine where doubles are meant (``[0, 0, 1]``). Only what rcl is known
    to refuse: cog_id_node names anything else rcl refuses by its line.
    """
    if not isinstance(value, list) or not all(
            isinstance(item, (bool, int, float, str)) for item in value):
        return None
    kinds = set()
    for item in value:
        kinds.add(bool if isinstance(item, bool) else int if isinstance(item, int)
                  else float if isinstance(item, float) else str)
    if kinds == {int, float}:
        return (f"the array mixes integers and doubles ({value!r}), which ROS 2's parameter "
                'file parser refuses: write every number as a double (0.0, not 0)')
    if len(kinds) > 1:
        return (f"the array mixes types ({value!r}), which ROS 2's parameter file parser "
                'refuses: one type per array')
    return None


_SafeBase = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)   # libyaml's parser when built


class RclLoader(_SafeBase):
    """YAML's safe loader (libyaml's parser where available: 50x faster) reading numbers as
    rcl does: floats may be written without a dot (``1e9``, ``-1e-4``) or a leading digit
    (``-.5``), and ``1_0``, ``1:30`` and ``0b1`` are strings (YAML 1.1 reads 10, 90, 1)."""


class ParamsLoader(RclLoader):
    """:class:`RclLoader`, as strict as a ROS parameter file should be read: a key written
    twice in one mapping is an error (not "the last wins")."""

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


# Numbers as rcl reads them (rcl_yaml_param_parser, get_value: strtoll with base 0, then
# strtod, each consuming the whole text, else a string). YAML 1.1's resolvers read digits
# with '_' between them (1_0 as 10), base 60 (1:30 as 90) and binary (0b101 as 5), which rcl
# reads as the strings '1_0', '1:30' and '0b101' (checked with rcl, Jazzy): left out, so the
# API refuses them as the node does ("must be a number"). They do not read what strtod does
# and rcl takes as a double: -.5, .5e3, 1e9 (no dot), 09: added.
_INT, _FLOAT = 'tag:yaml.org,2002:int', 'tag:yaml.org,2002:float'
RclLoader.yaml_implicit_resolvers = {
    first: [(tag, regexp) for tag, regexp in resolvers if tag not in (_INT, _FLOAT)]
    for first, resolvers in _SafeBase.yaml_implicit_resolvers.items()}
RclLoader.add_implicit_resolver(       # first: a text both match (12) is an integer, as in rcl
    _INT, re.compile(r'^[-+]?(?:0[0-7]*|[1-9][0-9]*|0x[0-9a-fA-F]+)$'), list('-+0123456789'))
RclLoader.add_implicit_resolver(
    _FLOAT, re.compile(r'^(?:[-+]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][-+]?[0-9]+)?'
                       r'|[-+]?\.(?:inf|Inf|INF)|\.(?:nan|NaN|NAN))$'),
    list('-+0123456789.'))
