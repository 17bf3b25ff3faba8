"""A URDF plus loop closures as mechanism parameters (cog_id_ros.description.urdf,
docs/urdf.md).

The references are independent of the converter: Pinocchio's own URDF parser (urdfdom) and
RNEA for open chains read from the same URDF text; for closed loops, the same mechanism
written by hand in the native schema, and Pinocchio's tree of config/crank_rocker.urdf with
the principle of virtual work (the loop's constraint forces do no work along the motion).
"""
import math
import os

from conftest import REPO
import numpy as np
import pytest

import cog_id_ros
from cog_id_ros import Mechanism, MechanismConfigError
from cog_id_ros.description.frames import rpy_matrix, rpy_of
from cog_id_ros.description.params_file import load_params_file
from cog_id_ros.description.urdf import is_urdf, native_parameters

CONFIG = os.path.join(REPO, 'config')

INERTIA = 'ixx="{}" ixy="{}" ixz="{}" iyy="{}" iyz="{}" izz="{}"'


def inertial(mass, xyz='0 0 0', rpy='0 0 0', ixx=0.01, iyy=0.02, izz=0.015, ixy=0.0, ixz=0.0,
             iyz=0.0):
    return (f'<inertial><origin xyz="{xyz}" rpy="{rpy}"/><mass value="{mass}"/>'
            f'<inertia {INERTIA.format(ixx, ixy, ixz, iyy, iyz, izz)}/></inertial>')


def joint(name, kind, parent, child, xyz='0 0 0', rpy='0 0 0', axis=None, limit=None,
          extra=''):
    axis = '' if axis is None else f'<axis xyz="{axis}"/>'
    limit = '' if limit is None else f'<limit {limit} velocity="1.0"/>'
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{xyz}" rpy="{rpy}"/>{axis}{limit}{extra}'
            f'</joint>')


# --- open chains against Pinocchio -----------------------------------------------------------

#: a serial arm with a branch, rotated inertial frames with products of inertia, fixed joints
#: (into the root, into moving links, a chain of two, a massless link), joints whose parent is
#: a merged link, an unaligned axis and one left to URDF's default (x)
ARM = '\n'.join([
    '<robot name="arm">',
    '<link name="world"/>',
    '<link name="pedestal">' + inertial(4.0, '0.01 0.02 0.1', '0.1 0.2 0.3', 0.05, 0.06, 0.04,
                                        0.002, -0.001, 0.003) + '</link>',
    joint('pedestal_mount', 'fixed', 'world', 'pedestal', '0.1 -0.2 0.05', '0 0 0.5'),
    '<link name="shoulder">' + inertial(2.5, '0.02 -0.01 0.08', '0.3 -0.2 0.1', 0.02, 0.025,
                                        0.015, 0.001, 0.0005, -0.002) + '</link>',
    joint('j1', 'revolute', 'pedestal', 'shoulder', '0 0 0.3', '0.05 -0.1 0.2', '0 0 1',
          'lower="-3" upper="3" effort="50"'),
    '<link name="upper_arm">' + inertial(1.8, '0.2 0.01 0', '-0.4 0.25 0.9', 0.004, 0.03,
                                         0.031, 0.0003, 0.0, 0.0002) + '</link>',
    joint('j2', 'revolute', 'shoulder', 'upper_arm', '0.05 0.1 0.2', '1.5707963267948966 0 0',
          None, 'lower="-2.5" upper="2.5" effort="40"'),
    '<link name="elbow_motor">' + inertial(1.2, '0.01 0 -0.02', '0.7 0.1 -0.3', 0.002, 0.0015,
                                           0.001, 0.0001, -0.0002, 0.0) + '</link>',
    joint('motor_mount', 'fixed', 'upper_arm', 'elbow_motor', '0.4 0 0.02', '0.3 0.4 -0.5'),
    '<link name="elbow_flange"/>',
    joint('flange_mount', 'fixed', 'elbow_motor', 'elbow_flange', '0 0.03 0', '0 -0.7 0'),
    '<link name="forearm">' + inertial(1.1, '0.15 0 0.01', '0.2 -0.3 0.5', 0.002, 0.012, 0.013,
                                       0.0, 0.0004, 0.0) + '</link>',
    joint('j3', 'revolute', 'elbow_flange', 'forearm', '0.02 0 0.05', '0.2 0.1 0',
          '0.6 0 0.8', 'lower="-2" upper="2" effort="0"'),
    '<link name="wrist">' + inertial(0.4, '0 0.02 0.03', '0 0 0', 0.0004, 0.0005, 0.0003)
    + '</link>',
    joint('j4', 'revolute', 'forearm', 'wrist', '0.3 0 0', '-0.3 0.2 0.1', '0 1 0',
          'lower="-2" upper="2" effort="10"'),
    '<link name="tool">' + inertial(0.7, '0 0 0.05', '0.5 0.5 0.5', 0.001, 0.002, 0.0012,
                                    0.0001, 0.0001, -0.0001) + '</link>',
    joint('tool_mount', 'fixed', 'wrist', 'tool', '0 0 0.06', '0.1 0 -0.2'),
    '<link name="counterweight">' + inertial(3.0, '-0.1 0 0', '0 0.3 0', 0.003, 0.004, 0.005)
    + '</link>',
    joint('j5', 'revolute', 'shoulder', 'counterweight', '-0.05 0 0.1', '0 0 0', '1 0 0',
          'lower="-1" upper="1" effort="5"'),
    '</robot>'])

