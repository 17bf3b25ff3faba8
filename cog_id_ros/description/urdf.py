"""A URDF plus loop closures, read into the native mechanism parameters (docs/urdf.md).

URDF describes a tree; a closed-link mechanism is that tree plus the joints that close its
loops. The URDF form of the parameters gives the tree as a URDF (``robot_description``, the
URDF as a string, or ``mechanism.urdf_file``) and the loop-closing joints as
``loop_closures.<name>.*``, listed in ``mechanism.loop_closures``. :func:`native_parameters`
turns that into the native dotted names the core reads (README, "Mechanism parameter file"):
``mechanism.links``, ``mechanism.joints``, ``links.<l>.*``, ``joints.<j>.*`` and a list of
``mechanism.initial_positions``. File formats stay out of :mod:`cog_id_ros.core`; the core
calls this module when it is handed the URDF form.

Conventions (URDF's): a joint's ``<origin>`` places the joint frame in the parent link's
frame and the child link's frame is the joint frame; ``<axis>`` is in the joint frame and
defaults to x; ``<inertial>`` gives the mass, the COG and the inertia about the COG in the
frame of its ``<origin>`` (rotated into the link frame here: R I R^T). Fixed joints weld
their two links into one rigid body (mass, COG and inertia combined with the parallel-axis
theorem, in the frame of the link that survives); every joint, closure and base link that
refers to a merged link is re-expressed in the survivor's frame. ``continuous`` joints are
revolute joints without position limits; ``floating`` and ``planar`` joints (more than one
coordinate) and ``mimic`` (a coupling the core does not model) are refused naming the joint.
``<dynamics>``, ``<safety_controller>``, ``<calibration>``, ``<visual>``, ``<collision>``,
``<transmission>``, ``<gazebo>`` and ``<material>`` are ignored.

Parser: the standard library's expat (``xml.parsers.expat``), not a URDF package. The
URDF subset a mechanism needs (links with ``<inertial>``, joints with ``<origin>``,
``<axis>``, ``<limit>``, ``<mimic>``) is a few dozen lines to read; expat reports the line of
every element, so each error can say where in the URDF it is; and it lets the reader refuse
DOCTYPE and ENTITY declarations outright (no entity expansion, no external entities: a
"billion laughs" URDF is refused at its first line). The PyPI parsers were weighed and left
out: urdf-parser-py (0.0.4, November 2021, a 13 kB sdist needing lxml) and yourdfpy (0.0.60,
January 2026, a 22 kB wheel needing lxml and trimesh[easy], i.e. mesh handling and its
dependencies) would each add pinned dependencies to requirements.txt for what the standard
library does, neither reports line numbers for its semantic errors, and both are lenient in
ways that hide mistakes (missing attributes become defaults). Pinocchio's own URDF parser
(urdfdom) is the independent reference of the tests (test/test_urdf_input.py), never the
runtime reader.

Every error is a MechanismConfigError naming the parameter (``robot_description``,
``mechanism.urdf_file``, ``loop_closures.<name>.<key>``, ``mechanism.active_joints``, ...);
errors inside the URDF give its line and name the link or joint.
"""
import math
import os
import re
import stat
from xml.parsers import expat

import numpy as np

from ..core.errors import MechanismConfigError
from ..core.mechanism import (
    MAX_COORDINATE,
    MAX_INERTIA,
    MAX_LENGTH,
    MAX_MASS,
    NAME_PATTERN,
    bounded,
    inertia_problem,
)
from ..core.parameters import ParameterReader, as_float, show

#: the joint types of ``loop_closures.<name>.type`` (those of the native schema)
CLOSURE_TYPES = ('revolute', 'prismatic', 'spherical', 'universal', 'fixed')
#: the keys of ``loop_closures.<name>.*``
CLOSURE_KEYS = ('type', 'parent', 'child', 'parent_xyz', 'parent_rpy', 'child_xyz',
                'child_rpy', 'axis', 'axis2')
