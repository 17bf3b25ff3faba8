"""The links and joints of a URDF, read from its elements and checked to form one tree.

Every number is read as urdfdom reads it and bounded as the native schema bounds what it
becomes (core/model/mechanism.py), at its element, so that an error names the line it is on.
"""
import math
import re

import numpy as np

from ..core.kinematics import joints
from ..core.kinematics.parameters import show
from ..core.model.mechanism import (
    MAX_COORDINATE,
    MAX_INERTIA,
    MAX_LENGTH,
    MAX_MASS,
    inertia_problem,
)
from .frames import ZERO, rpy_matrix
from .rigid_bodies import six
from .urdf_xml import parse_xml

#: URDF joint types read; the others are refused naming the joint
URDF_JOINT_TYPES = ('revolute', 'continuous', 'prismatic', 'fixed')
#: a number as urdfdom reads one: std::stringstream >> double in the classic locale, the
#: whole text consumed (urdf_model/utils.h, strToDouble). ASCII digits with an optional sign,
#: decimal point and exponent; not the '1_0', other scripts' digits, 'inf', 'nan' or
#: surrounding text that Python's float() also takes. A text that matches is read by float(),
#: which gives the same correctly rounded double as the C library
_NUMBER = re.compile(r'[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?')
#: what separates the numbers of xyz, rpy: urdfdom splits at spaces, and XML turns the tabs
#: and line breaks written in an attribute into spaces (a character reference such as &#9;
#: survives as itself: taken as a separator too, never as part of a number)
_SEPARATORS = re.compile(r'[ \t\r\n]+')


class _Link:
    def __init__(self, name, line, mass, com, inertia):
        self.name, self.line = name, line
        self.mass, self.com, self.inertia = mass, com, inertia   # COG in the link frame


class _Joint:
    def __init__(self, name, line, kind, parent, child, xyz, rpy, axis, limit):
        self.name, self.line, self.kind = name, line, kind     # kind: the URDF's type
        self.parent, self.child = parent, child
        self.xyz, self.rpy, self.axis = xyz, rpy, axis
        self.limit = limit       # (lower or None, upper or None, effort or None) or None
        self.mimic = None        # (leader joint, multiplier, offset) of a <mimic>, or None

    @property
    def welds(self):
        """A fixed joint: its two links are one rigid body (never a joint of the model)."""
        return self.kind == 'fixed'

    @property
    def joint_kind(self):
        """The core's joint kind of a joint that moves (URDF 'continuous': a revolute)."""
        return joints.kind(self.kind, aliases=True)