#: continuous and prismatic joints, axes not of unit length, one axis left to the default
SLIDES = '\n'.join([
    '<robot name="slides">',
    '<link name="base">' + inertial(10.0) + '</link>',
    '<link name="table">' + inertial(3.0, '0.1 0.05 0.02', '0.2 0 0.4', 0.1, 0.12, 0.2, 0.01)
    + '</link>',
    joint('turntable', 'continuous', 'base', 'table', '0 0 0.1', '0 0 0', '0 0 1',
          'effort="30"'),
    '<link name="carriage">' + inertial(1.5, '0 0.03 0', '0.1 0.2 0.3', 0.01, 0.02, 0.03)
    + '</link>',
    joint('lift', 'prismatic', 'table', 'carriage', '0.3 0 0.05', '0 0.2 0', '0 0 2',
          'lower="-0.5" upper="0.5" effort="200"'),
    '<link name="rotor">' + inertial(0.8, '0.01 0 0.02', '-0.3 0.1 0.6', 0.003, 0.004, 0.002,
                                     0.0002, 0.0001, 0.0003) + '</link>',
    joint('spindle', 'continuous', 'carriage', 'rotor', '0 0.1 0', '0.4 0 0', '1 1 0'),
    '<link name="slider">' + inertial(0.5, '0.05 0 0', '0 0 0.2', 0.001, 0.002, 0.002)
    + '</link>',
    joint('slide', 'prismatic', 'rotor', 'slider', '0.05 0.02 0', '0 0 0.3', None,
          'lower="-0.2" upper="0.2" effort="0"'),
    '</robot>'])


def pinocchio_torques(urdf, names, q, qd, qdd, gravity):
    """Pinocchio's RNEA for the URDF, joints in the order ``names``."""
    pin = pytest.importorskip('pinocchio')
    model = pin.buildModelFromXML(urdf)
    model.gravity.linear = np.array(gravity, dtype=float)
    data = model.createData()
    out = np.empty_like(q)
    for k in range(len(q)):
        pq, pv, pa = np.zeros(model.nq), np.zeros(model.nv), np.zeros(model.nv)
        for j, name in enumerate(names):
            jm = model.joints[model.getJointId(name)]
            if jm.nq == 2:       # continuous: (cos, sin)
                pq[jm.idx_q:jm.idx_q + 2] = math.cos(q[k, j]), math.sin(q[k, j])
            else:
                pq[jm.idx_q] = q[k, j]
            pv[jm.idx_v], pa[jm.idx_v] = qd[k, j], qdd[k, j]
        tau = pin.rnea(model, data, pq, pv, pa)
        out[k] = [tau[model.joints[model.getJointId(name)].idx_v] for name in names]
    return out


def random_states(native, n, seed):
    """n random (q, qd, qdd) of every joint: q within 0.9 of the position limits, or +-2."""
    rng = np.random.default_rng(seed)
    names = native['mechanism.joints']
    low = np.array([native.get(f'joints.{name}.lower', -2.0) for name in names])
    high = np.array([native.get(f'joints.{name}.upper', 2.0) for name in names])
    middle, half = (high + low) / 2, 0.9 * (high - low) / 2
    shape = (n, len(names))
    return (middle + half * rng.uniform(-1.0, 1.0, shape), rng.normal(0.0, 1.5, shape),
            rng.normal(0.0, 3.0, shape))


def all_active(urdf, gravity, **extra):
    """The native parameters of an open chain with every joint active, and its joints."""
    params = {'robot_description': urdf, 'mechanism.gravity': list(gravity), **extra}
    joints = native_parameters(params)['mechanism.joints']
    return native_parameters({**params, 'mechanism.active_joints': joints}), joints


@pytest.mark.parametrize('urdf, gravity, seed', [
    (ARM, (0.4, -0.3, -9.81), 1),
    (SLIDES, (0.0, 0.0, -9.81), 2),
])
def test_open_chains_match_pinocchio(urdf, gravity, seed):
    native, names = all_active(urdf, gravity)
    solver = cog_id_ros.InverseDynamics(Mechanism.from_parameters(native))
    q, qd, qdd = random_states(native, 12, seed)
    ours = solver.torques(q, qd, qdd)
    ref = pinocchio_torques(urdf, names, q, qd, qdd, gravity)
    scale = np.abs(ref).max()
    assert scale > 1.0
    np.testing.assert_allclose(ours, ref, rtol=1e-10, atol=1e-10 * scale)
    for k in (0, 5):       # one sample at a time too
        np.testing.assert_allclose(solver.sample_torques(list(q[k]), list(qd[k]), list(qdd[k])),
                                   ref[k], rtol=1e-10, atol=1e-10 * scale)


def test_base_link_may_be_a_link_welded_to_the_root():
    """mechanism.base_link names the pedestal (welded to the root 'world'): the base body is
    named after it and its frame, in which gravity is given, is the pedestal's."""
    g_pedestal = np.array([0.5, 0.2, -9.81])
    native, names = all_active(ARM, g_pedestal, **{'mechanism.base_link': 'pedestal'})
    assert native['mechanism.base_link'] == 'pedestal'
    assert 'world' not in native['mechanism.links']
    assert native['joints.j1.parent'] == 'pedestal'
    assert native['joints.j1.parent_rpy'] == [0.05, -0.1, 0.2]     # unchanged
    solver = cog_id_ros.InverseDynamics(Mechanism.from_parameters(native))
    q, qd, qdd = random_states(native, 6, 3)
    g_world = rpy_matrix((0.0, 0.0, 0.5)) @ g_pedestal
    ref = pinocchio_torques(ARM, names, q, qd, qdd, g_world)
    np.testing.assert_allclose(solver.torques(q, qd, qdd), ref, rtol=1e-10,
                               atol=1e-10 * np.abs(ref).max())


def test_arm_conversion_details():
    native, names = all_active(ARM, (0.0, 0.0, -9.81))
    assert names == ['j1', 'j2', 'j3', 'j4', 'j5']          # document order, fixed ones out
    assert native['mechanism.name'] == 'arm'
    assert native['mechanism.base_link'] == 'world'          # the root
    # merged links are gone; elbow_motor and elbow_flange are part of upper_arm
    assert native['mechanism.links'] == ['shoulder', 'upper_arm', 'forearm', 'wrist',
                                         'counterweight']
    assert native['joints.j3.parent'] == 'upper_arm'
    assert native['joints.j2.axis'] == [1.0, 0.0, 0.0]       # URDF's default axis is x
    assert native['joints.j1.parent'] == 'world'
    # limits: lower/upper as written, effort only when positive
    assert (native['joints.j1.lower'], native['joints.j1.upper'],
            native['joints.j1.effort']) == (-3.0, 3.0, 50.0)
    assert 'joints.j3.effort' not in native and native['joints.j3.lower'] == -2.0
    assert native['mechanism.initial_positions'] == [0.0] * 5
    # the merged upper arm: mass and COG of the three links
    assert native['links.upper_arm.mass'] == pytest.approx(1.8 + 1.2)