#: URDF joint types read; the others are refused naming the joint
URDF_JOINT_TYPES = ('revolute', 'continuous', 'prismatic', 'fixed')
#: how far from perpendicular (cosine) a universal closure's two axes may be written (as
#: the core allows for a native universal joint)
AXES_PERPENDICULAR = 1e-6
#: largest URDF read (characters or bytes); a mechanism within the core's size limits takes
#: far less, even with its visual and collision elements
MAX_URDF_SIZE = 8 * 1024 * 1024
#: most URDF elements kept while reading (links, joints and the elements inside them that
#: are read); about ten per link
MAX_URDF_ELEMENTS = 200_000

_ZERO = (0.0, 0.0, 0.0)
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
#: parameters the URDF form consumes (everything else under mechanism.* passes through)
_CONSUMED = ('robot_description', 'mechanism.urdf_file', 'mechanism.loop_closures',
             'mechanism.base_link', 'mechanism.initial_positions')
#: which children are read, by the tag of the element they are in (others are skipped
#: whole, e.g. <visual>, <collision>, <gazebo>, <transmission>)
_READ_INSIDE = {'robot': None, 'link': ('inertial',), 'joint': None,
                'inertial': ('origin', 'mass', 'inertia')}


def is_urdf(params: dict) -> bool:
    """True when ``params`` (dotted names, or a nested dict) is in the URDF form: it holds
    ``robot_description`` or ``mechanism.urdf_file``."""
    if not isinstance(params, dict):
        return False
    if 'robot_description' in params or 'mechanism.urdf_file' in params:
        return True
    nested = params.get('mechanism')
    return isinstance(nested, dict) and 'urdf_file' in nested


def native_parameters(params: dict, base_dir: 'str | None' = None) -> dict:
    """The native dotted-name parameters of the mechanism that ``params`` gives in the URDF
    form (docs/urdf.md).

    ``params`` holds dotted names (as rclpy gives them) or a nested dict; ``base_dir`` is
    where a relative ``mechanism.urdf_file`` is looked for (the params file's directory;
    default: the working directory). Every ``mechanism.*`` parameter that the URDF form does
    not define passes through unchanged (``name``, ``gravity``, ``active_joints``,
    ``torque_weights``, the tolerances), and so does every parameter outside the
    mechanism's (a node's own). Raises MechanismConfigError naming the parameter."""
    if not isinstance(params, dict):
        raise MechanismConfigError('parameters', f'must be a dict, got {type(params).__name__}')
    r = ParameterReader(params)
    flat = r.params
    for name in ('mechanism.links', 'mechanism.joints'):
        if name in flat:
            raise MechanismConfigError(
                name, 'must not be given with a URDF (robot_description or '
                      'mechanism.urdf_file): the links and joints come from the URDF, and the '
                      'joints that close loops from mechanism.loop_closures')
    for name in flat:
        if name.startswith(('links.', 'joints.')):
            raise MechanismConfigError(
                name, 'links.* and joints.* are not read with a URDF (robot_description or '
                      "mechanism.urdf_file): give masses and inertias in the URDF's "
                      '<inertial>, joints in the URDF or under loop_closures.<name>')
    source = _read_source(r, base_dir)
    robot = _Robot(source)
    closures = _read_closures(r, robot)
    base = _choose_base(r, robot)
    bodies = _merge_fixed(robot, base)
    return _native(r, robot, closures, base, bodies)


# --- the URDF text ---------------------------------------------------------------------------


class _Source:
    """The URDF's text and how errors in it are named."""

    def __init__(self, parameter, where, data):
        self.parameter = parameter   # robot_description or mechanism.urdf_file
        self.where = where           # '' or the file's path, ahead of 'line N'
        # str (robot_description) or bytes (a file). Whitespace ahead of the XML declaration
        # (a YAML string starting on a new line) is dropped, as XML would refuse it; lines
        # are still counted from the start of what was given
        self.data = data.lstrip()
        skipped = data[:len(data) - len(self.data)]
        self.skipped_lines = skipped.count('\n' if isinstance(data, str) else b'\n')

    def error(self, line, message):
        line += self.skipped_lines
        at = f'{self.where} line {line}' if self.where else f'line {line}'
        return MechanismConfigError(self.parameter, f'{at}: {message}')


