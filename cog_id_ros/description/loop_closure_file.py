"""``mechanism.loop_closure_file``: the loop list that closed-loop robot models published for
Pinocchio keep beside their URDF (docs/loading_a_closed_loop_urdf.md, docs/urdf.md).

The file is YAML with five lists, as those models write it::

    closed_loop: [['frame_a', 'frame_b'], ...]   # two frames that coincide at assembly
    type: ['6d', '3d', ...]                      # 6d: welded (a fixed closure); 3d: their
                                                 # origins coincide (a spherical closure)
    name_mot: ['motor_1', ...]                   # the actuated joints
    joint_name: ['ball_joint', ...]              # joint edits: these URDF joints become
    joint_type: ['SPHERICAL', ...]               # SPHERICAL, FIXED or UJOINT_<A><B>

A frame is a URDF link (its frame) or a URDF joint (its frame, which is its child link's),
links welded to others by fixed joints included. The closures are named ``closed_loop_<k>``
(k from 1, file order). The joint edits are applied as the Pinocchio loader of that
collection applies them: ``SPHERICAL``, the joint becomes a spherical joint at its frame;
``FIXED``, a fixed joint (welded at position 0, where the URDF places the child);
``UJOINT_<A><B>`` (A, B two of X, Y, Z), two revolute joints ``<joint>_<A>`` then
``<joint>_<B>`` about those axes of the joint frame, through a massless link
``<joint>_cross``. ``type`` and ``joint_type`` values are read case-insensitively.

Every error is a MechanismConfigError naming ``mechanism.loop_closure_file``, the file, the
key and the entry. The file is read as defensively as a parameter file: a regular file of
at most MAX_FILE_CHARS, through :mod:`.yaml_guard` (no collections nested more than
``yaml_guard.MAX_DEPTH`` deep: PyYAML's C loader crashes the process on deeper ones).
"""
import os
import stat

import numpy as np
import yaml

from ..core.errors import MechanismConfigError
from ..core.kinematics.parameters import show
from . import yaml_guard
from .frames import ZERO
from .loop_closures import Closure
from .params_file import ParamsLoader

PARAMETER = 'mechanism.loop_closure_file'
#: the keys of the file (a real file has these five; others are refused as typos)
KEYS = ('closed_loop', 'type', 'name_mot', 'joint_name', 'joint_type')
#: closure kind of each ``type`` (lower case)
CLOSURE_TYPES = {'6d': 'fixed', '3d': 'spherical'}
#: the joint edits (upper case) other than UJOINT_<A><B>, as the kind the joint becomes
JOINT_EDITS = {'SPHERICAL': 'spherical', 'FIXED': 'fixed'}
#: largest loop-closure file read (characters); a robot's is a few hundred
MAX_FILE_CHARS = 256 * 1024
_UNIT = {'X': (1.0, 0.0, 0.0), 'Y': (0.0, 1.0, 0.0), 'Z': (0.0, 0.0, 1.0)}


