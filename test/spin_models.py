"""A Stewart-like parallel robot with rods between two ball joints, in three forms.

The delta robot of config/delta_3rus.yaml is built with a universal joint at each rod's
elbow end (two revolutes about x, then y, through a massless cross) and a ball at its
platform end (three revolutes through two massless links). The robot as built has balls at
both ends; :func:`delta_3rss` gives it that way: a third revolute ``<rod>_u3`` about the
rod's own axis (z of the elbow frame) through a second massless link ``<rod>_cross2``, at
0 in the initial positions (the same pose). Each of the six rods then spins about its own
axis, a freedom no actuator drives: 3 actuators for 9 degrees of freedom.

* :func:`delta_3rss`: native schema, revolute joints only (what the Pinocchio oracle of
  test/pinocchio_reference.py reads);
* :func:`delta_3rss_spherical`: native schema, every platform ball but r0a's one
  ``type: spherical`` joint (a rod between three revolutes and a native ball);
* :func:`delta_3rss_urdf`: a URDF of the same tree (r0a carries the platform; the
  platform is placed by a fixed joint, URDF's child frame being the joint frame) and the
  other five platform balls as ``spherical`` loop closures.

Locking ``<rod>_u3`` at 0 makes each rod's elbow a universal joint again: the robot of
delta_3rus.yaml, whose torques are known. Locking ``<rod>_s3`` (the platform ball's
revolute about the rod's axis at home) is another valid choice.
"""
import math
import os

from mechanisms import from_yaml
import numpy as np
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
DELTA = os.path.join(os.path.dirname(HERE), 'config', 'delta_3rus.yaml')
RODS = [f'r{i}{side}' for i in range(3) for side in 'ab']
ELBOW_LOCKS = [f'{rod}_u3' for rod in RODS]
PLATFORM_LOCKS = [f'{rod}_s3' for rod in RODS]


def delta_3rss():
    """The delta robot with a ball joint at both ends of every rod (module docstring)."""
    p = dict(from_yaml(DELTA))
    links, joints = list(p['mechanism.links']), list(p['mechanism.joints'])
    init = list(p['mechanism.initial_positions'])
    for rod in RODS:
        cross2 = f'{rod}_cross2'
        links.insert(links.index(rod), cross2)
        p.update({f'links.{cross2}.mass': 0.0, f'links.{cross2}.com': [0.0] * 3,
                  f'links.{cross2}.inertia': [0.0] * 6})
        p[f'joints.{rod}_u2.child'] = cross2
        k = joints.index(f'{rod}_u2') + 1
        joints.insert(k, f'{rod}_u3')
        init.insert(k, 0.0)
        p.update({f'joints.{rod}_u3.type': 'revolute', f'joints.{rod}_u3.parent': cross2,
                  f'joints.{rod}_u3.child': rod, f'joints.{rod}_u3.axis': [0.0, 0.0, 1.0]})
    p.update({'mechanism.name': 'delta_3rss', 'mechanism.links': links,
              'mechanism.joints': joints, 'mechanism.initial_positions': init})
    return p


def delta_3rss_spherical():
    """delta_3rss with the platform ball of every rod but r0a one spherical joint."""
    p = delta_3rss()
    gone_links, gone_joints = set(), set()
    for rod in RODS[1:]:
        gone_links |= {f'{rod}_sa', f'{rod}_sb'}
        gone_joints |= {f'{rod}_s1', f'{rod}_s2', f'{rod}_s3'}
        ball = f'{rod}_s'
        p.update({f'joints.{ball}.type': 'spherical', f'joints.{ball}.parent': rod,
                  f'joints.{ball}.child': 'platform',
                  f'joints.{ball}.parent_xyz': p[f'joints.{rod}_s1.parent_xyz'],
                  f'joints.{ball}.child_xyz': p[f'joints.{rod}_s3.child_xyz']})
    keep = [k for k, name in enumerate(p['mechanism.joints']) if name not in gone_joints]
    p['mechanism.initial_positions'] = [p['mechanism.initial_positions'][k] for k in keep]
    p['mechanism.joints'] = [p['mechanism.joints'][k] for k in keep] + [
        f'{rod}_s' for rod in RODS[1:]]
    p['mechanism.links'] = [name for name in p['mechanism.links'] if name not in gone_links]
    return {key: value for key, value in p.items()
            if key.split('.')[0] not in ('links', 'joints') or
            key.split('.')[1] not in gone_links | gone_joints}


