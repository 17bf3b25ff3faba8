"""Small mechanisms for the core tests, as dotted-name parameter dicts (what rclpy gives)."""
import copy
import math

import yaml

from cog_id_ros.core.kinematics.parameters import flatten

ROD = [0.0, 0.020833333333333332, 0.020833333333333332, 0.0, 0.0, 0.0]


def from_yaml(path):
    with open(path, encoding='utf-8') as f:
        return flatten(yaml.safe_load(f)['/**']['ros__parameters'])


def four_bar(ground=0.5, crank=0.5, coupler=0.5, rocker=0.5, active=('joint3',), init=None):
    """Planar four-bar in x-y, gravity -y; links are uniform 1 kg rods along their x axis."""
    p = {
        'mechanism.name': 'test_four_bar', 'mechanism.gravity': [0.0, -9.81, 0.0],
        'mechanism.links': ['link1', 'link2', 'link3'],
        'mechanism.joints': ['joint1', 'joint2', 'joint3', 'joint4'],
        'mechanism.active_joints': list(active),
        'joints.joint1.type': 'revolute', 'joints.joint1.parent': 'ground', 'joints.joint1.child': 'link1',
        'joints.joint2.type': 'revolute', 'joints.joint2.parent': 'link1', 'joints.joint2.child': 'link2',
        'joints.joint2.parent_xyz': [crank, 0, 0],
        'joints.joint3.type': 'revolute', 'joints.joint3.parent': 'ground', 'joints.joint3.child': 'link3',
        'joints.joint3.parent_xyz': [ground, 0, 0],
        'joints.joint4.type': 'revolute', 'joints.joint4.parent': 'link2', 'joints.joint4.child': 'link3',
        'joints.joint4.parent_xyz': [coupler, 0, 0], 'joints.joint4.child_xyz': [rocker, 0, 0],
    }
    for name, length in (('link1', crank), ('link2', coupler), ('link3', rocker)):
        p[f'links.{name}.mass'] = 1.0
        p[f'links.{name}.com'] = [length / 2, 0.0, 0.0]
        p[f'links.{name}.inertia'] = [0.0, length ** 2 / 12, length ** 2 / 12, 0, 0, 0]
    if init is not None:
        p['mechanism.initial_positions'] = list(init)
    return p


def slider_crank(crank=0.1, rod=0.3):
    """Crank (active, joint 'crank') on the ground, rod, slider on a prismatic joint along x.

    The prismatic joint is written from the slider to the ground (child closer to the base)
    and the loop closes on the crank pin joint, to exercise both conventions."""
    x = crank + rod
    return {
        'mechanism.name': 'test_slider_crank', 'mechanism.gravity': [0.0, -9.81, 0.0],
        'mechanism.links': ['crank', 'rod', 'slider'],
        'mechanism.joints': ['j_crank', 'j_slider', 'j_pin', 'j_wrist'],
        'mechanism.active_joints': ['j_crank'],
        'mechanism.initial_positions': [0.0, -x, 0.0, math.pi],
        'links.crank.mass': 0.5, 'links.crank.com': [crank / 2, 0, 0],
        'links.crank.inertia': [1e-5, 0.5 * crank ** 2 / 12, 0.5 * crank ** 2 / 12, 0, 0, 0],
        'links.rod.mass': 0.8, 'links.rod.com': [rod / 2, 0, 0],
        'links.rod.inertia': [1e-5, 0.8 * rod ** 2 / 12, 0.8 * rod ** 2 / 12, 0, 0, 0],
        'links.slider.mass': 2.0, 'links.slider.inertia': [1e-3, 1e-3, 1e-3, 0, 0, 0],
        'joints.j_crank.type': 'revolute', 'joints.j_crank.parent': 'ground', 'joints.j_crank.child': 'crank',
        # slider -> ground, axis -x: q is the ground's travel seen from the slider (q = -x)
        'joints.j_slider.type': 'prismatic', 'joints.j_slider.parent': 'slider',
        'joints.j_slider.child': 'ground', 'joints.j_slider.axis': [1.0, 0.0, 0.0],
        'joints.j_pin.type': 'revolute', 'joints.j_pin.parent': 'crank', 'joints.j_pin.child': 'rod',
        'joints.j_pin.parent_xyz': [crank, 0, 0],
        'joints.j_wrist.type': 'revolute', 'joints.j_wrist.parent': 'slider', 'joints.j_wrist.child': 'rod',
        'joints.j_wrist.child_xyz': [rod, 0, 0], 'joints.j_wrist.child_rpy': [0.0, 0.0, math.pi],
    }


def double_pendulum():
    """An open chain (no loop): both joints active, gravity -z, axes along y."""
    p = {
        'mechanism.name': 'test_double_pendulum',
        'mechanism.links': ['upper', 'lower'], 'mechanism.joints': ['shoulder', 'elbow'],
        'mechanism.active_joints': ['shoulder', 'elbow'],
        'joints.shoulder.type': 'revolute', 'joints.shoulder.parent': 'ground',
        'joints.shoulder.child': 'upper', 'joints.shoulder.axis': [0, 1, 0],
        'joints.elbow.type': 'revolute', 'joints.elbow.parent': 'upper', 'joints.elbow.child': 'lower',
        'joints.elbow.parent_xyz': [0.4, 0, 0], 'joints.elbow.axis': [0, 1, 0],
    }
    for name, m, length in (('upper', 2.0, 0.4), ('lower', 1.0, 0.3)):
        p[f'links.{name}.mass'] = m
        p[f'links.{name}.com'] = [length / 2, 0.0, 0.0]
        p[f'links.{name}.inertia'] = [1e-4, m * length ** 2 / 12, m * length ** 2 / 12, 0, 0, 0]
    return p


def with_changes(params, **changes):
    """Copy of params with dotted names changed (name=None removes; '__' stands for '.')."""
    p = copy.deepcopy(params)
    for key, value in changes.items():
        key = key.replace('__', '.')
        if value is None:
            p.pop(key, None)
        else:
            p[key] = value
    return p
