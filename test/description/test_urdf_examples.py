"""Every native example of config/, written as a URDF plus loop closures, is the same mechanism.

A small exporter (here, test-only) turns a native mechanism into the URDF form of
docs/urdf.md: the URDF tree is the core's spanning tree (``Mechanism.model.edges``), each
link's URDF frame is the child-side attachment frame of its tree joint (URDF's child link
frame IS the joint frame), and every loop-closing joint (``KinematicModel.loops``) becomes a
``loop_closures.<name>`` entry. Everything fixed to a link (COG, inertia, the other joints'
attachments, the closure frames) is re-expressed in the link's new frame; the base keeps its
frame, so gravity passes unchanged.

A tree joint written backwards (its parent is the tree child, ``edge.sign == -1``) moves
its declared child relative to its declared parent by ``M(axis, q)``: with P the tree parent
and C the tree child, ``T_C A M(axis, q) = T_P B`` (A, B its parent- and child-side
attachments), so ``T_C A = T_P B M(axis, -q) = T_P B M(-axis, q)``. The URDF joint from P to
C therefore has its origin at B (in P's new frame), the child frame ``T_C A`` and the axis
negated: its coordinate is ours, with the same sign, limits and initial position.

The URDF form is read back by ``Mechanism.from_parameters`` (cog_id_ros.description.urdf) and must
give the native file's torques along the config's test motion (test/trajectories.py) to
1e-12 of the largest torque, and the same joint positions (mapped by name: the URDF form
lists its joints in document order, then the closures).
"""
import glob
import math
import os
import warnings

from conftest import REPO
import numpy as np
import pytest
import trajectories

from cog_id_ros import AssemblyWarning, InverseDynamics, Mechanism
from cog_id_ros.core.kinematics import kinematics as kin
from cog_id_ros.core.kinematics.kinematics import BASE
from cog_id_ros.core.linalg import spatial as sp
from cog_id_ros.description.frames import rpy_matrix, rpy_of
from cog_id_ros.description.params_file import load_params_file

CONFIG = os.path.join(REPO, 'config')

#: max |tau_urdf - tau_native| / max |tau_native| along the motion
TORQUE_TOLERANCE = 1e-12
#: max |q_urdf - q_native| over every joint coordinate (rad or m)
POSITION_TOLERANCE = 1e-12
#: samples of the test motion; the parallel robots (many links, slow) take fewer
SAMPLES = 40
SLOW_SAMPLES = 20
SLOW = ('stewart', 'delta')


def native_configs(urdf_tree=True):
    """Names of the config/*.yaml files in the native schema (no robot_description, no
    mechanism.urdf_file) whose spanning tree a URDF can hold (``urdf_tree``: revolute and
    prismatic joints only), or else those whose tree holds a universal or spherical joint
    (no URDF joint type: such a robot goes to URDF as its helper-link twin)."""
    names = []
    for path in sorted(glob.glob(os.path.join(CONFIG, '*.yaml'))):
        params = load_params_file(path)
        if 'robot_description' in params or 'mechanism.urdf_file' in params:
            continue
        mech = Mechanism.from_parameters(params)
        # (a universal joint of the tree is two revolute edges of hidden coordinates)
        if all(e.kind.name in ('revolute', 'prismatic') and e.joint < len(mech.joint_specs)
               for e in mech.model.edges) == urdf_tree:
            names.append(os.path.basename(path))
    return names


# --- the exporter ----------------------------------------------------------------------------


def _frame(xyz, rpy):
    """(R, t) of an attachment frame in its link's frame; None for the identity (so values
    that need no re-expression pass through exactly as written)."""
    if not any(xyz) and not any(rpy):
        return None
    return rpy_matrix(rpy), np.array(xyz, dtype=float)


def _express(new, xyz, rpy):
    """(xyz, rpy) of the frame T(xyz, rpy), given in a link's native frame, in the link's new
    frame ``new`` ((R, t) in the native frame; None: the same frame)."""
    if new is None:
        return [float(x) for x in xyz], [float(x) for x in rpy]
    rotation, origin = new
    return (list(rotation.T @ (np.array(xyz, dtype=float) - origin)),
            list(rpy_of(rotation.T @ rpy_matrix(rpy))))