def _rpy(r):
    """URDF roll, pitch, yaw of a rotation matrix (R = Rz Ry Rx)."""
    return [math.atan2(r[2, 1], r[2, 2]), -math.asin(max(-1.0, min(1.0, r[2, 0]))),
            math.atan2(r[1, 0], r[0, 0])]


def _rotation(rpy):
    r, p, y = rpy
    rx = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    ry = np.array([[math.cos(p), 0, math.sin(p)], [0, 1, 0], [-math.sin(p), 0, math.cos(p)]])
    rz = np.array([[math.cos(y), -math.sin(y), 0], [math.sin(y), math.cos(y), 0], [0, 0, 1]])
    return rz @ ry @ rx


def _numbers(values):
    return ' '.join(repr(float(v)) for v in values)


def _link(p, name):
    mass = p.get(f'links.{name}.mass', 0.0)
    if not mass:
        return f'  <link name="{name}"/>'
    ixx, iyy, izz, ixy, ixz, iyz = p[f'links.{name}.inertia']
    return (f'  <link name="{name}"><inertial><origin xyz="{_numbers(p[f"links.{name}.com"])}"'
            f'/><mass value="{mass!r}"/><inertia ixx="{ixx!r}" ixy="{ixy!r}" ixz="{ixz!r}" '
            f'iyy="{iyy!r}" iyz="{iyz!r}" izz="{izz!r}"/></inertial></link>')


def _joint(name, kind, parent, child, xyz, rpy, axis=None):
    return (f'  <joint name="{name}" type="{kind}"><parent link="{parent}"/><child '
            f'link="{child}"/><origin xyz="{_numbers(xyz)}" rpy="{_numbers(rpy)}"/>'
            + (f'<axis xyz="{_numbers(axis)}"/>' if axis is not None else '') + '</joint>')


def delta_3rss_urdf():
    """(parameters in the URDF form, the names of its spherical loop closures): the tree of
    delta_3rss as a URDF, r0a's platform ball in it, the other five as closures."""
    p = delta_3rss_spherical()
    tree = [name for name in p['mechanism.joints'] if p[f'joints.{name}.type'] == 'revolute']
    closures = [name for name in p['mechanism.joints'] if name not in tree]
    lines = ['<robot name="delta_3rss">', _link(p, 'ground'), '  <link name="platform_mount"/>']
    lines += [_link(p, name) for name in p['mechanism.links']]
    for name in tree:
        prefix = f'joints.{name}.'
        child = p[prefix + 'child']
        if child == 'platform':          # the URDF child frame is the joint frame
            child = 'platform_mount'
            rot = _rotation(p[prefix + 'child_rpy'])
            lines.append(_joint('platform_fix', 'fixed', 'platform_mount', 'platform',
                                -rot.T @ np.array(p[prefix + 'child_xyz']), _rpy(rot.T)))
        lines.append(_joint(name, 'continuous', p[prefix + 'parent'], child,
                            p.get(prefix + 'parent_xyz', [0.0] * 3),
                            p.get(prefix + 'parent_rpy', [0.0] * 3), p[prefix + 'axis']))
    lines.append('</robot>')
    init = dict(zip(p['mechanism.joints'], p['mechanism.initial_positions']))
    params = {'robot_description': '\n'.join(lines),
              'mechanism.active_joints': p['mechanism.active_joints'],
              'mechanism.loop_closures': closures}
    params.update({f'mechanism.initial_positions.{name}': init[name] for name in tree})
    for name in closures:
        for key in ('type', 'parent', 'child', 'parent_xyz', 'child_xyz'):
            params[f'loop_closures.{name}.{key}'] = p[f'joints.{name}.{key}']
    return params


def write_params(params, path):
    """``params`` (dotted names) as a ROS 2 parameter file for every node."""
    nested = {}
    for key, value in params.items():
        node = nested
        *parts, last = key.split('.')
        for part in parts:
            node = node.setdefault(part, {})
        node[last] = value
    with open(path, 'w', encoding='utf-8') as f:
        yaml.safe_dump({'/**': {'ros__parameters': nested}}, f)
    return str(path)