def _read_source(r, base_dir):
    has_text, has_file = r.has('robot_description'), r.has('mechanism.urdf_file')
    if has_text and has_file:
        raise MechanismConfigError(
            'mechanism.urdf_file', 'give either robot_description (the URDF as a string) or '
                                   'mechanism.urdf_file, not both')
    if has_text:
        text = r.string('robot_description', required=True)
        if not text.strip():
            raise MechanismConfigError('robot_description', 'is empty; give the URDF text')
        if len(text) > MAX_URDF_SIZE:
            raise MechanismConfigError(
                'robot_description', f'is {len(text)} characters long, more than the supported '
                                     f'{MAX_URDF_SIZE // (1024 * 1024)} MB')
        return _Source('robot_description', '', text)
    if not has_file:
        raise MechanismConfigError('robot_description',
                                   'missing: give the URDF (robot_description) or '
                                   'mechanism.urdf_file')
    given = r.string('mechanism.urdf_file', required=True)
    if not given.strip():
        raise MechanismConfigError('mechanism.urdf_file', 'is empty; give the path of a URDF')
    if '://' in given:
        raise MechanismConfigError(
            'mechanism.urdf_file', f'{given!r}: URIs (package://, file://) are not resolved; '
                                   f'give a path, absolute or relative to the parameter file')
    path = given if os.path.isabs(given) else os.path.join(base_dir or os.getcwd(), given)
    try:
        if not stat.S_ISREG(os.stat(path).st_mode):    # a FIFO would block the reader
            raise MechanismConfigError('mechanism.urdf_file', f'{path} is not a regular file')
        with open(path, 'rb') as stream:
            data = stream.read(MAX_URDF_SIZE + 1)
    except OSError as exc:
        raise MechanismConfigError(
            'mechanism.urdf_file', f'cannot read {path}: {exc.strerror or exc}') from None
    except ValueError as exc:     # a NUL or a lone surrogate: no file can have that name
        raise MechanismConfigError(
            'mechanism.urdf_file', f'cannot read {show(path)}: not a possible file name '
                                   f'({exc})') from None
    if len(data) > MAX_URDF_SIZE:
        raise MechanismConfigError(
            'mechanism.urdf_file', f'{path} is larger than the supported '
                                   f'{MAX_URDF_SIZE // (1024 * 1024)} MB')
    return _Source('mechanism.urdf_file', path, data)


class _Element:
    __slots__ = ('tag', 'attrib', 'children', 'line')

    def __init__(self, tag, attrib, line):
        self.tag, self.attrib, self.children, self.line = tag, attrib, [], line

    def all(self, tag):
        return [child for child in self.children if child.tag == tag]


class _Refused(Exception):
    pass


