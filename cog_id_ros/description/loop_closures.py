"""The joints that close a tree's loops, as the URDF form gives them (docs/urdf.md):
``mechanism.loop_closures`` lists their names, ``loop_closures.<name>.*`` gives each one's
type, the links it joins, where it sits on each and its axes."""
import math

from ..core.errors import MechanismConfigError
from ..core.kinematics import joints
from ..core.kinematics.joints import AXES_PERPENDICULAR
from ..core.kinematics.parameters import show, split_owner
from ..core.model.mechanism import MAX_COORDINATE, MAX_LENGTH, bounded, name_problem
from .frames import ZERO

#: the keys of ``loop_closures.<name>.*``
CLOSURE_KEYS = ('type', 'parent', 'child', 'parent_xyz', 'parent_rpy', 'child_xyz',
                'child_rpy', 'axis', 'axis2')


class Closure:
    """A loop-closing joint: its name, kind (the native schema's type), the two URDF links
    it joins, where it sits on each and its axes."""

    def __init__(self, name, kind, parent, child, offsets, axis, axis2):
        self.name, self.kind, self.parent, self.child = name, kind, parent, child
        self.offsets = offsets           # parent_xyz, parent_rpy, child_xyz, child_rpy
        self.axis, self.axis2 = axis, axis2

    def error(self, key: str, message: str) -> MechanismConfigError:
        """The error about its ``key``, naming where it was given (a loop-closure file's
        closures name the file and the entry instead)."""
        return MechanismConfigError(f'loop_closures.{self.name}.{key}', message)


def read_closures(r, robot):
    """The loop closures ``mechanism.loop_closures`` lists (parameters read by ``r``), each
    checked against the links and joints of the URDF ``robot``."""
    names = r.string_list('mechanism.loop_closures') or []
    for name in names:
        problem = name_problem(name)
        if problem:
            raise MechanismConfigError('mechanism.loop_closures', f'{name!r} {problem}')
        if name in robot.joints:
            raise MechanismConfigError(
                'mechanism.loop_closures',
                f"'{name}' is already a joint of the URDF (line {robot.joints[name].line}); "
                f'give the loop closure a name of its own')
    for key in r.params:
        if key == 'loop_closures':
            value = r.params[key]
            if isinstance(value, dict) and not value and not names:
                continue
            raise MechanismConfigError(
                key, f'must map closure names to their keys ({", ".join(CLOSURE_KEYS)}), '
                     f'got {show(value)}')
        if not key.startswith('loop_closures.'):
            continue
        owner, rest = split_owner(key[len('loop_closures.'):], names)
        if owner is None:
            raise MechanismConfigError(
                key, f"'{rest.rsplit('.', 1)[0]}' is not in mechanism.loop_closures "
                     f"({', '.join(names) if names else 'none listed'}): list it there, or "
                     f'correct the name')
        if rest not in CLOSURE_KEYS:
            raise MechanismConfigError(
                key, f"unknown parameter (loop_closures.{owner}.* takes "
                     f"{', '.join(CLOSURE_KEYS)})")
    return [_read_closure(r, robot, name) for name in names]


def _read_closure(r, robot, name):
    prefix = f'loop_closures.{name}.'
    kind = r.string(prefix + 'type', required=True)     # the native schema's types
    kind_class = joints.kind(kind)
    if kind_class is None:
        raise MechanismConfigError(
            prefix + 'type', f"must be one of {', '.join(joints.names())}, got {show(kind)}")
    ends = []
    for side in ('parent', 'child'):
        link = r.string(prefix + side, required=True)
        if link not in robot.links:
            known = list(robot.links)
            listed = ', '.join(known[:12]) + (', ...' if len(known) > 12 else '')
            raise MechanismConfigError(
                prefix + side, f"unknown link '{link}' (not a link of the URDF: {listed})")
        ends.append(link)
    # bounded as written, as the core would bound them: on a link welded to another they
    # reach the core re-expressed (an rpy of 1e300 as an angle within +-pi), under joints.*
    offsets = tuple(bounded(prefix + key, r.vector(prefix + key, 3, default=ZERO), bound, unit)
                    for key, bound, unit in (('parent_xyz', MAX_LENGTH, 'm'),
                                             ('parent_rpy', MAX_COORDINATE, 'rad'),
                                             ('child_xyz', MAX_LENGTH, 'm'),
                                             ('child_rpy', MAX_COORDINATE, 'rad')))
    axis = axis2 = None
    if 'axis' in kind_class.parameters:
        axis = _axis(r, prefix + 'axis', (0.0, 0.0, 1.0))
    elif r.has(prefix + 'axis'):
        raise MechanismConfigError(prefix + 'axis', f'a {kind} closure has no axis; delete it')
    if 'axis2' in kind_class.parameters:
        if not r.has(prefix + 'axis2'):
            raise MechanismConfigError(
                prefix + 'axis2', 'missing: a universal closure needs axis2, its second axis '
                                  'in the child closure frame, perpendicular to axis')
        axis2 = _axis(r, prefix + 'axis2', None)
        cosine = abs(sum(a * b for a, b in zip(axis, axis2))) / (
            math.hypot(*axis) * math.hypot(*axis2))
        if cosine > AXES_PERPENDICULAR:
            raise MechanismConfigError(
                prefix + 'axis2', f'must be perpendicular to axis {list(axis)} (a universal '
                                  f'joint keeps its two axes perpendicular), got {list(axis2)}')
    elif r.has(prefix + 'axis2'):
        raise MechanismConfigError(
            prefix + 'axis2', f'only universal closures have axis2, this one is {kind}')
    return Closure(name, kind, ends[0], ends[1], offsets, axis, axis2)


def _axis(r, name, default):
    axis = r.vector(name, 3, default=default, required=default is None)
    if not math.hypot(*axis) > 0.0:
        raise MechanismConfigError(name, f'must not be zero-length, got {list(axis)}')
    return axis
