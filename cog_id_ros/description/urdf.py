"""A URDF plus loop closures, read into the native mechanism parameters (docs/urdf.md).

URDF describes a tree; a closed-link mechanism is that tree plus the joints that close its
loops. The URDF form of the parameters gives the tree as a URDF (``robot_description``, the
URDF as a string, or ``mechanism.urdf_file``) and the loop-closing joints as
``loop_closures.<name>.*``, listed in ``mechanism.loop_closures``. :func:`native_parameters`
turns that into the native dotted names the core reads (docs/parameter_file.md):
``mechanism.links``, ``mechanism.joints``, ``links.<l>.*``, ``joints.<j>.*`` and a list of
``mechanism.initial_positions``. File formats stay out of :mod:`cog_id_ros.core`:
``cog_id_ros.Mechanism.from_parameters`` (:mod:`.mechanism`) calls this module when it is
handed the URDF form, and hands the core what it returns.

Conventions (URDF's): a joint's ``<origin>`` places the joint frame in the parent link's
frame and the child link's frame is the joint frame; ``<axis>`` is in the joint frame and
defaults to x; ``<inertial>`` gives the mass, the COG and the inertia about the COG in the
frame of its ``<origin>`` (rotated into the link frame here: R I R^T). Fixed joints weld
their two links into one rigid body (mass, COG and inertia combined with the parallel-axis
theorem, in the frame of the link that survives); every joint, closure and base link that
refers to a merged link is re-expressed in the survivor's frame. ``continuous`` joints are
revolute joints without position limits; ``floating`` and ``planar`` joints (more than one
coordinate) are refused naming the joint; ``<mimic>`` couples a joint to another
(core/kinematics/couplings.py: ``joints.<name>.mimic``, ``mimic_multiplier``, ``mimic_offset``).
``<dynamics>``, ``<safety_controller>``, ``<calibration>``, ``<visual>``, ``<collision>``,
``<transmission>``, ``<gazebo>`` and ``<material>`` are ignored.

Every error is a MechanismConfigError naming the parameter (``robot_description``,
``mechanism.urdf_file``, ``loop_closures.<name>.<key>``, ``mechanism.active_joints``, ...);
errors inside the URDF give its line and name the link or joint.
"""
import math

from ..core.errors import MechanismConfigError
from ..core.kinematics import joints
from ..core.kinematics.parameters import ParameterReader, as_float, show
from ..core.model.mechanism import name_problem
from .frames import ZERO
from .loop_closure_file import PARAMETER as LOOP_FILE
from .loop_closure_file import apply_edits, file_closures, read_loop_file
from .loop_closures import read_closures
from .rigid_bodies import mass_properties, merge_fixed, six
from .urdf_tree import Robot
from .urdf_xml import read_source

#: parameters the URDF form consumes (everything else under mechanism.* passes through)
_CONSUMED = ('robot_description', 'mechanism.urdf_file', 'mechanism.loop_closures',
             'mechanism.base_link', 'mechanism.initial_positions', LOOP_FILE)


def is_urdf(params: dict) -> bool:
    """True when ``params`` (dotted names, or a nested dict) is in the URDF form: it holds
    ``robot_description`` or ``mechanism.urdf_file``."""
    if not isinstance(params, dict):
        return False
    if 'robot_description' in params or 'mechanism.urdf_file' in params:
        return True
    nested = params.get('mechanism')
    return isinstance(nested, dict) and 'urdf_file' in nested


def native_parameters(params: dict, base_dir: 'str | dict | None' = None) -> dict:
    """The native dotted-name parameters of the mechanism that ``params`` gives in the URDF
    form (docs/urdf.md).

    ``params`` holds dotted names (as rclpy gives them) or a nested dict; ``base_dir`` is
    where a relative ``mechanism.urdf_file`` or ``mechanism.loop_closure_file`` is looked
    for (the params file's directory; default: the working directory), or a dict of the
    directory for each of them (the node's, whose params files may differ). Every
    ``mechanism.*`` parameter that the URDF form does not define passes through unchanged
    (``name``, ``gravity``, ``active_joints``, ``torque_weights``, the tolerances), and so
    does every parameter outside the mechanism's (a node's own). Raises
    MechanismConfigError naming the parameter."""
    return read(params, base_dir)[0]