def _parse_xml(source):
    """The URDF's elements that are read (_READ_INSIDE), with their line numbers.

    DOCTYPE and ENTITY declarations are refused, so no entity is ever expanded or fetched;
    only XML's predefined entities (&amp; and friends) and character references remain."""
    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    found = []
    stack = []           # the open elements; None for those skipped
    count = [0]

    def start(tag, attrib):
        if tag.startswith('xacro:'):
            raise _Refused(f'<{tag}> is a xacro macro: run xacro on the file first and give '
                           f'the URDF it prints')
        parent = stack[-1] if stack else None
        if stack:
            inside = () if parent is None else _READ_INSIDE.get(parent.tag, ())
            if inside is not None and tag not in inside:
                stack.append(None)
                return
        count[0] += 1
        if count[0] > MAX_URDF_ELEMENTS:
            raise _Refused(f'more than {MAX_URDF_ELEMENTS} elements to read; a mechanism '
                           f'within the supported size (docs/mechanism.md) has far fewer')
        element = _Element(tag, attrib, parser.CurrentLineNumber)
        if parent is None:
            found.append(element)
        else:
            parent.children.append(element)
        stack.append(element)

    def end(_tag):
        stack.pop()

    def refuse_doctype(*_args):
        raise _Refused('DOCTYPE declarations are not accepted (they can define entities that '
                       'expand without bound); remove the <!DOCTYPE ...> and write the values '
                       'out')

    def refuse_entity(*_args):
        raise _Refused('ENTITY declarations are not accepted; write the values out')

    parser.StartElementHandler = start
    parser.EndElementHandler = end
    parser.StartDoctypeDeclHandler = refuse_doctype
    parser.EntityDeclHandler = refuse_entity
    _check_encodable(source)
    try:
        parser.Parse(source.data, True)
    except expat.ExpatError as exc:
        raise source.error(exc.lineno, f'not well-formed XML (column {exc.offset + 1}): '
                                       f'{expat.ErrorString(exc.code)}'
                                       f'{_not_utf8(source.data, exc)}') from None
    except _Refused as exc:
        raise source.error(parser.CurrentLineNumber, str(exc)) from None
    return found[0]


def _check_encodable(source):
    """A robot_description string is handed to expat as UTF-8; a lone surrogate (a str made
    from undecodable bytes, or a JSON or YAML "\\ud800" escape) has no UTF-8 form and would
    escape as UnicodeEncodeError. Said here with its line and column instead."""
    text = source.data
    if not isinstance(text, str):
        return
    try:
        text.encode('utf-8')
    except UnicodeEncodeError as exc:
        start = text.rfind('\n', 0, exc.start) + 1
        raise source.error(
            text.count('\n', 0, exc.start) + 1,
            f'not well-formed XML (column {exc.start - start + 1}): '
            f'U+{ord(text[exc.start]):04X} is a lone surrogate, not a character; remove it '
            f'or write the character it stands for') from None


def _not_utf8(data, error):
    """Why a file's bytes did not parse, when it is that they are not UTF-8 (XML's encoding
    unless the file declares another): expat says only "invalid token", on the line of the
    first byte that is not; else ''."""
    if not isinstance(data, bytes) or \
            error.code != expat.errors.codes[expat.errors.XML_ERROR_INVALID_TOKEN]:
        return ''
    try:
        data.decode('utf-8')
    except UnicodeDecodeError as exc:
        if data.count(b'\n', 0, exc.start) + 1 == error.lineno:
            return (f' (byte 0x{data[exc.start]:02x} is not UTF-8: save the file as UTF-8, or '
                    f'declare its encoding in <?xml version="1.0" encoding="..."?>)')
    return ''


# --- the URDF's links and joints -------------------------------------------------------------


class _Link:
    def __init__(self, name, line, mass, com, inertia):
        self.name, self.line = name, line
        self.mass, self.com, self.inertia = mass, com, inertia   # COG in the link frame


class _Joint:
    def __init__(self, name, line, kind, parent, child, xyz, rpy, axis, limit):
        self.name, self.line, self.kind = name, line, kind
        self.parent, self.child = parent, child
        self.xyz, self.rpy, self.axis = xyz, rpy, axis
        self.limit = limit       # (lower or None, upper or None, effort or None) or None