def _numbers(values):
    return ' '.join(repr(float(x)) for x in values)


def export_urdf(params):
    """(URDF text, URDF-form parameters) of the native mechanism ``params`` (dotted names).

    Parameters of the mechanism that the URDF form passes through (name, gravity,
    active_joints, torque_weights, the tolerances) are copied as they are."""
    mech = Mechanism.from_parameters(params)
    model = mech.model
    name_of = dict(enumerate(mech.links))
    name_of[BASE] = mech.base_link
    new = {BASE: None}          # link -> its URDF frame in its native frame (None: the same)
    joints = []
    for edge in model.edges:
        spec = mech.joint_specs[edge.joint]
        inner = (spec.parent_xyz, spec.parent_rpy)      # on edge.parent if written outwards
        outer = (spec.child_xyz, spec.child_rpy)
        axis = spec.kind.axis
        if edge.sign < 0:                               # written towards the base
            inner, outer, axis = outer, inner, tuple(-a for a in axis)
        assert (spec.parent, spec.child) == ((edge.parent, edge.child) if edge.sign > 0 else
                                             (edge.child, edge.parent))
        new[edge.child] = _frame(*outer)
        xyz, rpy = _express(new[edge.parent], *inner)
        j = mech.joints.index(spec.name)
        lower, upper = mech.position_limits[j]
        effort = mech.joint_efforts[j]
        limited = lower > -math.inf or upper < math.inf
        if limited and not (lower > -math.inf and upper < math.inf):
            raise ValueError(f'{spec.name}: a one-sided position limit has no URDF form')
        # URDF: a revolute joint without position limits is continuous; revolute and
        # prismatic joints need a <limit> (urdfdom), one without lower/upper sets none here
        kind = spec.kind.name if spec.kind.name == 'prismatic' or limited else 'continuous'
        limit = ''
        if kind != 'continuous' or effort < math.inf:
            bounds = f'lower="{lower!r}" upper="{upper!r}" ' if limited else ''
            written = effort if effort < math.inf else 0.0      # 0: no effort limit
            limit = f'<limit {bounds}effort="{written!r}" velocity="0.0"/>'
        joints.append(
            f'  <joint name="{spec.name}" type="{kind}">\n'
            f'    <parent link="{name_of[edge.parent]}"/>\n'
            f'    <child link="{name_of[edge.child]}"/>\n'
            f'    <origin xyz="{_numbers(xyz)}" rpy="{_numbers(rpy)}"/>\n'
            f'    <axis xyz="{_numbers(axis)}"/>\n'
            + (f'    {limit}\n' if limit else '') + '  </joint>')
    links = [f'  <link name="{mech.base_link}"/>']
    for k, link in enumerate(mech.links):
        mass, com = mech.link_mass[k], np.array(mech.link_com[k], dtype=float)
        inertia = np.array(mech.link_inertia[k], dtype=float).reshape(3, 3)
        if mass == 0.0 and not inertia.any():
            links.append(f'  <link name="{link}"/>')          # massless
            continue
        if new[k] is not None:
            rotation, origin = new[k]
            com, inertia = rotation.T @ (com - origin), rotation.T @ inertia @ rotation
        ixx, ixy, ixz, iyy, iyz, izz = (float(inertia[a, b]) for a, b in
                                        ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)))
        links.append(
            f'  <link name="{link}">\n'
            f'    <inertial>\n'
            f'      <origin xyz="{_numbers(com)}" rpy="0.0 0.0 0.0"/>\n'
            f'      <mass value="{float(mass)!r}"/>\n'
            f'      <inertia ixx="{ixx!r}" ixy="{ixy!r}" ixz="{ixz!r}" iyy="{iyy!r}" '
            f'iyz="{iyz!r}" izz="{izz!r}"/>\n'
            f'    </inertial>\n'
            f'  </link>')
    urdf = '\n'.join(['<?xml version="1.0"?>', f'<robot name="{mech.name}">', *links, *joints,
                      '</robot>', ''])

    out = {'robot_description': urdf}
    for key, value in params.items():
        if key.startswith('mechanism.') and key not in (
                'mechanism.links', 'mechanism.joints', 'mechanism.initial_positions'):
            out[key] = value
    specs = {spec.name: spec for spec in mech.joint_specs + mech.closure_specs}
    closures = [loop.name for loop in model.loops]
    out['mechanism.loop_closures'] = closures
    for name in closures:
        spec = specs[name]
        prefix = f'loop_closures.{name}.'
        out[prefix + 'type'] = spec.kind.name
        out[prefix + 'parent'] = name_of[spec.parent]
        out[prefix + 'child'] = name_of[spec.child]
        out[prefix + 'parent_xyz'], out[prefix + 'parent_rpy'] = _express(
            new[spec.parent], spec.parent_xyz, spec.parent_rpy)
        out[prefix + 'child_xyz'], out[prefix + 'child_rpy'] = _express(
            new[spec.child], spec.child_xyz, spec.child_rpy)
        if spec.kind.name in ('revolute', 'prismatic', 'universal'):
            out[prefix + 'axis'] = [float(a) for a in spec.kind.axis]
        if spec.kind.name == 'universal':
            out[prefix + 'axis2'] = [float(a) for a in spec.kind.axis2]
    for name, value in zip(mech.joints, mech.initial_positions):
        out[f'mechanism.initial_positions.{name}'] = float(value)
    return urdf, out