def read(params: dict, base_dir: 'str | dict | None' = None) -> tuple:
    """(native parameters, sources): :func:`native_parameters`, and where each of its
    names was written, for :func:`.urdf_messages.for_urdf_user`: the URDF parameter
    (``source``), the URDF line of each joint and link (``lines``) and the loop closures by
    name (``closures``)."""
    if not isinstance(params, dict):
        raise MechanismConfigError('parameters', f'must be a dict, got {type(params).__name__}')
    r = ParameterReader(params)
    flat = r.params
    if 'mechanism.found_at_assembly' in flat:
        raise MechanismConfigError(
            'mechanism.found_at_assembly', 'is not read with a URDF (robot_description or '
                                           'mechanism.urdf_file): leave a joint out of '
                                           'mechanism.initial_positions to have its position '
                                           'found at assembly')
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
    source = read_source(r, _directory(base_dir, 'mechanism.urdf_file'))
    robot = Robot(source)
    loop_file = read_loop_file(r, _directory(base_dir, LOOP_FILE))
    closures = read_closures(r, robot)
    if loop_file is not None:
        # frames as the file names them: links, and joints (each its child link's frame)
        frames = {joint.name: joint.child for joint in robot.joints.values()}
        frames.update({name: name for name in robot.links})
        apply_edits(robot, loop_file)
        taken = {closure.name for closure in closures} | set(robot.joints)
        closures += file_closures(robot, loop_file, frames, taken)
    base = _choose_base(r, robot)
    bodies = merge_fixed(robot, base)
    lines = {name: link.line for name, link in robot.links.items()}
    lines.update({name: joint.line for name, joint in robot.joints.items()})
    sources = {'source': source.parameter, 'lines': lines,
               'closures': {closure.name: closure for closure in closures}}
    return _native(r, robot, closures, base, bodies, loop_file), sources


def _directory(base_dir: 'str | dict | None', parameter: str) -> 'str | None':
    return base_dir.get(parameter) if isinstance(base_dir, dict) else base_dir


def _choose_base(r, robot):
    base = r.string('mechanism.base_link')
    if base is None:
        return robot.root
    if base not in robot.links:
        raise MechanismConfigError(
            'mechanism.base_link', f"'{base}' is not a link of the URDF (its root link is "
                                   f"'{robot.root}', the default base)")
    return base


def _native(r, robot, closures, base, bodies, loop_file):
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
    tree_joints = [joint for joint in robot.joints.values() if not joint.welds]
    for joint in tree_joints:
        _check_name(robot, joint, 'joint')
    out['mechanism.links'] = links
    out['mechanism.joints'] = [j.name for j in tree_joints] + [c.name for c in closures]
    coordinates = [j.name for j in tree_joints if j.joint_kind.has_coordinate] + [
        c.name for c in closures if joints.kind(c.kind).has_coordinate]
    _active(r, robot, closures, loop_file, out)
    given = _initial_positions(r, robot, closures, coordinates)
    out['mechanism.initial_positions'] = [given.get(name, 0.0) for name in coordinates]
    # the joints left out: their positions are found by the assembly (core/model/assembly.py)
    out['mechanism.found_at_assembly'] = [name for name in coordinates if name not in given]
    for name in links:
        mass, com, inertia = mass_properties(bodies, name)
        out[f'links.{name}.mass'] = float(mass)
        out[f'links.{name}.com'] = com
        out[f'links.{name}.inertia'] = six(inertia)
    _floating(out, robot, bodies, base)
    for joint in tree_joints:
        _native_joint(out, bodies, joint.name, joint.joint_kind.name,
                      joint.parent, joint.child, (joint.xyz, joint.rpy, ZERO, ZERO),
                      joint.axis)
        prefix = f'joints.{joint.name}.'
        if joint.mimic is not None:
            leader, multiplier, offset = joint.mimic
            if leader not in robot.joints:
                raise robot.error(joint.line, f"<mimic> of joint '{joint.name}' names "
                                              f"'{leader}', which the URDF does not have")
            out[prefix + 'mimic'] = leader
            out[prefix + 'mimic_multiplier'], out[prefix + 'mimic_offset'] = multiplier, offset
        if joint.limit is not None:
            lower, upper, effort = joint.limit
            if lower is not None:
                out[prefix + 'lower'], out[prefix + 'upper'] = lower, upper
            if effort is not None:
                out[prefix + 'effort'] = effort
    for closure in closures:
        if bodies.body[closure.parent] == bodies.body[closure.child]:
            raise closure.error(
                'child',
                f"links '{closure.parent}' and '{closure.child}' are already rigidly connected "
                f"(fixed joints weld them into one body, '{bodies.body[closure.child]}'): a "
                f'loop closure must join two links that can move relative to each other')
        _native_joint(out, bodies, closure.name, closure.kind, closure.parent, closure.child,
                      closure.offsets, closure.axis)
        if closure.axis2 is not None:
            out[f'joints.{closure.name}.axis2'] = [float(x) for x in closure.axis2]
    return out