class _Robot:
    """The links and joints of a URDF, checked to form one tree."""

    def __init__(self, source):
        self.source = source
        root = _parse_xml(source)
        if root.tag != 'robot':
            raise source.error(root.line, f"the root element is <{root.tag}>; a URDF's is "
                                          f'<robot>')
        self.name = root.attrib.get('name') or None
        self.links = {}      # name -> _Link, in document order
        self.joints = {}     # name -> _Joint, in document order
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
            return _ZERO, _ZERO
        return (self._numbers(origin, 'xyz', what, default=_ZERO, bound=MAX_LENGTH, unit='m'),
                self._numbers(origin, 'rpy', what, default=_ZERO, bound=MAX_COORDINATE,
                              unit='rad'))

    def _link(self, element):
        name = self._name(element, 'link')
        what = f"link '{name}'"
        inertial = self._one(element, 'inertial', what)
        if inertial is None:         # massless
            return _Link(name, element.line, 0.0, _ZERO, np.zeros((3, 3)))
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
        problem = inertia_problem(_six(inertia))
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
        mimic = self._one(element, 'mimic', what)
        if mimic is not None:
            raise self.error(mimic.line, f'{what} has <mimic>: coupled joints are not '
                                         f'supported (model the coupling as a mechanism, or '
                                         f'drive the joint as an actuator of its own)')
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
            tag = self._one(element, 'limit', what)
            if tag is not None:
                limit = self._limit(tag, what, kind)
        return _Joint(name, element.line, kind, ends[0], ends[1], xyz, rpy, axis, limit)

    def _limit(self, tag, what, kind):
        lower = upper = None
        if kind != 'continuous' and ('lower' in tag.attrib or 'upper' in tag.attrib):
            # URDF: an attribute left out is 0
            (lower,) = self._numbers(tag, 'lower', what, count=1, default=(0.0,))
            (upper,) = self._numbers(tag, 'upper', what, count=1, default=(0.0,))
            if not lower < upper:
                raise self.error(tag.line, f'<limit> of {what}: lower ({lower!r}) must be '
                                           f'below upper ({upper!r}); a joint that cannot move '
                                           f'is a fixed joint')
        effort = None
        if 'effort' in tag.attrib:
            (effort,) = self._numbers(tag, 'effort', what, count=1)
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


# --- loop closures, base link, fixed joints --------------------------------------------------


class _Closure:
    def __init__(self, name, kind, parent, child, offsets, axis, axis2):
        self.name, self.kind, self.parent, self.child = name, kind, parent, child
        self.offsets = offsets           # parent_xyz, parent_rpy, child_xyz, child_rpy
        self.axis, self.axis2 = axis, axis2


def _read_closures(r, robot):
    names = r.string_list('mechanism.loop_closures') or []
    for name in names:
        if not NAME_PATTERN.match(name):
            raise MechanismConfigError(
                'mechanism.loop_closures',
                f"'{name}' is not a valid joint name: names become parts of ROS 2 parameter "
                f"names (loop_closures.<name>.*, joints.<name>.*) and may hold only letters, "
                f"digits and '_', not starting with a digit")
        if name in robot.joints:
            raise MechanismConfigError(
                'mechanism.loop_closures',
                f"'{name}' is already a joint of the URDF (line {robot.joints[name].line}); "
                f'give the loop closure a name of its own')
    listed = set(names)
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
        parts = key.split('.', 2)
        if parts[1] not in listed:
            raise MechanismConfigError(
                key, f"'{parts[1]}' is not in mechanism.loop_closures "
                     f"({', '.join(names) if names else 'none listed'}): list it there, or "
                     f'correct the name')
        if len(parts) < 3 or parts[2] not in CLOSURE_KEYS:
            raise MechanismConfigError(
                key, f"unknown parameter (loop_closures.{parts[1]}.* takes "
                     f"{', '.join(CLOSURE_KEYS)})")
    return [_read_closure(r, robot, name) for name in names]


def _read_closure(r, robot, name):
    prefix = f'loop_closures.{name}.'
    kind = r.string(prefix + 'type', required=True)
    if kind not in CLOSURE_TYPES:
        raise MechanismConfigError(
            prefix + 'type', f"must be one of {', '.join(CLOSURE_TYPES)}, got {show(kind)}")
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
    offsets = tuple(bounded(prefix + key, r.vector(prefix + key, 3, default=_ZERO), bound, unit)
                    for key, bound, unit in (('parent_xyz', MAX_LENGTH, 'm'),
                                             ('parent_rpy', MAX_COORDINATE, 'rad'),
                                             ('child_xyz', MAX_LENGTH, 'm'),
                                             ('child_rpy', MAX_COORDINATE, 'rad')))
    axis = axis2 = None
    if kind in ('revolute', 'prismatic', 'universal'):
        axis = _axis(r, prefix + 'axis', (0.0, 0.0, 1.0))
    elif r.has(prefix + 'axis'):
        raise MechanismConfigError(prefix + 'axis', f'a {kind} closure has no axis; delete it')
    if kind == 'universal':
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
    return _Closure(name, kind, ends[0], ends[1], offsets, axis, axis2)