def test_continuous_and_prismatic_conversion_details():
    native, names = all_active(SLIDES, (0.0, 0.0, -9.81))
    assert names == ['turntable', 'lift', 'spindle', 'slide']
    assert native['joints.turntable.type'] == 'revolute'       # continuous
    assert 'joints.turntable.lower' not in native and 'joints.turntable.upper' not in native
    assert native['joints.turntable.effort'] == 30.0
    assert 'joints.spindle.effort' not in native               # no <limit>
    assert native['joints.lift.type'] == 'prismatic'
    assert (native['joints.lift.lower'], native['joints.lift.upper']) == (-0.5, 0.5)
    assert native['joints.slide.axis'] == [1.0, 0.0, 0.0]
    assert 'joints.slide.effort' not in native                 # effort 0: no limit
    negative = SLIDES.replace('effort="0"', 'effort="-1"')
    assert 'joints.slide.effort' not in native_parameters({'robot_description': negative})
    assert native['joints.lift.child_xyz'] == [0.0, 0.0, 0.0]
    assert native['mechanism.base_link'] == 'base' and 'base' not in native['mechanism.links']


def test_rpy_round_trip_including_gimbal_lock():
    rng = np.random.default_rng(7)
    cases = [tuple(rng.uniform(-3, 3, 3)) for _ in range(50)]
    cases += [(0.3, math.pi / 2, -0.4), (1.0, -math.pi / 2, 2.0), (0.0, 0.0, math.pi)]
    for rpy in cases:
        rotation = rpy_matrix(rpy)
        np.testing.assert_allclose(rpy_matrix(rpy_of(rotation)), rotation, atol=1e-14)


# --- closed loops ----------------------------------------------------------------------------

#: a crank-rocker four-bar in the x-y plane, gravity along -y: the URDF tree, the closure
#: rocker tip - coupler end, and the same mechanism written by hand in the native schema
FOUR_BAR_LINKS = {
    'crank': (0.5, (0.05, 0.01, 0.0), (1e-4, 8e-4, 8.5e-4, 1e-5, 0.0, 0.0)),
    'coupler': (1.2, (0.175, 0.0, 0.01), (2e-4, 1.2e-2, 1.21e-2, 0.0, 3e-5, 0.0)),
    'rocker': (0.9, (0.15, -0.005, 0.0), (1.5e-4, 7e-3, 7.1e-3, 0.0, 0.0, 2e-5)),
}


def four_bar_urdf(tip=False):
    """With ``tip``, the coupler carries a massless link 'coupler_tip' at its far end (a fixed
    joint, rotated), to which the closure is attached instead."""
    body = ['<robot name="four_bar">', '<link name="ground"/>']
    for name, (mass, com, (ixx, iyy, izz, ixy, ixz, iyz)) in FOUR_BAR_LINKS.items():
        body.append(f'<link name="{name}">' + inertial(
            mass, ' '.join(map(str, com)), '0 0 0', ixx, iyy, izz, ixy, ixz, iyz) + '</link>')
    body += [joint('crank_joint', 'continuous', 'ground', 'crank', axis='0 0 1'),
             joint('coupler_joint', 'revolute', 'crank', 'coupler', '0.1 0 0', axis='0 0 1',
                   limit='lower="-6" upper="6" effort="0"'),
             joint('rocker_joint', 'revolute', 'ground', 'rocker', '0.4 0 0', axis='0 0 1',
                   limit='lower="-6" upper="6" effort="0"')]
    if tip:
        body += ['<link name="coupler_tip"/>',
                 joint('tip_mount', 'fixed', 'coupler', 'coupler_tip', '0.35 0 0',
                       '0.3 -0.2 1.1')]
    body.append('</robot>')
    return '\n'.join(body)


def four_bar_urdf_params(tip=False):
    closure = {'type': 'revolute', 'parent': 'rocker', 'child': 'coupler',
               'parent_xyz': [0.3, 0.0, 0.0], 'child_xyz': [0.35, 0.0, 0.0],
               'axis': [0.0, 0.0, 1.0]}
    if tip:        # the same pin, in the tip's frame: its axis is the coupler's z there
        closure['child'] = 'coupler_tip'
        closure['child_xyz'] = [0.0, 0.0, 0.0]
        closure['child_rpy'] = list(rpy_of(rpy_matrix((0.3, -0.2, 1.1)).T))
    return {
        'robot_description': four_bar_urdf(tip),
        'mechanism': {
            'gravity': [0.0, -9.81, 0.0],
            'active_joints': ['crank_joint'],
            'loop_closures': ['closing_joint'],
            'initial_positions': {'crank_joint': 1.2, 'coupler_joint': -0.6,
                                  'rocker_joint': 1.82, 'closing_joint': -1.22},
            'torque_weights': [1.0],
            'closure_tolerance': 1e-11,
        },
        'loop_closures': {'closing_joint': closure},
    }


