"""The one way the package reads YAML: :func:`load` and :func:`compose`, each after
:func:`check_nesting`, for every YAML text a user gives (parameter files, loop-closure
files, the node's ``-p`` values) and the demos' configs.

PyYAML builds a document's nodes recursively. Its C extension (what ``CSafeLoader`` uses)
has no recursion check: about 20,000 nested collections, which 40 kB of text make (one
line of ``- - - ... x`` or ``? ? ? ... x``, ``[[[...]]]``, indented mappings), overflow
the C stack and kill the process (SIGSEGV, exit status 139); the pure-Python loader
raises RecursionError at a few hundred. Parsing is not the danger: libyaml's parser (and
PyYAML's pure-Python one) keeps its state on the heap and reads any nesting in linear
time, event by event. So before a document is built, :func:`check_nesting` refuses
collections nested more than MAX_DEPTH deep (block and flow, in any mix), with one line
naming the parameter, the file and the line:

1. from the text alone, flow collections: ``[`` and ``{`` counted against ``]`` and ``}``
   (those in strings and comments count too: only absurd text is refused). This also
   spares PyYAML's pure-Python scanner, which takes time quadratic in that depth;
2. then the parse events, counted up to the first collection deeper than MAX_DEPTH (a
   sixth of the time building the document takes; a URDF in a block scalar is one event).
"""
import re

import yaml

from ..core.errors import MechanismConfigError

#: deepest nesting of YAML collections read, block and flow together (a list in a mapping
#: in a mapping is 3 deep); a parameter file's mechanism takes six (the node entry,
#: ros__parameters, links, link1, com, the list of com), a loop-closure file three
MAX_DEPTH = 32
_BRACKETS = re.compile(r'[\[\]{}]')
_LINE_BREAK = re.compile(r'\r\n|[\n\r\x85\u2028\u2029]')

_Loader = getattr(yaml, 'CSafeLoader', yaml.SafeLoader)   # libyaml's parser when built


def check_nesting(text: str, parameter: str, source: object) -> None:
    """MechanismConfigError(``parameter``, ...) naming ``source`` (the file) and a line
    when the YAML ``text`` nests collections more than MAX_DEPTH deep; yaml.YAMLError
    when it is not YAML before that depth (as building the document would raise)."""
    flow = 0
    for match in _BRACKETS.finditer(text):
        if match.group() in '[{':
            flow += 1
            if flow > MAX_DEPTH:
                raise _too_deep(parameter, source, _line(text, match.start()),
                                '[...] or {...}')
        else:
            flow = max(0, flow - 1)
    depth = 0
    for event in yaml.parse(text, Loader=_Loader):
        if isinstance(event, yaml.CollectionStartEvent):
            depth += 1
            if depth > MAX_DEPTH:
                what = ('block entries ("- - - ...")' if isinstance(event, yaml.SequenceStartEvent)
                        and not event.flow_style else 'collections')
                raise _too_deep(parameter, source, event.start_mark.line + 1, what)
        elif isinstance(event, yaml.CollectionEndEvent):
            depth -= 1


def load(text: str, loader: type, parameter: str, source: object) -> object:
    """``yaml.load(text, Loader=loader)`` (``loader``: a safe loader) after
    :func:`check_nesting`; yaml.YAMLError as yaml.load raises it."""
    check_nesting(text, parameter, source)
    return yaml.load(text, Loader=loader)     # noqa: S506 (callers pass safe loaders)


def compose(text: str, parameter: str, source: object) -> object:
    """``yaml.compose(text)``: the node tree, with the lines of its nodes, after
    :func:`check_nesting`."""
    check_nesting(text, parameter, source)
    return yaml.compose(text, Loader=_Loader)


def _line(text: str, index: int) -> int:
    """The line (from 1) of ``text[index]``, YAML's line breaks counted."""
    return len(_LINE_BREAK.findall(text, 0, index)) + 1


def _too_deep(parameter: str, source: object, line: int, what: str) -> MechanismConfigError:
    return MechanismConfigError(
        parameter, f'{source} nests {what} more than {MAX_DEPTH} deep (line {line}); a '
                   f"mechanism's files nest six levels at most")