class Robot:
    """The links and joints of a URDF, checked to form one tree."""

    def __init__(self, source):
        self.source = source
        root = parse_xml(source)
        if root.tag != 'robot':
            raise source.error(root.line, f"the root element is <{root.tag}>; a URDF's is "
                                          f'<robot>')
        self.name = root.attrib.get('name') or None
        self.links = {}      # name -> _Link, in document order
        self.joints = {}     # name -> _Joint, in document order
        #: URDF joint name -> the two joints a loop-closure file's UJOINT edit made of it
        self.renamed = {}
        for element in root.children:
            if element.tag == 'link':
                link = self._link(element)
                self.links[link.name] = link
            elif element.tag == 'joint':
                joint = self._joint(element)
                self.joints[joint.name] = joint
        if not self.links:
            raise source.error(root.line, 'the URDF has no <link>')
        self._check_tree(root)

    def error(self, line, message):
        return self.source.error(line, message)

    def _name(self, element, kind):
        name = element.attrib.get('name')
        if not name:
            raise self.error(element.line, f'a <{kind}> without a name')
        if name in (self.links if kind == 'link' else self.joints):
            raise self.error(element.line, f"a second {kind} named '{name}'")
        return name

    def _one(self, element, tag, what, required=False):
        found = element.all(tag)
        if len(found) > 1:
            raise self.error(found[1].line, f'{what} has more than one <{tag}>')
        if not found and required:
            raise self.error(element.line, f'{what} has no <{tag}>')
        return found[0] if found else None

    def _numbers(self, element, attribute, what, count=3, default=None, bound=math.inf,
                 unit='', low=None):
        """The ``count`` numbers of an attribute, each written as urdfdom reads numbers
        (_NUMBER) and within +-``bound`` (the native schema's bound for the value, or from
        ``low`` to ``bound``): checked here, at the element, before any arithmetic on them
        (fixed-joint merging, rotations) could overflow or hide the value as written."""
        text = element.attrib.get(attribute)
        if text is None:
            if default is None:
                raise self.error(element.line,
                                 f'<{element.tag}> of {what} has no {attribute} attribute')
            return default
        where = f'{attribute}={show(text)} in <{element.tag}> of {what}'
        tokens = [token for token in _SEPARATORS.split(text) if token]
        for token in tokens:
            if not _NUMBER.fullmatch(token):
                raise self.error(element.line, f'{where}: {show(token)} is not a number; write '
                                               f'numbers as urdfdom reads them: ASCII digits '
                                               f'with an optional sign, decimal point and '
                                               f'exponent (e.g. -1.5e-3)')
        if len(tokens) != count:
            want = 'a number' if count == 1 else f'{count} numbers'
            raise self.error(element.line, f'{where}: must be {want}')
        values = tuple(float(token) for token in tokens)
        for token, value in zip(tokens, values):
            # the text as written, not the double: 1e400 overflows to inf
            written = token if len(token) <= 40 else show(token)
            if low is not None and value < low:
                raise self.error(element.line, f'{where}: must be >= {low:g} {unit}, got '
                                               f'{written}')
            if not abs(value) <= bound or math.isinf(value):
                if bound == math.inf:
                    why = 'is too large for a double'
                elif low is not None:
                    why = f'must be at most {bound:g} {unit}'
                else:
                    why = f"{'entries ' if count > 1 else ''}must lie within +-{bound:g} {unit}"
                raise self.error(element.line, f'{where}: {why}, got {written}')
        return values

    def _origin(self, element, what):
        """xyz and rpy of the <origin> in ``element``, within the bounds the native schema
        sets on the parent_xyz and parent_rpy (or com) they become."""
        origin = self._one(element, 'origin', what)
        if origin is None:
            return ZERO, ZERO
        return (self._numbers(origin, 'xyz', what, default=ZERO, bound=MAX_LENGTH, unit='m'),
                self._numbers(origin, 'rpy', what, default=ZERO, bound=MAX_COORDINATE,
                              unit='rad'))

    def _link(self, element):
        name = self._name(element, 'link')
        what = f"link '{name}'"
        inertial = self._one(element, 'inertial', what)
        if inertial is None:         # massless
            return _Link(name, element.line, 0.0, ZERO, np.zeros((3, 3)))
        xyz, rpy = self._origin(inertial, f'<inertial> of {what}')
        mass = self._one(inertial, 'mass', f'<inertial> of {what}', required=True)
        (value,) = self._numbers(mass, 'value', what, count=1, low=0.0, bound=MAX_MASS,
                                 unit='kg')
        tensor = self._one(inertial, 'inertia', f'<inertial> of {what}', required=True)
        ixx, ixy, ixz, iyy, iyz, izz = (
            self._numbers(tensor, key, what, count=1, bound=MAX_INERTIA, unit='kg m^2')[0]
            for key in ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz'))
        inertia = np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])
        rotation = rpy_matrix(rpy)
        inertia = rotation @ inertia @ rotation.T
        # Checked here, on what the core would be given for this link alone (the link frame,
        # symmetrised), rather than by the core: a link welded to another by a fixed joint
        # reaches the core only inside their sum, under the other link's name
        problem = inertia_problem(six(inertia))
        if problem:
            frame = ' (rotated into the link frame by the <origin> rpy)' if any(rpy) else ''
            raise self.error(tensor.line, f'<inertia> of {what}{frame}: {problem}')
        return _Link(name, element.line, value, xyz, inertia)

    def _joint(self, element):
        name = self._name(element, 'joint')
        what = f"joint '{name}'"
        kind = element.attrib.get('type')
        if kind in ('floating', 'planar'):
            raise self.error(element.line, f"{what} is of type '{kind}', which has more than "
                                           f'one coordinate: not supported (cog_id_ros joints '
                                           f'are revolute, prismatic or loop-closing)')
        if kind not in URDF_JOINT_TYPES:
            raise self.error(element.line, f"{what} has type {show(kind)}; must be one of "
                                           f"{', '.join(URDF_JOINT_TYPES)}")
        mimic = self._mimic(element, what)
        ends = []
        for side in ('parent', 'child'):
            tag = self._one(element, side, what, required=True)
            link = tag.attrib.get('link')
            if not link:
                raise self.error(tag.line, f'<{side}> of {what} has no link attribute')
            ends.append(link)
        xyz, rpy = self._origin(element, what)
        axis, limit = (1.0, 0.0, 0.0), None
        if kind != 'fixed':
            tag = self._one(element, 'axis', what)
            if tag is not None:
                axis = self._numbers(tag, 'xyz', what)
            if not math.hypot(*axis) > 0.0:
                raise self.error(tag.line, f'<axis> of {what} must not be zero-length')
        # urdfdom parses a <limit> whatever the joint's type: so are its numbers checked here
        tag = self._one(element, 'limit', what)
        if tag is not None:
            limit = self._limit(tag, what, kind)
        joint = _Joint(name, element.line, kind, ends[0], ends[1], xyz, rpy, axis, limit)
        joint.mimic = mimic
        return joint

    def _mimic(self, element, what):
        """(leader, multiplier, offset) of a joint's <mimic>, as urdfdom reads it (multiplier
        1 and offset 0 where not written), or None."""
        tag = self._one(element, 'mimic', what)
        if tag is None:
            return None
        leader = tag.attrib.get('joint')
        if not leader:
            raise self.error(tag.line, f'<mimic> of {what} has no joint attribute')
        (multiplier,) = self._numbers(tag, 'multiplier', what, count=1, default=(1.0,),
                                      bound=MAX_COORDINATE)
        (offset,) = self._numbers(tag, 'offset', what, count=1, default=(0.0,),
                                  bound=MAX_COORDINATE, unit='rad or m')
        return leader, multiplier, offset

    def _limit(self, tag, what, kind):
        """``(lower, upper, effort)`` of a joint's <limit>, each None when the joint does not
        use it. Every number written in it (lower, upper, effort, velocity) is read as
        urdfdom reads it, whatever the joint's type, as urdfdom does; then only what the
        mechanism needs is kept: position limits of revolute and prismatic joints, a
        positive effort of a joint that moves. ``velocity`` is checked, never used."""
        # URDF: an attribute left out is 0
        written = {key: self._numbers(tag, key, what, count=1, default=(0.0,))[0]
                   for key in ('lower', 'upper', 'effort', 'velocity')}
        if kind == 'fixed':
            return None
        lower = upper = None
        if kind != 'continuous' and ('lower' in tag.attrib or 'upper' in tag.attrib):
            lower, upper = written['lower'], written['upper']
            if not lower < upper:
                raise self.error(tag.line, f'<limit> of {what}: lower ({lower!r}) must be '
                                           f'below upper ({upper!r}); a joint that cannot move '
                                           f'is a fixed joint')
        effort = None
        if 'effort' in tag.attrib:
            effort = written['effort']
            effort = effort if effort > 0.0 else None    # 0 or less: a placeholder, no limit
        return lower, upper, effort

    def _check_tree(self, root):
        parent_joint = {}
        for joint in self.joints.values():
            for link in (joint.parent, joint.child):
                if link not in self.links:
                    raise self.error(joint.line, f"joint '{joint.name}' refers to link "
                                                 f"'{link}', which the URDF does not have")
            if joint.parent == joint.child:
                raise self.error(joint.line,
                                 f"joint '{joint.name}' has the same parent and child link")
            if joint.child in parent_joint:
                raise self.error(joint.line, f"link '{joint.child}' is the child of joints "
                                             f"'{parent_joint[joint.child].name}' and "
                                             f"'{joint.name}': a URDF is a tree; close loops "
                                             f'with mechanism.loop_closures')
            parent_joint[joint.child] = joint
        roots = [name for name in self.links if name not in parent_joint]
        if len(roots) != 1:
            named = ', '.join(f"'{name}'" for name in roots[:8])
            raise self.error(root.line, f'the links must form one tree with one root; '
                                        f'{len(roots)} links have no parent joint'
                                        + (f': {named}' if roots else ' (a cycle)'))
        self.root = roots[0]
        self.parent_joint = parent_joint
        self.children = {name: [] for name in self.links}
        for joint in self.joints.values():
            self.children[joint.parent].append(joint)
        reached = set(self.walk())
        if len(reached) != len(self.links):
            cycle = [name for name in self.links if name not in reached][:8]
            raise self.error(parent_joint[cycle[0]].line,
                             f"the joints form a cycle through links "
                             f"{', '.join(repr(n) for n in cycle)}: a URDF is a tree; close "
                             f'loops with mechanism.loop_closures')

    def walk(self):
        """Link names, breadth-first from the root."""
        order, k = [self.root], 0
        while k < len(order):
            order.extend(joint.child for joint in self.children[order[k]])
            k += 1
        return order