def four_bar_native():
    links = {name: {'mass': mass, 'com': list(com), 'inertia': list(inertia)}
             for name, (mass, com, inertia) in FOUR_BAR_LINKS.items()}
    z = [0.0, 0.0, 1.0]
    return {
        'mechanism': {
            'name': 'four_bar', 'gravity': [0.0, -9.81, 0.0], 'base_link': 'ground',
            'links': ['crank', 'coupler', 'rocker'],
            'joints': ['crank_joint', 'coupler_joint', 'rocker_joint', 'closing_joint'],
            'active_joints': ['crank_joint'],
            'initial_positions': [1.2, -0.6, 1.82, -1.22],
            'torque_weights': [1.0], 'closure_tolerance': 1e-11,
        },
        'links': links,
        'joints': {
            'crank_joint': {'type': 'revolute', 'parent': 'ground', 'child': 'crank',
                            'axis': z},
            'coupler_joint': {'type': 'revolute', 'parent': 'crank', 'child': 'coupler',
                              'parent_xyz': [0.1, 0.0, 0.0], 'axis': z},
            'rocker_joint': {'type': 'revolute', 'parent': 'ground', 'child': 'rocker',
                             'parent_xyz': [0.4, 0.0, 0.0], 'axis': z},
            'closing_joint': {'type': 'revolute', 'parent': 'rocker', 'child': 'coupler',
                              'parent_xyz': [0.3, 0.0, 0.0], 'child_xyz': [0.35, 0.0, 0.0],
                              'axis': z},
        },
    }


def crank_motion(n=60):
    t = np.linspace(0.0, 2.0, n)
    theta = 1.2 + 2.5 * t + 0.4 * np.sin(np.pi * t)
    theta_d = 2.5 + 0.4 * np.pi * np.cos(np.pi * t)
    theta_dd = -0.4 * np.pi ** 2 * np.sin(np.pi * t)
    return theta[:, None], theta_d[:, None], theta_dd[:, None]


