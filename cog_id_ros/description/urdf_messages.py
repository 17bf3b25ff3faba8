"""The core's refusals, said to a user of the URDF form in its own terms (docs/urdf.md).

The core reads the native parameters the URDF reader made (:mod:`.urdf`) and names them in
its errors: ``mechanism.joints``, ``joints.<name>.parent_xyz``, a hint to write
``type: universal``. A URDF user wrote none of these. :func:`for_urdf_user` names what they
did write instead (the URDF parameter and the joint's or link's line, a loop closure's
``loop_closures.<name>.*``, the loop-closure file and its entry) and says what to write
there; anything it does not recognise passes unchanged.
"""
import re

from ..core.errors import MechanismConfigError
from ..core.kinematics import joints
from ..core.kinematics.parameters import split_owner
from ..core.model.assembly import POSE_MARK, PoseRefused, mapping_block

#: native advice -> the same advice for the URDF form (patterns, in the core's words)
_ADVICE = (
    (re.compile(r'check the geometry \(parent_xyz, child_xyz, \*_rpy and axis\)'),
     "check the geometry (each URDF joint's <origin> and <axis>; each loop closure's "
     'parent_xyz, child_xyz, *_rpy and axis, or the frames mechanism.loop_closure_file '
     'pairs)'),
    (re.compile(r'write one of them as `type: universal`(?: \(with `axis` and `axis2` '
                r'perpendicular to the line through the two centres\))?'),
     'make one of them universal: a URDF joint cannot be, but a loop closure can '
     '(loop_closures.<name>.type: universal, its axis and axis2 perpendicular to the line '
     'through the two centres), and so can a URDF joint edited by '
     'mechanism.loop_closure_file (joint_type UJOINT_<A><B>)'),
    (re.compile(r'write it as `type: spherical`'),
     'make it one spherical joint (a spherical loop closure, or joint_type SPHERICAL for '
     'one URDF joint in mechanism.loop_closure_file)'),
    (re.compile(r'write such a ball joint as one `type: spherical` joint'),
     'make such a ball joint one spherical joint (a spherical loop closure, or joint_type '
     'SPHERICAL in mechanism.loop_closure_file)'),
)


def for_urdf_user(error: MechanismConfigError, native: dict, sources: dict
                  ) -> MechanismConfigError:
    """``error`` (the core's, about the native parameters ``native`` that the URDF reader
    made) as a URDF user can act on it. ``sources``: the URDF parameter (``source``), and
    per joint or link name where it was written (``lines``: URDF line numbers;
    ``closures``: the Closure objects, which name their own origin)."""
    prefix = f'{error.parameter}: '
    message = str(error)[len(prefix):] if str(error).startswith(prefix) else str(error)
    if isinstance(error, PoseRefused):      # the pose to paste, as the URDF form writes it
        message = error.template.replace(POSE_MARK, mapping_block(error.pose))
    for pattern, advice in _ADVICE:
        message = pattern.sub(advice, message)
    index = re.search(r' at index (\d+)$', message)
    if error.parameter == 'mechanism.initial_positions' and index:   # a list only natively
        joint = _coordinates(native)[int(index.group(1))]
        return MechanismConfigError(f'mechanism.initial_positions.{joint}',
                                    message[:index.start()].replace('entries must', 'must'))
    parameter, where = _where(error.parameter, native, sources)
    if where:
        message = f'{where}: {message}'
    closure = sources['closures'].get(_owner(error.parameter, native)[0] or '')
    if closure is not None and parameter is None:
        return closure.error(_owner(error.parameter, native)[1], message)
    return MechanismConfigError(parameter or error.parameter, message)


def _coordinates(native: dict) -> list:
    """The joints with a coordinate, in the order of the native initial_positions."""
    return [name for name in native['mechanism.joints']
            if joints.kind(native[f'joints.{name}.type']).has_coordinate]


def _owner(parameter: str, native: dict) -> tuple:
    for group, names in (('joints.', native.get('mechanism.joints', [])),
                         ('links.', native.get('mechanism.links', []))):
        if parameter.startswith(group):
            return split_owner(parameter[len(group):], names)
    return None, None


def _where(parameter: str, native: dict, sources: dict) -> tuple:
    """(parameter to name, or None for a closure's own; what in it, or '')."""
    source = sources['source']
    if parameter == 'mechanism.joints' or parameter == 'mechanism.links':
        return source, ''
    owner, _ = _owner(parameter, native)
    if owner is None:
        return parameter, ''
    if owner in sources['closures']:
        return None, ''
    line = sources['lines'].get(owner)
    what = 'link' if parameter.startswith('links.') else 'joint'
    return source, f"{what} '{owner}'" + (f' (line {line})' if line else '')