# --- the tests -------------------------------------------------------------------------------


def world_inertias(mech, rotations):
    """Each link's inertia about its COG in the base frame, (N, n_links, 3, 3), for the link
    rotations of InverseDynamics.cog_poses."""
    inertia = np.array(mech.link_inertia).reshape(-1, 3, 3)
    return rotations @ inertia @ np.swapaxes(rotations, -1, -2)


def relative_difference(a, b):
    return float(np.abs(a - b).max() / np.abs(b).max())


@pytest.mark.parametrize('config', native_configs())
def test_urdf_form_gives_the_native_torques_and_positions(config):
    params = load_params_file(os.path.join(CONFIG, config))
    urdf, urdf_params = export_urdf(params)
    with warnings.catch_warnings():
        warnings.simplefilter('error', AssemblyWarning)    # the same assembly, no surprises
        native = Mechanism.from_parameters(params)
        converted = Mechanism.from_parameters(urdf_params)
    # the same mechanism, the joints in the URDF form's order (document order, then closures)
    tree = [native.joint_specs[e.joint] for e in native.model.edges]
    closures = [lp.name for lp in native.model.loops]
    assert converted.joints == [s.name for s in tree] + [
        c for c in closures if c in native.joints]
    assert sorted(converted.joints) == sorted(native.joints)
    assert sorted(converted.closure_joints) == sorted(native.closure_joints)
    assert converted.active_joints == native.active_joints
    assert converted.dof == native.dof
    assert list(converted.gravity) == list(native.gravity)
    assert list(converted.torque_weights) == list(native.torque_weights)
    # a tree joint written backwards keeps its coordinate: the URDF joint's axis is negated
    backwards = [native.joint_specs[e.joint].name for e in native.model.edges if e.sign < 0]
    for name in backwards:
        assert f'<joint name="{name}"' in urdf

    n = SLOW_SAMPLES if config.startswith(SLOW) else SAMPLES
    _, q, qd, qdd = trajectories.sample(config, n)
    tau_native = InverseDynamics(native, backend='python').torques(q, qd, qdd)
    tau_urdf = InverseDynamics(converted, backend='python').torques(q, qd, qdd)
    assert np.abs(tau_native).max() > 0.0
    assert relative_difference(tau_urdf, tau_native) <= TORQUE_TOLERANCE

    solvers = [InverseDynamics(m, backend='python') for m in (native, converted)]
    at_native, at_urdf = (solver.solve_positions(q) for solver in solvers)
    order = [converted.joints.index(name) for name in native.joints]
    assert np.abs(at_urdf[:, order] - at_native).max() <= POSITION_TOLERANCE

    # the bodies: each link's COG and its inertia in the base frame, by link name
    (cog_native, rot_native), (cog_urdf, rot_urdf) = (solver.cog_poses(q) for solver in solvers)
    links = [converted.links.index(name) for name in native.links]
    assert np.abs(cog_urdf[:, links] - cog_native).max() <= POSITION_TOLERANCE
    inertia_native = world_inertias(native, rot_native)
    inertia_urdf = world_inertias(converted, rot_urdf)[:, links]
    assert (np.abs(inertia_urdf - inertia_native).max()
            <= TORQUE_TOLERANCE * np.abs(inertia_native).max())