class LoopFile:
    """What a loop-closure file says: frame pairs, actuated joints, joint edits."""

    def __init__(self, path: str, data: dict) -> None:
        self.path = path
        for key in data:
            if key not in KEYS:
                raise self.error(key, None, f'unknown key (the file takes {", ".join(KEYS)})')
        pairs = self._list(data, 'closed_loop')
        types = self._list(data, 'type')
        if pairs and all(isinstance(x, str) for x in pairs):
            # one pair written without its list around it: say so, not that types are missing
            raise self.error('closed_loop', None, f'must be a list of pairs of frame names, '
                                                  f'got {show(pairs)}: write [{show(pairs)}]')
        self._same_length('closed_loop', pairs, 'type', types)
        self.pairs = []
        for k, (pair, kind) in enumerate(zip(pairs, types)):
            if not (isinstance(pair, list) and len(pair) == 2
                    and all(isinstance(x, str) and x for x in pair)):
                raise self.error('closed_loop', k, f'must be a pair of frame names, got '
                                                   f'{show(pair)}')
            closure = CLOSURE_TYPES.get(kind.lower()) if isinstance(kind, str) else None
            if closure is None:
                raise self.error('type', k, f"must be '6d' (welded) or '3d' (a ball joint), "
                                            f'got {show(kind)}')
            self.pairs.append((pair[0], pair[1], closure))
        self.motors = self._names(data, 'name_mot') if 'name_mot' in data else None
        names = self._names(data, 'joint_name')
        edits = self._list(data, 'joint_type')
        self._same_length('joint_name', names, 'joint_type', edits)
        self.edits = []
        for k, (name, edit) in enumerate(zip(names, edits)):
            self.edits.append((name, self._edit(k, edit)))

    def error(self, key: str, index: 'int | None', message: str) -> MechanismConfigError:
        """The error about ``key`` (entry ``index``, from 0, shown from 1) of the file."""
        where = key if index is None else f'{key} entry {index + 1}'
        return MechanismConfigError(PARAMETER, f'{self.path}: {where}: {message}')

    def _list(self, data: dict, key: str) -> list:
        value = data.get(key, [])
        if not isinstance(value, list):
            raise self.error(key, None, f'must be a list, got {show(value)}')
        return value

    def _names(self, data: dict, key: str) -> list:
        names = self._list(data, key)
        for k, name in enumerate(names):
            if not isinstance(name, str) or not name:
                raise self.error(key, k, f'must be a joint name, got {show(name)}')
            if name in names[:k]:
                raise self.error(key, k, f'{name!r} is listed twice')
        return names

    def _same_length(self, key: str, items: list, other: str, others: list) -> None:
        if len(items) != len(others):
            raise self.error(other, None, f'has {len(others)} entries, {key} has '
                                          f'{len(items)}: one per entry of {key}')

    def _edit(self, k: int, edit: object) -> str:
        text = edit.upper() if isinstance(edit, str) else None
        if text in JOINT_EDITS:
            return text
        if text is not None and text.startswith('UJOINT_') and len(text) == 9 and \
                text[7] in _UNIT and text[8] in _UNIT and text[7] != text[8]:
            return text
        raise self.error('joint_type', k, f'must be SPHERICAL, FIXED or UJOINT_<A><B> (A, B '
                                          f'two different axes of X, Y, Z), got {show(edit)}')


def read_loop_file(r, base_dir: 'str | None') -> 'LoopFile | None':
    """The file ``mechanism.loop_closure_file`` names (parameters read by ``r``), relative to
    ``base_dir`` (default: the working directory); None when it is not given."""
    given = r.string(PARAMETER)
    if given is None:
        return None
    if not given.strip():
        raise MechanismConfigError(PARAMETER, 'is empty; give the path of the YAML loop list')
    path = given if os.path.isabs(given) else os.path.join(base_dir or os.getcwd(), given)
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):     # a FIFO would block the reader
            raise MechanismConfigError(PARAMETER, f'{path} is not a regular file')
        with open(path, encoding='utf-8') as stream:
            text = stream.read(MAX_FILE_CHARS + 1)
    except OSError as exc:
        raise MechanismConfigError(PARAMETER, f'cannot read {path}: {exc.strerror or exc}'
                                   ) from None
    except UnicodeDecodeError:
        raise MechanismConfigError(PARAMETER, f'{path} is not UTF-8 text') from None
    except ValueError as exc:      # a NUL in the path
        raise MechanismConfigError(PARAMETER, f'cannot read {show(path)}: {exc}') from None
    if len(text) > MAX_FILE_CHARS:
        raise MechanismConfigError(PARAMETER, f'{path} is larger than the supported '
                                              f'{MAX_FILE_CHARS // 1024} kB')
    try:
        data = yaml_guard.load(text, ParamsLoader, PARAMETER, path)
    except (yaml.YAMLError, RecursionError, ValueError, OverflowError) as exc:
        raise MechanismConfigError(PARAMETER, f'{path} is not valid YAML: {exc}') from None
    if not isinstance(data, dict):
        raise MechanismConfigError(PARAMETER, f'{path} must hold a mapping with the keys '
                                              f'{", ".join(KEYS)}, got {show(data)}')
    return LoopFile(path, data)