@pytest.mark.parametrize('tip', [False, True], ids=['closure_on_coupler', 'closure_on_tip'])
def test_four_bar_matches_native(tip):
    urdf_mech = Mechanism.from_parameters(native_parameters(four_bar_urdf_params(tip)))
    native_mech = Mechanism.from_parameters(four_bar_native())
    assert urdf_mech.joints == native_mech.joints
    assert urdf_mech.dof == 1
    motion = crank_motion()
    ours = cog_id_ros.InverseDynamics(urdf_mech).torques(*motion)
    ref = cog_id_ros.InverseDynamics(native_mech).torques(*motion)
    assert np.abs(ref).max() > 0.5
    np.testing.assert_allclose(ours, ref, rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_four_bar_emits_the_native_dict():
    native = native_parameters(four_bar_urdf_params())
    assert native['mechanism.joints'] == ['crank_joint', 'coupler_joint', 'rocker_joint',
                                          'closing_joint']
    assert native['mechanism.initial_positions'] == [1.2, -0.6, 1.82, -1.22]
    assert native['mechanism.torque_weights'] == [1.0]          # passed through
    assert native['mechanism.closure_tolerance'] == 1e-11
    assert native['mechanism.name'] == 'four_bar'              # the URDF robot name
    expected = {f'{k}': v for k, v in four_bar_native()['joints']['closing_joint'].items()}
    for key, value in expected.items():
        assert native[f'joints.closing_joint.{key}'] == value
    assert not any(key.startswith(('loop_closures', 'robot_description')) for key in native)


def test_initial_positions_left_out_are_zero_and_other_parameters_pass_through():
    params = four_bar_urdf_params()
    params['mechanism']['initial_positions'] = {'rocker_joint': 1.82}
    params['mechanism']['name'] = 'renamed'
    params['rate'] = 500.0                   # a node's own parameter: not the mechanism's
    native = native_parameters(params)
    assert native['mechanism.initial_positions'] == [0.0, 0.0, 1.82, 0.0]
    assert native['mechanism.name'] == 'renamed'
    assert native['rate'] == 500.0


def test_params_file_with_relative_urdf_file(tmp_path, monkeypatch):
    sub = tmp_path / 'robots'
    sub.mkdir()
    (sub / 'four_bar.urdf').write_text(four_bar_urdf(), encoding='utf-8')
    (sub / 'four_bar.yaml').write_text("""\
/**:
  ros__parameters:
    mechanism:
      urdf_file: four_bar.urdf
      gravity: [0.0, -9.81, 0.0]
      active_joints: [crank_joint]
      loop_closures: [closing_joint]
      initial_positions: {crank_joint: 1.2, coupler_joint: -0.6, rocker_joint: 1.82,
                          closing_joint: -1.22}
      closure_tolerance: 1.0e-11
    loop_closures:
      closing_joint:
        type: revolute
        parent: rocker
        child: coupler
        parent_xyz: [0.3, 0.0, 0.0]
        child_xyz: [0.35, 0.0, 0.0]
""", encoding='utf-8')
    path = str(sub / 'four_bar.yaml')
    flat = load_params_file(path)
    assert is_urdf(flat)
    native = native_parameters(flat, base_dir=os.path.dirname(path))
    mech = Mechanism.from_parameters(native)
    motion = crank_motion(20)
    ref = cog_id_ros.InverseDynamics(Mechanism.from_parameters(four_bar_native())).torques(
        *motion)
    np.testing.assert_allclose(cog_id_ros.InverseDynamics(mech).torques(*motion), ref,
                               rtol=1e-12, atol=1e-12 * np.abs(ref).max())
    # the core's own entry point, from another working directory
    monkeypatch.chdir(tmp_path)
    mech = Mechanism.from_params_file(path)
    np.testing.assert_allclose(cog_id_ros.InverseDynamics(mech).torques(*motion), ref,
                               rtol=1e-12, atol=1e-12 * np.abs(ref).max())


def test_is_urdf():
    assert is_urdf({'robot_description': '<robot/>'})
    assert is_urdf({'mechanism.urdf_file': 'x.urdf'})
    assert is_urdf({'mechanism': {'urdf_file': 'x.urdf'}})
    assert not is_urdf({'mechanism.links': ['a']})
    assert not is_urdf(load_params_file(os.path.join(CONFIG, 'paper_four_bar_a.yaml')))


def test_spherical_universal_and_fixed_closures_become_native_joints():
    urdf = four_bar_urdf()
    params = four_bar_urdf_params()
    params['mechanism']['loop_closures'] = ['ball', 'cross', 'weld', 'closing_joint']
    params['mechanism']['initial_positions'] = {'crank_joint': 1.2}
    params['loop_closures'].update({
        'ball': {'type': 'spherical', 'parent': 'rocker', 'child': 'coupler',
                 'parent_xyz': [0.1, 0.0, 0.0]},
        'cross': {'type': 'universal', 'parent': 'ground', 'child': 'coupler',
                  'axis': [1.0, 0.0, 0.0], 'axis2': [0.0, 2.0, 0.0]},
        'weld': {'type': 'fixed', 'parent': 'crank', 'child': 'ground',
                 'child_rpy': [0.0, 0.0, 0.5]},
    })
    params['robot_description'] = urdf
    native = native_parameters(params)
    assert native['mechanism.joints'][3:] == ['ball', 'cross', 'weld', 'closing_joint']
    # one position per revolute or prismatic joint, closures included
    assert native['mechanism.initial_positions'] == [1.2, 0.0, 0.0, 0.0]
    assert native['joints.ball.type'] == 'spherical' and 'joints.ball.axis' not in native
    assert native['joints.ball.parent_xyz'] == [0.1, 0.0, 0.0]
    assert (native['joints.cross.axis'], native['joints.cross.axis2']) == (
        [1.0, 0.0, 0.0], [0.0, 2.0, 0.0])
    assert native['joints.weld.type'] == 'fixed' and native['joints.weld.child'] == 'ground'
    assert native['joints.weld.child_rpy'] == [0.0, 0.0, 0.5]


# --- config/crank_rocker.urdf + config/crank_rocker_urdf.yaml --------------------------------

def test_config_crank_rocker_loads_and_solves_a_motion():
    path = os.path.join(CONFIG, 'crank_rocker_urdf.yaml')
    flat = load_params_file(path)
    native = native_parameters(flat, base_dir=CONFIG)
    assert native['mechanism.links'] == ['crank', 'coupler', 'rocker']   # flywheel merged
    assert native['mechanism.base_link'] == 'world'                      # frame merged
    mech = Mechanism.from_parameters(native)
    assert mech.dof == 1 and not mech.assembly_warnings
    assert Mechanism.from_params_file(path).joints == mech.joints
    solver = cog_id_ros.InverseDynamics(mech)
    t = np.linspace(0.0, 2.0, 201)        # two revolutions at 1 rev/s, plus a wobble
    theta = math.pi / 2 + 2 * math.pi * t + 0.2 * np.sin(np.pi * t)
    theta_d = 2 * math.pi + 0.2 * np.pi * np.cos(np.pi * t)
    theta_dd = -0.2 * np.pi ** 2 * np.sin(np.pi * t)
    tau = solver.torques(theta[:, None], theta_d[:, None], theta_dd[:, None])
    assert tau.shape == (201, 1) and np.all(np.isfinite(tau))
    assert 0.3 < np.abs(tau).max() < mech.effort_limits[0]


def test_config_crank_rocker_against_pinocchio_by_virtual_work():
    """Pinocchio reads config/crank_rocker.urdf itself (the tree, with its fixed joints):
    the loop closes in its geometry at the poses our solver reports, and the crank torque is
    the virtual work of the tree's RNEA torques along the loop's motion,
    tau = sum_i tau_tree_i dq_i/dtheta (the pin closing the loop does no work)."""
    pin = pytest.importorskip('pinocchio')
    model = pin.buildModelFromUrdf(os.path.join(CONFIG, 'crank_rocker.urdf'))
    data = model.createData()
    mech = Mechanism.from_params_file(os.path.join(CONFIG, 'crank_rocker_urdf.yaml'))
    solver = cog_id_ros.InverseDynamics(mech)
    tree = ['crank_joint', 'coupler_joint', 'rocker_joint']
    index = [mech.joints.index(name) for name in tree]

    def to_pin(q):
        pq = np.zeros(model.nq)
        for name, k in zip(tree, index):
            jm = model.joints[model.getJointId(name)]
            if jm.nq == 2:
                pq[jm.idx_q:jm.idx_q + 2] = math.cos(q[k]), math.sin(q[k])
            else:
                pq[jm.idx_q] = q[k]
        return pq

    def to_pin_v(v):
        pv = np.zeros(model.nv)
        for name, k in zip(tree, index):
            pv[model.joints[model.getJointId(name)].idx_v] = v[k]
        return pv

    def state(time):
        theta = 2.0 + 3.0 * time + 0.5 * math.sin(2.0 * time)
        theta_d = 3.0 + math.cos(2.0 * time)
        theta_dd = -2.0 * math.sin(2.0 * time)
        tau = solver.sample_torques([theta], [theta_d], [theta_dd])[0]
        q, qdot = solver.last_pose([theta_d])
        _, dq_dtheta = solver.last_pose([1.0])
        return tau, np.array(q), np.array(qdot), np.array(dq_dtheta)

    h = 1e-4         # central differences: truncation and solver noise about 1e-9 N m
    for time in np.linspace(0.0, 2.0, 9):
        _, _, qdot_before, _ = state(time - h)
        _, _, qdot_after, _ = state(time + h)
        tau, q, qdot, dq_dtheta = state(time)
        qddot = (qdot_after - qdot_before) / (2 * h)
        pq = to_pin(q)
        pin.forwardKinematics(model, data, pq)
        rocker_tip = data.oMi[model.getJointId('rocker_joint')].act(np.array([0.3, 0.0, 0.012]))
        coupler_end = data.oMi[model.getJointId('coupler_joint')].act(np.array([0.35, 0.0, 0.0]))
        np.testing.assert_allclose(rocker_tip, coupler_end, atol=1e-12)
        tree_tau = pin.rnea(model, data, pq, to_pin_v(qdot), to_pin_v(qddot))
        expected = float(tree_tau @ to_pin_v(dq_dtheta))
        assert tau == pytest.approx(expected, rel=0.0, abs=2e-8)


# --- errors ----------------------------------------------------------------------------------

def error_of(params, base_dir=None):
    with pytest.raises(MechanismConfigError) as info:
        native_parameters(params, base_dir)
    return info.value


def with_urdf(urdf, **mechanism):
    return {'robot_description': urdf, 'mechanism': {'active_joints': ['crank_joint'],
                                                     **mechanism}}


def test_urdf_that_does_not_parse_gives_the_line():
    bad = four_bar_urdf().replace('<link name="rocker">', '<link name="rocker"', 1)
    line = bad[:bad.index('<link name="rocker"')].count('\n') + 1
    err = error_of(with_urdf(bad))
    assert err.parameter == 'robot_description'
    assert f'line {line}' in str(err) and 'not well-formed XML' in str(err)
    err = error_of(with_urdf('<robot name="x">\n<link name="a">\n</robot>'))
    assert str(err).startswith('robot_description: line 3') and 'mismatched tag' in str(err)


def test_whitespace_ahead_of_the_xml_declaration_is_accepted_and_lines_still_count():
    urdf = '\n  \n<?xml version="1.0"?>\n' + four_bar_urdf()
    assert native_parameters(with_urdf(urdf))['mechanism.links'] == ['crank', 'coupler',
                                                                      'rocker']
    floating = urdf.replace('type="continuous"', 'type="floating"')
    err = error_of(with_urdf(floating))
    line = floating[:floating.index('type="floating"')].count('\n') + 1
    assert line > 3 and f'robot_description: line {line}:' in str(err)


def test_doctype_and_entities_are_refused():
    laughs = ('<?xml version="1.0"?>\n<!DOCTYPE robot [\n<!ENTITY a "aaaaaaaaaa">\n'
              '<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">\n]>\n<robot name="&b;"/>')
    err = error_of(with_urdf(laughs))
    assert err.parameter == 'robot_description' and 'DOCTYPE' in str(err)
    assert 'line 2' in str(err)
    err = error_of(with_urdf('<robot name="&undefined;"/>'))
    assert 'undefined entity' in str(err)


def test_xacro_is_refused():
    err = error_of(with_urdf('<robot name="r" xmlns:xacro="http://www.ros.org/wiki/xacro">\n'
                             '<xacro:property name="l" value="1"/>\n</robot>'))
    assert 'line 2' in str(err) and 'run xacro' in str(err)


def test_root_must_be_robot():
    err = error_of(with_urdf('<model name="x"/>'))
    assert 'line 1' in str(err) and '<robot>' in str(err)


@pytest.mark.parametrize('kind', ['floating', 'planar'])
def test_floating_and_planar_joints_are_refused(kind):
    urdf = four_bar_urdf().replace('type="continuous"', f'type="{kind}"')
    err = error_of(with_urdf(urdf))
    assert err.parameter == 'robot_description'
    assert "joint 'crank_joint'" in str(err) and kind in str(err)


def test_unknown_joint_type_is_refused():
    err = error_of(with_urdf(four_bar_urdf().replace('type="continuous"', 'type="hinge"')))
    assert "joint 'crank_joint'" in str(err) and "'hinge'" in str(err)


def test_mimic_is_read_as_a_coupling():
    """<mimic> becomes the native coupling keys (core/kinematics/couplings.py), with urdfdom's defaults
    (multiplier 1, offset 0); a leader the URDF does not have is refused on its line."""
    urdf = four_bar_urdf().replace(
        '<axis xyz="0 0 1"/><limit lower="-6" upper="6" effort="0" velocity="1.0"/></joint>',
        '<axis xyz="0 0 1"/><limit lower="-6" upper="6" effort="0" velocity="1.0"/>'
        '<mimic joint="crank_joint" multiplier="2"/></joint>', 1)
    native = native_parameters(with_urdf(urdf))
    assert native['joints.coupler_joint.mimic'] == 'crank_joint'
    assert native['joints.coupler_joint.mimic_multiplier'] == 2.0
    assert native['joints.coupler_joint.mimic_offset'] == 0.0
    err = error_of(with_urdf(urdf.replace('joint="crank_joint"', 'joint="cranck_joint"')))
    assert err.parameter == 'robot_description', str(err)
    assert "<mimic> of joint 'coupler_joint' names 'cranck_joint'" in str(err)


def test_any_urdf_name_loads_and_a_control_character_is_refused():
    """Names as CAD exporters write them ('-', '.', '/', a leading digit, non-ASCII) load and
    reach the native parameters unchanged; only control characters are refused (they would
    split log lines and CSV rows), with the URDF line."""
    urdf = four_bar_urdf().replace('"rocker"', '"1 rocker-arm/\u00e9"').replace(
        '"rocker_joint"', '"rocker.joint"')
    native = native_parameters(with_urdf(urdf))
    assert '1 rocker-arm/\u00e9' in native['mechanism.links']
    assert 'rocker.joint' in native['mechanism.joints']
    assert native['joints.rocker.joint.child'] == '1 rocker-arm/\u00e9'
    err = error_of(with_urdf(four_bar_urdf().replace('"rocker"', '"rocker&#10;arm"')))
    assert "link name 'rocker\\narm'" in str(err) and 'line' in str(err)
    assert 'U+000A' in str(err)


def test_urdf_tree_errors():
    urdf = four_bar_urdf()
    err = error_of(with_urdf(urdf.replace('<child link="rocker"/>', '<child link="rockr"/>')))
    assert "joint 'rocker_joint'" in str(err) and "'rockr'" in str(err)
    err = error_of(with_urdf(urdf.replace('<child link="rocker"/>', '<child link="coupler"/>')))
    assert "link 'coupler' is the child of joints 'coupler_joint' and 'rocker_joint'" in str(err)
    err = error_of(with_urdf(urdf.replace(
        '</robot>', '<link name="spare"/></robot>')))
    assert '2 links have no parent joint' in str(err) and "'spare'" in str(err)
    cycle = ''.join(['<robot name="c">'] + [f'<link name="{n}"/>' for n in 'rabc']
                    + [joint('ja', 'revolute', 'r', 'a'), joint('jb', 'revolute', 'b', 'c'),
                       joint('jc', 'revolute', 'c', 'b'), '</robot>'])
    err = error_of(with_urdf(cycle))
    assert "cycle through links 'b', 'c'" in str(err)
    err = error_of(with_urdf(urdf.replace('<link name="rocker">', '<link name="crank">')))
    assert "a second link named 'crank'" in str(err)


def test_bad_numbers_and_limits_in_the_urdf():
    urdf = four_bar_urdf()
    err = error_of(with_urdf(urdf.replace('<origin xyz="0.4 0 0"', '<origin xyz="0.4 0"')))
    assert "joint 'rocker_joint'" in str(err) and 'xyz' in str(err) and '3 numbers' in str(err)
    err = error_of(with_urdf(urdf.replace('<mass value="0.9"/>', '<mass value="-0.9"/>')))
    assert "link 'rocker'" in str(err) and '>= 0' in str(err)
    err = error_of(with_urdf(urdf.replace('<mass value="0.9"/>', '<mass value="nan"/>')))
    assert "link 'rocker'" in str(err)
    err = error_of(with_urdf(urdf.replace('lower="-6" upper="6"', 'lower="1" upper="1"', 1)))
    assert "joint 'coupler_joint'" in str(err) and 'below upper' in str(err)
    err = error_of(with_urdf(urdf.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', 1)))
    assert "joint 'crank_joint'" in str(err) and 'zero-length' in str(err)


def test_both_or_neither_urdf_source():
    err = error_of({'robot_description': four_bar_urdf(), 'mechanism.urdf_file': 'x.urdf'})
    assert err.parameter == 'mechanism.urdf_file' and 'not both' in str(err)
    err = error_of({'mechanism.active_joints': ['crank_joint']})
    assert err.parameter == 'robot_description'


@pytest.mark.parametrize('name', ['mechanism.links', 'mechanism.joints'])
def test_native_link_and_joint_lists_are_refused_with_a_urdf(name):
    params = four_bar_urdf_params()
    params[name] = ['crank']
    err = error_of(params)
    assert err.parameter == name


def test_native_link_and_joint_parameters_are_refused_with_a_urdf():
    params = four_bar_urdf_params()
    params['links.crank.mass'] = 2.0
    err = error_of(params)
    assert err.parameter == 'links.crank.mass'


def test_unreadable_urdf_file_names_the_path(tmp_path):
    err = error_of({'mechanism.urdf_file': 'missing.urdf',
                    'mechanism.active_joints': ['crank_joint']}, base_dir=str(tmp_path))
    assert err.parameter == 'mechanism.urdf_file'
    assert str(tmp_path / 'missing.urdf') in str(err)
    err = error_of({'mechanism.urdf_file': str(tmp_path),
                    'mechanism.active_joints': ['crank_joint']})
    assert str(tmp_path) in str(err) and 'not a regular file' in str(err)
    err = error_of({'mechanism.urdf_file': 'package://robot/x.urdf',
                    'mechanism.active_joints': ['crank_joint']})
    assert 'package://' in str(err)


def test_errors_in_a_urdf_file_name_the_file_and_line(tmp_path):
    (tmp_path / 'bad.urdf').write_text('<robot name="r">\n<link name="a"/>\n'
                                       '<joint name="j" type="floating">\n'
                                       '<parent link="a"/><child link="b"/></joint>\n'
                                       '<link name="b"/>\n</robot>\n', encoding='utf-8')
    err = error_of({'mechanism.urdf_file': 'bad.urdf', 'mechanism.active_joints': ['j']},
                   base_dir=str(tmp_path))
    assert err.parameter == 'mechanism.urdf_file'
    assert f"{tmp_path / 'bad.urdf'} line 3" in str(err) and "joint 'j'" in str(err)


def test_closure_link_that_does_not_exist():
    params = four_bar_urdf_params()
    params['loop_closures']['closing_joint']['parent'] = 'rockr'
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_joint.parent' and "'rockr'" in str(err)


def test_closure_between_rigidly_connected_links():
    params = four_bar_urdf_params(tip=True)
    params['loop_closures']['closing_joint']['parent'] = 'coupler'
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_joint.child'
    assert 'already rigidly connected' in str(err) and "'coupler'" in str(err)


def test_closure_entries_not_listed_or_with_unknown_keys():
    params = four_bar_urdf_params()
    params['loop_closures']['closing_jiont'] = {'type': 'revolute'}
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_jiont.type'
    assert 'not in mechanism.loop_closures' in str(err)
    params = four_bar_urdf_params()
    params['loop_closures']['closing_joint']['axiss'] = [0.0, 0.0, 1.0]
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_joint.axiss' and 'unknown' in str(err)
    params = four_bar_urdf_params()
    params['loop_closures']['closing_joint']['type'] = 'ball'
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_joint.type'
    params = four_bar_urdf_params()
    params['mechanism']['loop_closures'] = ['rocker_joint']
    err = error_of(params)
    assert err.parameter == 'mechanism.loop_closures' and 'already a joint' in str(err)


def test_universal_closure_axis2():
    params = four_bar_urdf_params()
    closure = params['loop_closures']['closing_joint']
    closure['type'] = 'universal'
    params['mechanism']['initial_positions'] = {'crank_joint': 1.2}
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_joint.axis2' and 'missing' in str(err)
    closure['axis2'] = [0.0, 0.1, 1.0]
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_joint.axis2'
    assert 'perpendicular' in str(err)
    closure['axis2'] = [1.0, 0.0, 0.0]
    assert native_parameters(params)['joints.closing_joint.axis2'] == [1.0, 0.0, 0.0]
    params['mechanism']['loop_closures'] = ['closing_joint']
    closure['type'] = 'revolute'
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_joint.axis2'
    closure['type'] = 'spherical'
    del closure['axis2']
    err = error_of(params)
    assert err.parameter == 'loop_closures.closing_joint.axis'


@pytest.mark.parametrize('kind', ['spherical', 'universal', 'fixed'])
def test_active_closure_without_coordinate_is_refused(kind):
    params = four_bar_urdf_params()
    closure = params['loop_closures']['closing_joint']
    closure['type'] = kind
    closure.pop('axis') if kind != 'universal' else closure.update(axis2=[1.0, 0.0, 0.0])
    params['mechanism']['active_joints'] = ['closing_joint']
    params['mechanism']['initial_positions'] = {'crank_joint': 1.2}
    err = error_of(params)
    assert err.parameter == 'mechanism.active_joints'
    assert 'closing_joint' in str(err) and kind in str(err)


def test_active_joint_that_does_not_exist_or_is_fixed():
    params = four_bar_urdf_params()
    params['mechanism']['active_joints'] = ['crank_jiont']
    err = error_of(params)
    assert err.parameter == 'mechanism.active_joints' and "'crank_jiont'" in str(err)
    params = four_bar_urdf_params(tip=True)
    params['mechanism']['active_joints'] = ['tip_mount']
    err = error_of(params)
    assert err.parameter == 'mechanism.active_joints' and 'fixed joint' in str(err)


def test_initial_positions_errors():
    params = four_bar_urdf_params()
    params['mechanism']['initial_positions'] = {'crank': 1.0}
    err = error_of(params)
    assert err.parameter == 'mechanism.initial_positions.crank'
    params = four_bar_urdf_params(tip=True)
    params['mechanism']['initial_positions'] = {'tip_mount': 1.0}
    err = error_of(params)
    assert err.parameter == 'mechanism.initial_positions.tip_mount'
    assert 'fixed joint' in str(err)
    params = four_bar_urdf_params()
    params['loop_closures']['closing_joint']['type'] = 'spherical'
    del params['loop_closures']['closing_joint']['axis']
    err = error_of(params)
    assert err.parameter == 'mechanism.initial_positions.closing_joint'
    assert 'spherical' in str(err)
    params = four_bar_urdf_params()
    params['mechanism']['initial_positions'] = [1.2, -0.6, 1.82, -1.22]
    err = error_of(params)
    assert err.parameter == 'mechanism.initial_positions' and 'map joint names' in str(err)
    params['mechanism']['initial_positions'] = {'crank_joint': 'up'}
    err = error_of(params)
    assert err.parameter == 'mechanism.initial_positions.crank_joint'


def test_base_link_that_does_not_exist():
    params = four_bar_urdf_params()
    params['mechanism']['base_link'] = 'floor'
    err = error_of(params)
    assert err.parameter == 'mechanism.base_link' and "'ground'" in str(err)


@pytest.mark.parametrize('kind', ['spherical', 'universal'])
def test_four_bar_closed_by_a_joint_without_coordinate(kind):
    """The planar four-bar closed by a spherical or a universal joint (axis z on the rocker,
    axis2 x on the coupler: always perpendicular in the plane) moves as with the pin, so the
    crank torques are the same: the closure's constraint forces do no work either way."""
    params = four_bar_urdf_params()
    closure = params['loop_closures']['closing_joint']
    closure['type'] = kind
    if kind == 'spherical':
        del closure['axis']
    else:
        closure['axis2'] = [1.0, 0.0, 0.0]
    del params['mechanism']['initial_positions']['closing_joint']
    native = native_parameters(params)
    assert native['mechanism.initial_positions'] == [1.2, -0.6, 1.82]
    mech = Mechanism.from_parameters(native)
    assert mech.dof == 1 and mech.closure_joints == ['closing_joint']
    motion = crank_motion(30)
    ours = cog_id_ros.InverseDynamics(mech).torques(*motion)
    ref = cog_id_ros.InverseDynamics(Mechanism.from_parameters(four_bar_native())).torques(
        *motion)
    np.testing.assert_allclose(ours, ref, rtol=1e-10, atol=1e-10 * np.abs(ref).max())


def test_base_link_may_be_a_moving_link():
    """A base link welded to a moving link: its group of welded links is named after it, and
    the URDF's root becomes a moving link (the core takes joints in either direction)."""
    native, names = all_active(ARM, (0.0, 0.0, -9.81), **{'mechanism.base_link': 'elbow_flange'})
    assert native['mechanism.base_link'] == 'elbow_flange'
    assert native['mechanism.links'] == ['world', 'shoulder', 'forearm', 'wrist',
                                         'counterweight']
    assert native['joints.j2.child'] == 'elbow_flange'      # upper_arm is welded to the base
    assert native['joints.j2.child_xyz'] != [0.0, 0.0, 0.0]
    assert native['joints.j3.parent'] == 'elbow_flange'
    assert native['joints.j3.parent_xyz'] == [0.02, 0.0, 0.05]   # written in its frame
    assert native['links.world.mass'] == pytest.approx(4.0)     # the pedestal, welded to it
    mech = Mechanism.from_parameters(native)
    q, qd, qdd = random_states(native, 3, 4)
    assert np.all(np.isfinite(cog_id_ros.InverseDynamics(mech).torques(q, qd, qdd)))
    # the same body as base, named after upper_arm: the same torques, gravity turned along
    g_upper = np.array([0.3, -0.2, -9.81])
    r_upper_flange = rpy_matrix((0.3, 0.4, -0.5)) @ rpy_matrix((0.0, -0.7, 0.0))
    torques = []
    for base, g in (('upper_arm', g_upper), ('elbow_flange', r_upper_flange.T @ g_upper)):
        native, _ = all_active(ARM, g, **{'mechanism.base_link': base})
        torques.append(cog_id_ros.InverseDynamics(Mechanism.from_parameters(native)).torques(
            q, qd, qdd))
    np.testing.assert_allclose(torques[1], torques[0], rtol=1e-12,
                               atol=1e-12 * np.abs(torques[0]).max())