def test_every_native_example_is_exported():
    """The parametrisation above covers every native config (none is left out quietly)."""
    names = native_configs()
    assert len(names) >= 9
    assert 'crank_rocker_urdf.yaml' not in names
    for name in names:
        assert name in trajectories.TRAJECTORIES, f'{name} has no test motion'
    # the others have a helper-link twin that is exported (the same mechanism)
    # (the parallel ankle's rods hang on universal joints of its tree, with no twin: its
    # transmission is checked against its own geometry, test/core/test_transmission.py)
    others = set(native_configs(urdf_tree=False)) - {'parallel_ankle.yaml'}
    assert others <= set(trajectories.TWINS), others
    assert {trajectories.TWINS[name] for name in others} <= set(names)


@pytest.mark.parametrize('config', native_configs())
def test_urdfdom_reads_the_exported_urdf_as_the_same_bodies(config):
    """Independent of cog_id_ros.description.urdf: Pinocchio's URDF parser (urdfdom) reads the
    exported tree; at the native solver's joint positions every link with mass has the
    native COG and inertia in the base frame, and every loop closure's two frames meet."""
    pin = pytest.importorskip('pinocchio')
    params = load_params_file(os.path.join(CONFIG, config))
    urdf, urdf_params = export_urdf(params)
    native = Mechanism.from_parameters(params)
    model = pin.buildModelFromXML(urdf)
    data = model.createData()
    solver = InverseDynamics(native, backend='python')
    _, q, _, _ = trajectories.sample(config, 5)
    positions = solver.solve_positions(q)
    solver.reset()
    cogs, rotations = solver.cog_poses(q)
    inertias = world_inertias(native, rotations)
    body = {name: model.frames[model.getFrameId(name, pin.FrameType.BODY)].parentJoint
            for name in [native.base_link] + native.links}
    closures = urdf_params['mechanism.loop_closures']
    specs = {spec.name: spec for spec in native.joint_specs + native.closure_specs}
    for k in range(len(q)):
        pq = np.zeros(model.nq)
        for j, name in enumerate(native.joints):
            if name in closures:
                continue
            jm = model.joints[model.getJointId(name)]
            if jm.nq == 2:       # continuous: (cos, sin)
                pq[jm.idx_q:jm.idx_q + 2] = math.cos(positions[k, j]), math.sin(positions[k, j])
            else:
                pq[jm.idx_q] = positions[k, j]
        pin.forwardKinematics(model, data, pq)
        for i, name in enumerate(native.links):
            if native.link_mass[i] == 0.0:
                continue
            placement, inertia = data.oMi[body[name]], model.inertias[body[name]]
            np.testing.assert_allclose(placement.act(inertia.lever), cogs[k, i],
                                       rtol=0.0, atol=POSITION_TOLERANCE)
            rotation = placement.rotation
            np.testing.assert_allclose(rotation @ inertia.inertia @ rotation.T, inertias[k, i],
                                       rtol=0.0, atol=TORQUE_TOLERANCE * np.abs(inertias).max())
        frames = kin.forward_kinematics(native.model, list(positions[k]), sp.ScalarOps)
        for name in closures:
            spec = specs[name]
            for side, link, xyz, rpy in (
                    ('parent', spec.parent, spec.parent_xyz, spec.parent_rpy),
                    ('child', spec.child, spec.child_xyz, spec.child_rpy)):
                rotation, origin = kin.to_base(frames, link, sp.rpy_matrix(rpy), xyz)
                prefix = f'loop_closures.{name}.{side}'
                placed = data.oMi[body[urdf_params[prefix]]] * pin.SE3(
                    rpy_matrix(urdf_params[prefix + '_rpy']),
                    np.array(urdf_params[prefix + '_xyz']))
                np.testing.assert_allclose(placed.translation, origin,
                                           rtol=0.0, atol=POSITION_TOLERANCE)
                np.testing.assert_allclose(placed.rotation, np.reshape(rotation, (3, 3)),
                                           rtol=0.0, atol=POSITION_TOLERANCE)