class _Link:
    """The massless link between the two revolute joints of a UJOINT edit."""

    def __init__(self, name: str, line: int) -> None:
        self.name, self.line = name, line
        self.mass, self.com, self.inertia = 0.0, ZERO, np.zeros((3, 3))


def apply_edits(robot, loop_file: LoopFile) -> None:
    """The file's joint edits, made to ``robot`` (urdf_tree.Robot) in place."""
    for k, (name, edit) in enumerate(loop_file.edits):
        joint = robot.joints.get(name)
        if joint is None:
            raise loop_file.error('joint_name', k, f'{name!r} is not a joint of the URDF')
        if edit in JOINT_EDITS:
            joint.kind, joint.axis, joint.limit = JOINT_EDITS[edit], None, None
            continue
        first, second = f'{name}_{edit[7]}', f'{name}_{edit[8]}'
        cross = f'{name}_cross'
        for taken, what in ((first, 'joint'), (second, 'joint'), (cross, 'link')):
            if taken in robot.joints or taken in robot.links:
                raise loop_file.error('joint_type', k, f'{edit} of {name!r} makes the {what} '
                                                       f'{taken!r}, a name the URDF already has')
        _split(robot, joint, (first, second, cross), (_UNIT[edit[7]], _UNIT[edit[8]]))
        robot.renamed[name] = (first, second)
    robot.parent_joint = {joint.child: joint for joint in robot.joints.values()}
    robot.children = {name: [] for name in robot.links}
    for joint in robot.joints.values():
        robot.children[joint.parent].append(joint)


def _split(robot, joint, names: tuple, axes: tuple) -> None:
    """Joint ``joint`` of ``robot`` as two revolute joints through a massless link: the
    first at the joint's origin, the second at the first's child frame."""
    first, second, cross = names
    one = type(joint)(first, joint.line, 'revolute', joint.parent, cross, joint.xyz,
                      joint.rpy, axes[0], None)
    two = type(joint)(second, joint.line, 'revolute', cross, joint.child, ZERO, ZERO,
                      axes[1], None)
    robot.joints = {new.name: new for old in robot.joints.values()
                    for new in ((one, two) if old is joint else (old,))}
    links = {}
    for name, link in robot.links.items():
        if name == joint.child:
            links[cross] = _Link(cross, joint.line)
        links[name] = link
    robot.links = links


def file_closures(robot, loop_file: LoopFile, frames: dict, taken: set) -> list:
    """The closures of the file's frame pairs, ``closed_loop_<k>``; ``frames``: the link of
    every URDF link and joint name as written (before the edits); ``taken``: the names of
    closures given otherwise and of the URDF's joints."""
    closures = []
    for k, (frame_a, frame_b, kind) in enumerate(loop_file.pairs):
        name = f'closed_loop_{k + 1}'
        if name in taken:
            raise loop_file.error('closed_loop', k, f'its closure is named {name!r}, which '
                                                    f'is already a joint or loop closure; '
                                                    f'rename that one')
        ends = []
        for frame in (frame_a, frame_b):
            if frame not in frames:
                raise loop_file.error('closed_loop', k, f'{frame!r} is neither a link nor a '
                                                        f'joint of the URDF')
            ends.append(frames[frame])
        closures.append(_FileClosure(name, kind, ends, loop_file, k, [frame_a, frame_b]))
    return closures


class _FileClosure(Closure):
    """A closure of a frame pair: both frames are link frames (no offsets, no axes); its
    errors name the file and the entry."""

    def __init__(self, name: str, kind: str, ends: list, loop_file: LoopFile, index: int,
                 entry: list) -> None:
        super().__init__(name, kind, ends[0], ends[1], (ZERO, ZERO, ZERO, ZERO), None, None)
        self.loop_file, self.index, self.entry = loop_file, index, entry

    def error(self, key: str, message: str) -> MechanismConfigError:
        return self.loop_file.error('closed_loop', self.index, f'{self.entry}: {message}')