def _axis(r, name, default):
    axis = r.vector(name, 3, default=default, required=default is None)
    if not math.hypot(*axis) > 0.0:
        raise MechanismConfigError(name, f'must not be zero-length, got {list(axis)}')
    return axis


def _choose_base(r, robot):
    base = r.string('mechanism.base_link')
    if base is None:
        return robot.root
    if base not in robot.links:
        raise MechanismConfigError(
            'mechanism.base_link', f"'{base}' is not a link of the URDF (its root link is "
                                   f"'{robot.root}', the default base)")
    return base


class _Frame:
    """A rigid transform (rotation, translation); ``identity`` when exactly so, which keeps
    values written in the URDF unchanged through the conversion."""

    def __init__(self, rotation=None, translation=None):
        self.identity = rotation is None
        self.rotation = np.eye(3) if rotation is None else rotation
        self.translation = np.zeros(3) if translation is None else translation

    @classmethod
    def of(cls, xyz, rpy):
        return cls(rpy_matrix(rpy), np.array(xyz, dtype=float))

    def __mul__(self, other):
        if self.identity:
            return other
        if other.identity:
            return self
        return _Frame(self.rotation @ other.rotation,
                      self.rotation @ other.translation + self.translation)

    def inverse(self):
        if self.identity:
            return self
        return _Frame(self.rotation.T, -self.rotation.T @ self.translation)


class _Bodies:
    """Rigid bodies after merging fixed joints: for each URDF link the link that survives
    (``body``) and the link's frame in the survivor's (``frame``); for each survivor its
    links (``members``, document order)."""

    def __init__(self, robot, body, frame):
        self.body, self.frame = body, frame
        self.members = {}
        for link in robot.links.values():
            self.members.setdefault(body[link.name], []).append(link)

    def attach(self, link, xyz, rpy):
        """(xyz, rpy) of a frame given in ``link``'s frame, in the frame of its body."""
        frame = self.frame[link]
        if frame.identity:
            return [float(x) for x in xyz], [float(x) for x in rpy]
        placed = frame * _Frame.of(xyz, rpy)      # + 0.0: no -0.0 in what a user reads
        return ([float(x) + 0.0 for x in placed.translation],
                [float(x) + 0.0 for x in rpy_of(placed.rotation)])


def _merge_fixed(robot, base):
    """Each fixed joint welds its child to its parent. A group of links welded together is
    one body named after its top link (the child of a non-fixed joint, or the root), except
    the base link's group, which is named after the base link."""
    body, frame = {}, {}
    for link in robot.walk():
        joint = robot.parent_joint.get(link)
        if joint is None or joint.kind != 'fixed':
            body[link], frame[link] = link, _Frame()
        else:
            body[link] = body[joint.parent]
            frame[link] = frame[joint.parent] * _Frame.of(joint.xyz, joint.rpy)
    top = body[base]
    if top != base:
        to_base = frame[base].inverse()
        for link in robot.links:
            if body[link] == top:
                body[link] = base
                frame[link] = _Frame() if link == base else to_base * frame[link]
    return _Bodies(robot, body, frame)


