"""Reading mechanism parameters from a dict of dotted names (or a nested dict).

The names are the ones rclpy gives a node (``links.link1.mass``); nested mappings are
flattened to them. Files are not read here: the ROS parameter-file reader is
:mod:`cog_id_ros.description.params_file`, which hands this module the same dict.

The typed getters below turn anything a user can write (YAML integers where floats are
meant, tuples, numpy arrays) into plain Python values, and raise MechanismConfigError naming
the parameter for anything else.

Whatever the dict holds, only MechanismConfigError comes out of here: nulls, numbers too
large for a float, recursive or exponentially nested mappings (a "billion laughs" YAML
document) and nesting deeper than ``MAX_DEPTH`` are refused with the parameter's name (or
``source``), in time proportional to the size of the dict. Values are quoted in messages
with a bounded ``show`` so that no message can grow without limit.
"""
import math
import reprlib
from typing import Any, Iterable, Iterator, Literal, Mapping, Sequence, overload

from ..errors import MechanismConfigError

#: most parameters a file or dict may expand to (far above any mechanism within the size
#: limits of mechanism.py); more is refused before anything is built from them
MAX_PARAMETERS = 100_000
#: deepest nesting of mappings (the mechanism's parameters are three levels deep)
MAX_DEPTH = 16
#: most entries of one list value (the longest lists are one entry per joint)
MAX_LIST_LENGTH = 100_000

_SHOW = reprlib.Repr()
_SHOW.maxstring = 60
_SHOW.maxother = 60
_SHOW.maxlevel = 3
_SHOW.maxlist = _SHOW.maxtuple = _SHOW.maxdict = _SHOW.maxset = 8


def show(value: object) -> str:
    """A bounded repr for messages: never expands a huge, nested or recursive value."""
    try:
        return _SHOW.repr(value)
    except Exception:  # noqa: BLE001 -- a value whose repr fails is still shown somehow
        return f'<{type(value).__name__}>'


def flatten(tree: Mapping[str, Any], prefix: str = '',
            source: str = 'parameters') -> dict[str, Any]:
    """{'a': {'b': 1}} -> {'a.b': 1}; dotted keys that are already flat pass through.

    Keys must be strings. A mapping that contains itself (a recursive YAML alias), nesting
    deeper than MAX_DEPTH or more than MAX_PARAMETERS names (aliases nested inside each
    other expand exponentially) raise MechanismConfigError naming ``source`` or the
    parameter, after at most MAX_PARAMETERS steps.
    """
    flat: dict[str, Any] = {}
    stack: list[tuple[Iterator[tuple[Any, Any]], str, int]] = [(iter(tree.items()), prefix, 0)]
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


class ParameterReader:
    """Typed access to a dotted-name dict; every error names the parameter."""

    def __init__(self, params: Mapping[str, Any]) -> None:
        self.params = flatten(params)
        self.used: set[str] = set()

    def has(self, name: str) -> bool:
        return name in self.params

    def raw(self, name: str, default: Any = None, required: bool = False) -> Any:
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

    # the getters' overloads say what their callers know: a value is there when it is
    # required (else MechanismConfigError) or has a default; None only when neither
    @overload
    def string(self, name: str, default: str, required: bool = False) -> str:
        ...

    @overload
    def string(self, name: str, default: None = None, *, required: Literal[True]) -> str:
        ...

    @overload
    def string(self, name: str, default: str | None = None,
               required: bool = False) -> str | None:
        ...

    def string(self, name: str, default: str | None = None, required: bool = False) -> str | None:
        value = self.raw(name, default, required)
        if value is not None and not isinstance(value, str):
            raise MechanismConfigError(name, f'must be a string, got {show(value)}')
        return value

    @overload
    def number(self, name: str, default: float, required: bool = False) -> float:
        ...

    @overload
    def number(self, name: str, default: None = None, *, required: Literal[True]) -> float:
        ...

    @overload
    def number(self, name: str, default: float | None = None,
               required: bool = False) -> float | None:
        ...

    def number(self, name: str, default: float | None = None,
               required: bool = False) -> float | None:
        value = self.raw(name, default, required)
        return None if value is None else as_float(name, value)

    @overload
    def string_list(self, name: str, required: Literal[True]) -> list[str]:
        ...

    @overload
    def string_list(self, name: str, required: bool = False) -> list[str] | None:
        ...

    def string_list(self, name: str, required: bool = False) -> list[str] | None:
        value = self.raw(name, None, required)
        if value is None:
            return None
        if isinstance(value, str) or not _is_sequence(value):
            raise MechanismConfigError(name, f'must be a list of names, got {show(value)}')
        _check_length(name, value)
        names: list[str] = []
        seen: set[str] = set()
        for item in value:
            if not isinstance(item, str) or not item:
                raise MechanismConfigError(
                    name, f'must be a list of names, got {show(item)} in it')
            if item in seen:
                raise MechanismConfigError(name, f"duplicate name '{item}'")
            seen.add(item)
            names.append(item)
        return names

    @overload
    def vector(self, name: str, length: int | None = None, *, default: Iterable[float],
               required: bool = False) -> tuple[float, ...]:
        ...

    @overload
    def vector(self, name: str, length: int | None = None, default: None = None, *,
               required: Literal[True]) -> tuple[float, ...]:
        ...

    @overload
    def vector(self, name: str, length: int | None = None,
               default: Iterable[float] | None = None,
               required: bool = False) -> tuple[float, ...] | None:
        ...

    def vector(self, name: str, length: int | None = None, default: Iterable[float] | None = None,
               required: bool = False) -> tuple[float, ...] | None:
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

    def unused(self, prefix: str) -> list[str]:
        return sorted(k for k in self.params if k.startswith(prefix) and k not in self.used)


def _is_sequence(value: object) -> bool:
    if isinstance(value, (list, tuple)):
        return True
    if isinstance(value, (dict, set, frozenset, bytes, bytearray)):
        return False
    return hasattr(value, '__len__') and hasattr(value, '__iter__')


def _check_length(name: str, value: Any) -> None:
    try:
        length = len(value)
    except Exception:  # noqa: BLE001 -- e.g. a 0-d numpy array
        raise MechanismConfigError(name, f'must be a list, got {show(value)}') from None
    if length > MAX_LIST_LENGTH:
        raise MechanismConfigError(
            name, f'has {length} entries, more than the supported {MAX_LIST_LENGTH}')


def as_float(name: str, value: Any) -> float:
    if isinstance(value, bool) or \
            not isinstance(value, (int, float)) and not _is_number_like(value):
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


def _finite_in_own_type(value: Any) -> bool:
    try:
        import numpy as np
        return bool(np.isfinite(value))
    except (ImportError, TypeError):  # pragma: no cover
        return False


def _is_number_like(value: object) -> bool:
    try:
        import numpy as np
        return isinstance(value, np.number) and not isinstance(value, np.bool_)
    except ImportError:  # pragma: no cover
        return False


def split_owner(rest: str, names: list) -> tuple:
    """(name, key) of ``<name>.<key>``, the rest of a ``links.*`` or ``joints.*`` parameter,
    for the longest of ``names`` it starts with (names may hold '.'); (None, rest) if none."""
    owner = max((n for n in names if rest.startswith(n + '.')), key=len, default=None)
    return (owner, rest[len(owner) + 1:]) if owner is not None else (None, rest)


def massless(mass: float, inertia: Sequence[float]) -> bool:
    return mass == 0.0 and not any(inertia)