def _floating(out, robot, bodies, base):
    """A floating base: the base body's mass properties (every link welded to it), and each
    contact on a welded link moved to its body's frame (the contact stays where it was)."""
    if out.get('mechanism.floating_base') is True:
        mass, com, inertia = mass_properties(bodies, base)
        out[f'links.{base}.mass'] = float(mass)
        out[f'links.{base}.com'] = com
        out[f'links.{base}.inertia'] = six(inertia)
    prefix = 'mechanism.contacts.'
    for key in [k for k in out if k.startswith(prefix) and k.endswith('.link')]:
        link, name = out[key], key[len(prefix):-len('.link')]
        if not isinstance(link, str) or link not in robot.links or bodies.body[link] == link:
            continue
        xyz = out.get(f'{prefix}{name}.xyz', [0.0, 0.0, 0.0])
        rpy = out.get(f'{prefix}{name}.rpy', [0.0, 0.0, 0.0])
        for field, value in (('xyz', xyz), ('rpy', rpy)):
            if not _three_numbers(value):
                raise MechanismConfigError(f'{prefix}{name}.{field}',
                                           f'must be a list of 3 finite numbers, got {value!r}')
        out[key] = bodies.body[link]
        out[f'{prefix}{name}.xyz'], out[f'{prefix}{name}.rpy'] = bodies.attach(link, xyz, rpy)


def _three_numbers(value):
    return isinstance(value, (list, tuple)) and len(value) == 3 and all(
        isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)
        for x in value)


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
    problem = name_problem(item.name)
    if problem:
        raise robot.error(item.line, f'{kind} name {item.name!r} {problem}; rename it in the '
                                     f'URDF')


def _active(r: ParameterReader, robot: Robot, closures: list, loop_file, out: dict) -> None:
    """Check the active joints: ``mechanism.active_joints``, else the file's ``name_mot``
    (then written to ``out``)."""
    active = r.string_list('mechanism.active_joints')
    if active is None and loop_file is not None and not loop_file.motors:
        raise MechanismConfigError(
            'mechanism.active_joints', f'missing: give it, or the actuated joints as name_mot '
                                       f'in {LOOP_FILE} ({loop_file.path})')
    if active is not None or loop_file is None:
        _check_active(active or (), robot, closures,
                      lambda k, message: MechanismConfigError('mechanism.active_joints',
                                                              message))
        return
    _check_active(loop_file.motors, robot, closures,
                  lambda k, message: loop_file.error('name_mot', k, message))
    out['mechanism.active_joints'] = list(loop_file.motors)


def _check_active(active: list, robot: Robot, closures: list, error) -> None:
    kinds = {c.name: c.kind for c in closures}
    for k, name in enumerate(active):
        joint = robot.joints.get(name)
        if joint is not None and joint.welds:
            raise error(k, f"'{name}' is a fixed joint of the URDF (line {joint.line}): it "
                           f'welds two links together and cannot be driven')
        if joint is not None and not joint.joint_kind.has_coordinate:
            raise error(k, f"'{name}' is a {joint.kind} joint (made so by "
                           f'{LOOP_FILE}): spherical joints are passive (only revolute and '
                           f'prismatic joints can be driven)')
        if name in kinds and not joints.kind(kinds[name]).has_coordinate:
            raise error(k, f"'{name}' is a {kinds[name]} loop closure: spherical, universal "
                           f'and fixed joints are passive (only revolute and prismatic joints '
                           f'can be driven)')
        if joint is None and name not in kinds:
            raise error(k, f"'{name}' is neither a joint of the URDF nor in "
                           f'mechanism.loop_closures' + _edited(robot, name))


def _edited(robot: Robot, name: str) -> str:
    """Where a joint name the URDF had went: the two joints of its UJOINT edit."""
    split = robot.renamed.get(name)
    return f" (the UJOINT edit of {LOOP_FILE} made it {' and '.join(split)})" if split else ''


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
            joint = robot.joints.get(name)
            if joint is not None and joint.welds:
                why = f'a fixed joint of the URDF (line {joint.line})'
            elif joint is not None:
                why = f'a {joint.kind} joint (made so by {LOOP_FILE})'
            elif name in kinds:
                why = f'a {kinds[name]} loop closure'
            else:
                why = None
            raise MechanismConfigError(
                key, f"'{name}' is {why}: it has no position" if why else
                     f"'{name}' is neither a revolute or prismatic joint of the URDF nor in "
                     f"mechanism.loop_closures" + _edited(robot, name))
        given[name] = value
    return given