def _mass_properties(bodies, name):
    """Mass, COG and inertia about the COG of the body ``name``, in its frame."""
    members = bodies.members[name]
    if len(members) == 1:
        link = members[0]
        return link.mass, [float(x) for x in link.com], link.inertia
    placed = []
    for link in members:
        frame = bodies.frame[link.name]
        com = frame.rotation @ np.array(link.com) + frame.translation
        placed.append((link.mass, com, frame.rotation @ link.inertia @ frame.rotation.T))
    mass = sum(m for m, _, _ in placed)
    com = sum(m * c for m, c, _ in placed) / mass if mass > 0.0 else np.zeros(3)
    inertia = np.zeros((3, 3))
    for m, c, tensor in placed:
        d = c - com
        inertia += tensor + m * (np.dot(d, d) * np.eye(3) - np.outer(d, d))
    return mass, [float(x) for x in com], inertia


# --- the native parameters -------------------------------------------------------------------


def _native(r, robot, closures, base, bodies):
    out = {}
    for name, value in r.params.items():
        if name in _CONSUMED or name == 'loop_closures' or name.startswith(
                ('loop_closures.', 'mechanism.initial_positions.')):
            continue
        out[name] = value
    if 'mechanism.name' not in out and robot.name:
        out['mechanism.name'] = robot.name
    out['mechanism.base_link'] = base
    links = [name for name in robot.links if bodies.body[name] == name and name != base]
    if not links:
        raise robot.error(robot.links[base].line,
                          f"the URDF has no link that moves relative to the base link '{base}'")
    for name in links:
        _check_name(robot, robot.links[name], 'link')
    tree_joints = [joint for joint in robot.joints.values() if joint.kind != 'fixed']
    for joint in tree_joints:
        _check_name(robot, joint, 'joint')
    out['mechanism.links'] = links
    out['mechanism.joints'] = [j.name for j in tree_joints] + [c.name for c in closures]
    coordinates = [j.name for j in tree_joints] + [
        c.name for c in closures if c.kind in ('revolute', 'prismatic')]
    _check_active(r, robot, closures)
    out['mechanism.initial_positions'] = _initial_positions(r, robot, closures, coordinates)
    for name in links:
        mass, com, inertia = _mass_properties(bodies, name)
        out[f'links.{name}.mass'] = float(mass)
        out[f'links.{name}.com'] = com
        out[f'links.{name}.inertia'] = _six(inertia)
    for joint in tree_joints:
        _native_joint(out, bodies, joint.name,
                      'revolute' if joint.kind == 'continuous' else joint.kind,
                      joint.parent, joint.child, (joint.xyz, joint.rpy, _ZERO, _ZERO),
                      joint.axis)
        if joint.limit is not None:
            lower, upper, effort = joint.limit
            prefix = f'joints.{joint.name}.'
            if lower is not None:
                out[prefix + 'lower'], out[prefix + 'upper'] = lower, upper
            if effort is not None:
                out[prefix + 'effort'] = effort
    for closure in closures:
        if bodies.body[closure.parent] == bodies.body[closure.child]:
            raise MechanismConfigError(
                f'loop_closures.{closure.name}.child',
                f"links '{closure.parent}' and '{closure.child}' are already rigidly connected "
                f"(fixed joints weld them into one body, '{bodies.body[closure.child]}'): a "
                f'loop closure must join two links that can move relative to each other')
        _native_joint(out, bodies, closure.name, closure.kind, closure.parent, closure.child,
                      closure.offsets, closure.axis)
        if closure.axis2 is not None:
            out[f'joints.{closure.name}.axis2'] = [float(x) for x in closure.axis2]
    return out


def _native_joint(out, bodies, name, kind, parent, child, offsets, axis):
    prefix = f'joints.{name}.'
    parent_xyz, parent_rpy, child_xyz, child_rpy = offsets
    out[prefix + 'type'] = kind
    out[prefix + 'parent'] = bodies.body[parent]
    out[prefix + 'child'] = bodies.body[child]
    out[prefix + 'parent_xyz'], out[prefix + 'parent_rpy'] = bodies.attach(
        parent, parent_xyz, parent_rpy)
    out[prefix + 'child_xyz'], out[prefix + 'child_rpy'] = bodies.attach(
        child, child_xyz, child_rpy)
    if axis is not None:
        out[prefix + 'axis'] = [float(x) for x in axis]


