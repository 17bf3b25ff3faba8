"""mechanism.floating_base and mechanism.contacts: a base free in space and the frames where
the world may push on the robot, read and checked at load.

With ``floating_base: true`` the base link (the tree's root) moves: its own mass
(``links.<base_link>.mass``, ``com``, ``inertia``, which a fixed base never needs) enters
the dynamics, and whole-body inverse dynamics (dynamics/floating_base.py) takes the base's
six coordinates beside the actuators'. A contact is a frame fixed to a link (``xyz``,
``rpy`` in the link's frame): ``6d`` takes a wrench there, ``3d`` a force at its origin.
"""
import dataclasses
import math
from typing import Any, Callable

from ..errors import MechanismConfigError
from ..kinematics.kinematics import BASE
from ..linalg import spatial as sp

FLOATING = 'mechanism.floating_base'
CONTACTS = 'mechanism.contacts.'
CONTACT_KEYS = ('link', 'type', 'xyz', 'rpy')
CONTACT_TYPES = {'6d': 6, '3d': 3}
MAX_CONTACTS = 32


@dataclasses.dataclass(frozen=True)
class Contact:
    """A contact frame: on link ``link`` (its index in mechanism.links, BASE for the base
    link), at ``xyz`` with rotation ``rotation`` (row-major 9-tuple) in the link's frame;
    ``size`` 6 (a wrench) or 3 (a force)."""

    name: str
    link_name: str
    link: int
    size: int
    xyz: tuple[float, ...]
    rotation: tuple[float, ...]


def read_floating_base(mech: Any, reader: Any,
                       read_inertial: Callable[[str], tuple[float, Any, Any]]) -> None:
    """Set ``floating_base``, ``base_mass``, ``base_com``, ``base_inertia`` (row-major
    9-tuple) and ``contacts`` (name -> Contact, in the order written) on ``mech`` from the
    parameters. ``read_inertial(prefix)``: a link's (mass, com, inertia), checked as every
    link's are; the base's are read only when it floats (a fixed base never moves)."""
    floating = reader.raw(FLOATING, False)
    if not isinstance(floating, bool):
        raise MechanismConfigError(FLOATING, f'must be true or false, got {floating!r}')
    mech.floating_base = floating
    mass, com, inertia = read_inertial(f'links.{mech.base_link}.') if floating else \
        (0.0, (0.0, 0.0, 0.0), (0.0,) * 9)
    mech.base_mass, mech.base_com, mech.base_inertia = mass, tuple(com), tuple(inertia)
    mech.contacts = _contacts(mech, reader)


def _contacts(mech: Any, reader: Any) -> dict[str, Contact]:
    if reader.has('mechanism.contacts'):        # not a mapping of contacts
        value = reader.raw('mechanism.contacts')
        if value not in ({}, [], ()):
            raise MechanismConfigError(
                'mechanism.contacts', f'must be a mapping, one entry per contact (<name>: '
                                      f'{{link: <link>, type: 6d or 3d, xyz: [x, y, z], rpy: '
                                      f'[r, p, y]}}), got {value!r}')
    names: list[str] = []
    for key in reader.params:
        if key.startswith(CONTACTS):
            name = key[len(CONTACTS):].rsplit('.', 1)[0]
            if name not in names:
                names.append(name)
    if len(names) > MAX_CONTACTS:
        raise MechanismConfigError('mechanism.contacts', f'at most {MAX_CONTACTS} contacts, got '
                                                         f'{len(names)}')
    contacts = {}
    for name in names:
        prefix = CONTACTS + name + '.'
        for key in reader.params:
            if key.startswith(prefix) and key[len(prefix):] not in CONTACT_KEYS:
                raise MechanismConfigError(key, f"unknown parameter (a contact takes "
                                                f"{', '.join(CONTACT_KEYS)})")
        link = reader.string(prefix + 'link', required=True)
        if link == mech.base_link:
            index = BASE
        elif link in mech.links:
            index = mech.links.index(link)
        else:
            raise MechanismConfigError(prefix + 'link', f"'{link}' is not the base link or in "
                                                        f'mechanism.links')
        kind = reader.string(prefix + 'type', default='6d')
        if kind not in CONTACT_TYPES:
            raise MechanismConfigError(prefix + 'type', f"must be '6d' (a wrench) or '3d' (a "
                                                        f'force at a point), got {kind!r}')
        xyz = reader.vector(prefix + 'xyz', 3, default=(0.0, 0.0, 0.0))
        rpy = reader.vector(prefix + 'rpy', 3, default=(0.0, 0.0, 0.0))
        for key, values in (('xyz', xyz), ('rpy', rpy)):
            if not all(math.isfinite(x) and abs(x) <= 1e6 for x in values):
                raise MechanismConfigError(prefix + key, f'must be finite numbers within 1e6, '
                                                         f'got {list(values)}')
        contacts[name] = Contact(name, link, index, CONTACT_TYPES[kind],
                                 tuple(float(x) for x in xyz),
                                 tuple(float(x) for x in sp.rpy_matrix(rpy)))
    if contacts and not mech.floating_base:
        raise MechanismConfigError('mechanism.contacts', 'contacts need mechanism.floating_base: '
                                                         'true (a fixed base takes every load)')
    return contacts
