"""The URDF's text (``robot_description`` or ``mechanism.urdf_file``) and its XML elements.

Read defensively: at most MAX_URDF_SIZE characters or bytes, at most MAX_URDF_ELEMENTS
elements kept, only regular files, no DOCTYPE or ENTITY declarations. Every error is a
MechanismConfigError naming the parameter the URDF came from, with its line.

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
(urdfdom) is the independent reference of the tests (test/description/test_urdf.py), never the
runtime reader.
"""
import os
import stat
from xml.parsers import expat

from ..core.errors import MechanismConfigError
from ..core.kinematics.parameters import show

#: largest URDF read (characters or bytes); a mechanism within the core's size limits takes
#: far less, even with its visual and collision elements
MAX_URDF_SIZE = 8 * 1024 * 1024
#: most URDF elements kept while reading (links, joints and the elements inside them that
#: are read); about ten per link
MAX_URDF_ELEMENTS = 200_000
#: which children are read, by the tag of the element they are in (others are skipped
#: whole, e.g. <visual>, <collision>, <gazebo>, <transmission>)
_READ_INSIDE = {'robot': None, 'link': ('inertial',), 'joint': None,
                'inertial': ('origin', 'mass', 'inertia')}


class Source:
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


def read_source(r, base_dir):
    """The URDF the parameters give (read by ``r``, a ParameterReader), as a Source."""
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
        return Source('robot_description', '', text)
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
    return Source('mechanism.urdf_file', path, data)


class _Element:
    __slots__ = ('tag', 'attrib', 'children', 'line')

    def __init__(self, tag, attrib, line):
        self.tag, self.attrib, self.children, self.line = tag, attrib, [], line

    def all(self, tag):
        return [child for child in self.children if child.tag == tag]


class _Refused(Exception):
    pass


def parse_xml(source):
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