def _check_name(robot, item, kind):
    if NAME_PATTERN.match(item.name):
        return
    raise robot.error(
        item.line, f"{kind} name '{item.name}' may hold only letters, digits and '_', not "
                   f"starting with a digit: names of links and joints become parts of ROS 2 "
                   f"parameter names ({kind}s.<name>.*); rename it in the URDF (links "
                   f"welded to another by a fixed joint, fixed joints and the base link are "
                   f"exempt)")


def _check_active(r, robot, closures):
    active = r.string_list('mechanism.active_joints')
    kinds = {c.name: c.kind for c in closures}
    for name in active or ():
        if name in robot.joints and robot.joints[name].kind == 'fixed':
            raise MechanismConfigError(
                'mechanism.active_joints',
                f"'{name}' is a fixed joint of the URDF (line {robot.joints[name].line}): it "
                f'welds two links together and cannot be driven')
        if kinds.get(name) in ('spherical', 'universal', 'fixed'):
            raise MechanismConfigError(
                'mechanism.active_joints',
                f"'{name}' is a {kinds[name]} loop closure: spherical, universal and fixed "
                f'joints are passive (only revolute and prismatic joints can be driven)')
        if name not in robot.joints and name not in kinds:
            raise MechanismConfigError(
                'mechanism.active_joints',
                f"'{name}' is neither a joint of the URDF nor in mechanism.loop_closures")


def _initial_positions(r, robot, closures, coordinates):
    prefix = 'mechanism.initial_positions'
    if r.has(prefix):
        value = r.params[prefix]
        if isinstance(value, dict):
            raise MechanismConfigError(
                prefix, 'has no entries; give joint: position entries, or delete it for zeros')
        raise MechanismConfigError(
            prefix, f'must map joint names to positions with a URDF (e.g. '
                    f'initial_positions: {{{coordinates[0] if coordinates else "joint"}: 0.5}}), '
                    f'got {show(value)}')
    given = {}
    kinds = {c.name: c.kind for c in closures}
    for key in r.params:
        if not key.startswith(prefix + '.'):
            continue
        name = key[len(prefix) + 1:]
        value = as_float(key, r.raw(key, required=True))
        if name not in coordinates:
            if name in robot.joints:
                why = f'a fixed joint of the URDF (line {robot.joints[name].line})'
            elif name in kinds:
                why = f'a {kinds[name]} loop closure'
            else:
                why = None
            raise MechanismConfigError(
                key, f"'{name}' is {why}: it has no position" if why else
                     f"'{name}' is neither a revolute or prismatic joint of the URDF nor in "
                     f"mechanism.loop_closures")
        given[name] = value
    return [given.get(name, 0.0) for name in coordinates]


def _six(inertia):
    """[ixx, iyy, izz, ixy, ixz, iyz] of a 3x3 inertia (symmetrised)."""
    sym = (inertia + inertia.T) / 2.0
    return [float(sym[0, 0]), float(sym[1, 1]), float(sym[2, 2]), float(sym[0, 1]),
            float(sym[0, 2]), float(sym[1, 2])]


def rpy_matrix(rpy):
    """URDF roll-pitch-yaw: R = Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr = math.cos(rpy[0]), math.sin(rpy[0])
    cp, sp = math.cos(rpy[1]), math.sin(rpy[1])
    cy, sy = math.cos(rpy[2]), math.sin(rpy[2])
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def rpy_of(rotation):
    """Roll, pitch, yaw of a rotation matrix (the inverse of rpy_matrix), also at +-90
    degrees of pitch: roll is taken from what yaw and pitch leave."""
    yaw = math.atan2(rotation[1, 0], rotation[0, 0])
    pitch = math.atan2(-rotation[2, 0], math.hypot(rotation[0, 0], rotation[1, 0]))
    rest = rpy_matrix((0.0, pitch, yaw)).T @ rotation
    roll = math.atan2(rest[2, 1], rest[1, 1])
    return roll, pitch, yaw
