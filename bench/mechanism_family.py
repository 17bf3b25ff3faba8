"""Families of mechanisms for measuring how cost grows with legs and loops.

Generators return parameter dicts for ``cog_id_ros.Mechanism.from_parameters`` (dotted
names, as rclpy gives a node):

* ``ups_platform(k)``: a platform on k UPS legs (base -U- lower leg -P- upper leg -S-
  platform), the U joint as two revolutes through a massless cross, the S joint as three
  revolutes through two massless helper links, exactly like config/stewart_6ups.yaml (which
  is ``ups_platform(6)`` written out by ``write_yaml``). A platform on k UPS legs has
  6 k joint freedoms, 5 k + 1 moving links, k - 1 loops of 6 equations: always 6 DOF. So
  k = 3 actuates the prismatic joint AND the first U revolute of every leg (6 actuators),
  k = 6 the six prismatic joints (the Stewart-Gough platform), k = 8, 10, 12 every prismatic
  joint (redundant actuation: k actuators, DOF 6, equal torque weights). Odd k > 3 is left
  out: the symmetric odd layout puts every leg on one linear line complex (singular).
* ``delta_robot()``: the delta robot of config/delta_3rus.yaml (3 legs, each an active
  revolute, an upper arm and a parallelogram of two rods, each rod with a U end at the elbow
  and an S end at the platform).
* ``four_bar_chain(n)``: n planar four-bar loops in a row, each new loop sharing a rocker with
  the previous one (a chain of parallelograms on one crank): 3 n + 1 joints, n loops, DOF 1.

Each generator also returns the same closed initial pose that its inverse kinematics gives
(``initial_positions``), so every member assembles exactly.

Script mode prints, per member: joints, loops, DOF, the coordinates solved for and the traced
operation counts of ``kernels_for(mech.solver_mechanism, 'python').operations`` (S joints
written as three revolutes through massless links are solved as spherical joints,
core/kinematics/spherical_chains.py) and load and trace times:

    .venv/bin/python bench/mechanism_family.py [--max-joints 80] [--family ups|chain|all]
"""
import argparse
import datetime
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
REPO = os.path.dirname(HERE)
if REPO not in sys.path:
    sys.path.insert(0, REPO)


# --------------------------------------------------------------------------- rotations

def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def rpy_matrix(rpy):
    """URDF roll-pitch-yaw: Rz(yaw) Ry(pitch) Rx(roll)."""
    return rot_z(rpy[2]) @ rot_y(rpy[1]) @ rot_x(rpy[0])


def matrix_rpy(r):
    """Inverse of rpy_matrix (pitch within +-pi/2)."""
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    return [math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])]


def universal_angles(r_frame, d):
    """Angles (q1 about x, q2 about y) of a U joint whose attachment frame has world rotation
    ``r_frame`` and whose child z axis must point along the unit vector ``d``; returns
    (q1, q2, child rotation). Rx(q1) Ry(q2) e_z = (sin q2, -sin q1 cos q2, cos q1 cos q2)."""
    df = r_frame.T @ d
    q2 = math.asin(max(-1.0, min(1.0, df[0])))
    q1 = math.atan2(-df[1], df[2])
    return q1, q2, r_frame @ rot_x(q1) @ rot_y(q2)


def spherical_angles(m):
    """XYZ angles (a, b, c) with Rx(a) Ry(b) Rz(c) = m; b is the middle angle (lock at
    +-pi/2)."""
    b = math.asin(max(-1.0, min(1.0, m[0, 2])))
    return math.atan2(-m[1, 2], m[2, 2]), b, math.atan2(-m[0, 1], m[0, 0])


def _r(v, nd=4):
    return [round(float(x), nd) + 0.0 for x in v]


def _link(p, name, mass, com=(0.0, 0.0, 0.0), inertia=(0.0,) * 6):
    p[f'links.{name}.mass'] = float(mass)
    p[f'links.{name}.com'] = [float(x) for x in com]
    p[f'links.{name}.inertia'] = [float(x) for x in inertia]


def _joint(p, name, parent, child, jtype='revolute', parent_xyz=(0.0, 0.0, 0.0),
           parent_rpy=(0.0, 0.0, 0.0), child_xyz=(0.0, 0.0, 0.0), child_rpy=(0.0, 0.0, 0.0),
           axis=(0.0, 0.0, 1.0)):
    p[f'joints.{name}.type'] = jtype
    p[f'joints.{name}.parent'] = parent
    p[f'joints.{name}.child'] = child
    p[f'joints.{name}.parent_xyz'] = [float(x) + 0.0 for x in parent_xyz]
    p[f'joints.{name}.parent_rpy'] = [float(x) + 0.0 for x in parent_rpy]
    p[f'joints.{name}.child_xyz'] = [float(x) + 0.0 for x in child_xyz]
    p[f'joints.{name}.child_rpy'] = [float(x) + 0.0 for x in child_rpy]
    p[f'joints.{name}.axis'] = [float(x) + 0.0 for x in axis]


def _spherical(p, leg, parent, child, parent_xyz, child_xyz, child_rpy):
    """S joint as revolutes about x, y, z through helper links <leg>_sa, <leg>_sb."""
    _link(p, f'{leg}_sa', 0.0)
    _link(p, f'{leg}_sb', 0.0)
    _joint(p, f'{leg}_s1', parent, f'{leg}_sa', parent_xyz=parent_xyz, axis=(1.0, 0.0, 0.0))
    _joint(p, f'{leg}_s2', f'{leg}_sa', f'{leg}_sb', axis=(0.0, 1.0, 0.0))
    _joint(p, f'{leg}_s3', f'{leg}_sb', child, child_xyz=child_xyz, child_rpy=child_rpy,
           axis=(0.0, 0.0, 1.0))
    return [f'{leg}_sa', f'{leg}_sb'], [f'{leg}_s1', f'{leg}_s2', f'{leg}_s3']


# --------------------------------------------------------------------------- UPS platforms

UPS = dict(base_radius=0.5, platform_radius=0.3, height=0.85, base_half_angle=5.0,
           platform_half_angle=5.0, lower_length=0.4, upper_length=0.4)


def ups_layout(k, g=UPS):
    """Base points (world) and platform points (platform frame) of k legs. k even: k/2 pairs
    of legs, pair j from base angles s j + d_b and s (j + 1) - d_b to platform angles
    s j + s/2 -+ d_p (s = 720/k degrees): the Stewart-Gough zig-zag. k odd: leg i from base
    angle 360 i/k to platform angle 360 i/k + 180/k."""
    base, plat = [], []
    if k % 2 == 0:
        m = k // 2
        s = 360.0 / m
        db, dp = g['base_half_angle'], g['platform_half_angle']
        angles = []
        for j in range(m):
            angles.append((s * j + db, s * j + s / 2 - dp))
            angles.append((s * (j + 1) - db, s * j + s / 2 + dp))
    else:
        angles = [(360.0 * i / k, 360.0 * i / k + 180.0 / k) for i in range(k)]
    for ab, ap in angles:
        ab, ap = math.radians(ab), math.radians(ap)
        base.append(np.array([g['base_radius'] * math.cos(ab), g['base_radius'] * math.sin(ab), 0.0]))
        plat.append(np.array([g['platform_radius'] * math.cos(ap), g['platform_radius'] * math.sin(ap), 0.0]))
    return base, plat


def _universal(p, name, parent, child, parent_xyz, parent_rpy):
    """A native U joint: about x of the attachment frame (parent side), then about y."""
    _joint(p, name, parent, child, 'universal', parent_xyz=parent_xyz, parent_rpy=parent_rpy,
           axis=(1.0, 0.0, 0.0))
    p[f'joints.{name}.axis2'] = [0.0, 1.0, 0.0]


def ups_platform(k=6, g=UPS, name=None, spherical_closures=False, native=False):
    """Parameter dict of a platform on k UPS legs (see the module docstring); the joints of
    leg i are l<i>_u1, l<i>_u2 (U: about x, then y of a frame whose z is the leg's home
    direction), l<i>_p (prismatic along the leg, q = leg length - 0.8 m), l<i>_s1..s3 (S:
    about x, y, z; the platform-side frame is the leg's home frame, so the three angles are
    0 at home, rounding aside). ``spherical_closures``: the S of legs 1..k-1 is one
    ``spherical`` joint l<i>_s (no helper links, no coordinate); leg 0 keeps its three
    revolute joints, the platform's path through the tree. ``native``: every U and S is one
    ``universal`` / ``spherical`` joint (l<i>_u, l<i>_s), no helper link at all; the only
    coordinates are the legs' prismatic joints."""
    base, plat = ups_layout(k, g)
    home = np.array([0.0, 0.0, g['height']])
    p = {'mechanism.name': name or f'ups_platform_{k}', 'mechanism.gravity': [0.0, 0.0, -9.81],
         'mechanism.base_link': 'ground'}
    links, joints, active = [], [], []
    frames = []
    for i in range(k):
        leg = f'l{i}'
        d = home + plat[i] - base[i]
        d = d / np.linalg.norm(d)
        # the leg's home frame: z along the leg, rounded angles (the IK absorbs the rounding)
        rpy = _r([0.0, math.acos(d[2]), math.atan2(d[1], d[0])])
        frames.append(rpy)
        # lower leg: cylinder 0.4 m, 3 kg, valve block off the axis
        _link(p, f'{leg}_lower', 3.0, (0.004, 0.0, 0.2), (0.0410, 0.0412, 0.0030, 0.0, 0.0002, 0.0))
        # upper leg: rod 0.5 m, 1.5 kg, hanging below the S centre
        _link(p, f'{leg}_upper', 1.5, (0.0, 0.0, -0.25), (0.0315, 0.0315, 0.0006, 0.0, 0.0, 0.0))
        if native:
            _universal(p, f'{leg}_u', 'ground', f'{leg}_lower', base[i], rpy)
            ul, uj = [], [f'{leg}_u']
        else:
            _link(p, f'{leg}_cross', 0.0)
            _joint(p, f'{leg}_u1', 'ground', f'{leg}_cross', parent_xyz=base[i],
                   parent_rpy=rpy, axis=(1.0, 0.0, 0.0))
            _joint(p, f'{leg}_u2', f'{leg}_cross', f'{leg}_lower', axis=(0.0, 1.0, 0.0))
            ul, uj = [f'{leg}_cross'], [f'{leg}_u1', f'{leg}_u2']
        _joint(p, f'{leg}_p', f'{leg}_lower', f'{leg}_upper', 'prismatic',
               parent_xyz=(0.0, 0.0, g['lower_length']), child_xyz=(0.0, 0.0, -g['upper_length']))
        if native or spherical_closures and i > 0:
            _joint(p, f'{leg}_s', f'{leg}_upper', 'platform', 'spherical', child_xyz=plat[i])
            del p[f'joints.{leg}_s.axis']
            sl, sj = [], [f'{leg}_s']
        else:
            sl, sj = _spherical(p, leg, f'{leg}_upper', 'platform', (0.0, 0.0, 0.0),
                                plat[i], rpy)
        links += ul + [f'{leg}_lower', f'{leg}_upper'] + sl
        joints += uj + [f'{leg}_p'] + sj
        active.append(f'{leg}_p')
    if k < 6:
        active = [j for i in range(k) for j in (f'l{i}_u1', f'l{i}_p')]
    # platform: 10 kg plate of radius 0.35 m with a payload flange: full inertia
    _link(p, 'platform', 10.0, (0.01, -0.005, 0.03), (0.31, 0.32, 0.61, 0.004, -0.006, 0.003))
    links.append('platform')
    p['mechanism.links'] = links
    p['mechanism.joints'] = joints
    p['mechanism.active_joints'] = active
    geometry = dict(base=base, platform=plat, frames=frames, home=home, g=g, k=k,
                    spherical_closures=spherical_closures, native=native)
    p['mechanism.initial_positions'] = ups_ik(geometry, home, np.eye(3))
    return p, geometry


def ups_ik(geometry, position, rotation):
    """Every joint coordinate (file order) of the UPS platform at a platform pose."""
    g = geometry['g']
    out = []
    for b, pc, rpy in zip(geometry['base'], geometry['platform'], geometry['frames']):
        rf = rpy_matrix(rpy)
        u = position + rotation @ pc - b
        length = float(np.linalg.norm(u))
        q1, q2, r_leg = universal_angles(rf, u / length)
        s = spherical_angles(r_leg.T @ rotation @ rf)
        extension = length - g['lower_length'] - g['upper_length']
        if geometry.get('native'):           # U and S joints have no coordinate
            out.append(extension)
            continue
        if geometry.get('spherical_closures') and out:
            s = []                           # a spherical joint has no coordinate
        out += [q1, q2, extension, *s]
    return [float(x) for x in out]


# --------------------------------------------------------------------------- delta robot

DELTA = dict(base_radius=0.2, platform_radius=0.05, arm=0.3, rod=0.7, half_width=0.04,
             height=0.7)


def delta_arm_angle(g, phi, pos):
    """Closed-form delta IK: the arm angle (down from horizontal, elbow out) of the leg at
    azimuth phi for the platform centre ``pos`` (world)."""
    x, y, z = rot_z(-phi) @ pos
    a = g['base_radius'] - g['platform_radius'] - x
    k = g['rod'] ** 2 - a * a - g['arm'] ** 2 - y * y - z * z
    rho = math.hypot(a, z)
    return math.atan2(z, a) + math.acos(k / (2.0 * g['arm'] * rho))


def delta_robot(g=DELTA, name='delta_3rus', spherical_closures=False, native=False):
    """Parameter dict of the delta robot (module docstring). Leg i at azimuth 120 i deg:
    l<i>_arm_joint (active, about the leg frame's y: positive = arm down), rods r<i>a, r<i>b
    each with a U (about x then y of a frame whose x is the elbow axis and z the rod's home
    direction) at the elbow and an S at the platform. ``spherical_closures``: the S of every
    rod but r0a is one ``spherical`` joint r<i><s>_s (no helper links, no coordinate).
    ``native``: every U and S is one ``universal`` / ``spherical`` joint (r<i><s>_u,
    r<i><s>_s), no helper link at all; the only coordinates are the three arm angles."""
    p = {'mechanism.name': name, 'mechanism.gravity': [0.0, 0.0, -9.81],
         'mechanism.base_link': 'ground'}
    links, joints, active, legs = [], [], [], []
    home = np.array([0.0, 0.0, -g['height']])
    for i in range(3):
        phi = math.radians(120.0 * i)
        theta = delta_arm_angle(g, phi, home)
        r_arm = rot_z(phi) @ rot_y(theta)
        pivot = g['base_radius'] * np.array([math.cos(phi), math.sin(phi), 0.0])
        arm = f'l{i}_arm'
        # arm: 0.3 m carbon tube with the elbow block, 0.35 kg
        _link(p, arm, 0.35, (0.17, 0.0, 0.002), (1.2e-4, 3.3e-3, 3.3e-3, 0.0, 1.0e-5, 0.0))
        _joint(p, f'l{i}_arm_joint', 'ground', arm, parent_xyz=pivot,
               parent_rpy=[0.0, 0.0, phi], axis=(0.0, 1.0, 0.0))
        links.append(arm)
        joints.append(f'l{i}_arm_joint')
        active.append(f'l{i}_arm_joint')
        rods = []
        for side, sgn in (('a', 1.0), ('b', -1.0)):
            rod = f'r{i}{side}'
            top_local = np.array([g['arm'], sgn * g['half_width'], 0.0])
            plat_local = rot_z(phi) @ np.array([g['platform_radius'], sgn * g['half_width'], 0.0])
            d = home + plat_local - (pivot + r_arm @ top_local)
            d_arm = r_arm.T @ d / np.linalg.norm(d)
            xa = np.array([0.0, 1.0, 0.0])                      # the elbow axis
            za = d_arm - xa * (xa @ d_arm)
            za /= np.linalg.norm(za)
            att = np.column_stack([xa, np.cross(za, xa), za])
            att_rpy = _r(matrix_rpy(att))
            rod_rpy = _r(matrix_rpy(r_arm @ rpy_matrix(att_rpy)))
            # rod: 0.7 m carbon tube with two ball cups, 0.04 kg
            _link(p, rod, 0.04, (0.0, 0.0, 0.35), (1.64e-3, 1.64e-3, 2.0e-6, 0.0, 0.0, 0.0))
            if native:
                _universal(p, f'{rod}_u', arm, rod, top_local, att_rpy)
                ul, uj = [], [f'{rod}_u']
            else:
                _link(p, f'{rod}_cross', 0.0)
                _joint(p, f'{rod}_u1', arm, f'{rod}_cross', parent_xyz=top_local,
                       parent_rpy=att_rpy, axis=(1.0, 0.0, 0.0))
                _joint(p, f'{rod}_u2', f'{rod}_cross', rod, axis=(0.0, 1.0, 0.0))
                ul, uj = [f'{rod}_cross'], [f'{rod}_u1', f'{rod}_u2']
            if native or spherical_closures and rod != 'r0a':
                _joint(p, f'{rod}_s', rod, 'platform', 'spherical',
                       parent_xyz=(0.0, 0.0, g['rod']), child_xyz=plat_local)
                del p[f'joints.{rod}_s.axis']
                sl, sj = [], [f'{rod}_s']
            else:
                sl, sj = _spherical(p, rod, rod, 'platform', (0.0, 0.0, g['rod']),
                                    plat_local, rod_rpy)
            links += ul + [rod] + sl
            joints += uj + sj
            rods.append(dict(top=top_local, plat=plat_local, att=att_rpy, crpy=rod_rpy))
        legs.append(dict(phi=phi, pivot=pivot, rods=rods))
    # platform: 0.5 kg, tool flange below the centre
    _link(p, 'platform', 0.5, (0.0, 0.002, -0.01), (4.8e-4, 4.9e-4, 9.0e-4, 1.0e-6, 0.0, 2.0e-6))
    links.append('platform')
    p['mechanism.links'] = links
    p['mechanism.joints'] = joints
    p['mechanism.active_joints'] = active
    geometry = dict(g=g, legs=legs, home=home, spherical_closures=spherical_closures,
                    native=native)
    p['mechanism.initial_positions'] = delta_ik(geometry, home)
    return p, geometry


def delta_ik(geometry, pos):
    """Every joint coordinate (file order) of the delta robot at platform position ``pos``."""
    g = geometry['g']
    out = []
    for leg in geometry['legs']:
        theta = delta_arm_angle(g, leg['phi'], pos)
        r_arm = rot_z(leg['phi']) @ rot_y(theta)
        out.append(theta)
        if geometry.get('native'):           # U and S joints have no coordinate
            continue
        for rod in leg['rods']:
            d = pos + rod['plat'] - (leg['pivot'] + r_arm @ rod['top'])
            q1, q2, r_rod = universal_angles(r_arm @ rpy_matrix(rod['att']), d / np.linalg.norm(d))
            s = spherical_angles(r_rod.T @ rpy_matrix(rod['crpy']))
            if geometry.get('spherical_closures') and len(out) > 3:
                s = []                       # a spherical joint has no coordinate (not r0a)
            out += [q1, q2, *s]
    return [float(x) for x in out]


# --------------------------------------------------------------------------- four-bar chain

def four_bar_chain(n, crank=0.3, span=0.5, theta=1.2):
    """n parallelogram loops in a row in the x-y plane (gravity -y): rockers k = 0..n of
    length ``crank`` pivoted on the ground at x = span k (rocker 0 is the driven crank), and
    couplers k = 1..n of length ``span`` from the tip of rocker k-1 to the tip of rocker k.
    Loop k shares rocker k-1 with loop k-1. All rockers at ``theta`` (rad)."""
    p = {'mechanism.name': f'four_bar_chain_{n}', 'mechanism.gravity': [0.0, -9.81, 0.0],
         'mechanism.base_link': 'ground'}
    links, joints, q0 = [], [], []
    bar = lambda m, ln: (m, (ln / 2, 0.0, 0.0), (1e-5, m * ln * ln / 12, m * ln * ln / 12, 0.0, 0.0, 0.0))  # noqa: E731
    for k in range(n + 1):
        _link(p, f'rocker{k}', *bar(0.3, crank))
        _joint(p, f'r{k}', 'ground', f'rocker{k}', parent_xyz=(span * k, 0.0, 0.0))
        links.append(f'rocker{k}')
        joints.append(f'r{k}')
        q0.append(theta)
        if k == 0:
            continue
        _link(p, f'coupler{k}', *bar(0.5, span))
        _joint(p, f'c{k}', f'rocker{k - 1}', f'coupler{k}', parent_xyz=(crank, 0.0, 0.0))
        _joint(p, f'e{k}', f'coupler{k}', f'rocker{k}', parent_xyz=(span, 0.0, 0.0),
               child_xyz=(crank, 0.0, 0.0))
        links.append(f'coupler{k}')
        joints += [f'c{k}', f'e{k}']
        q0 += [-theta, theta]
    p['mechanism.links'] = links
    p['mechanism.joints'] = joints
    p['mechanism.active_joints'] = ['r0']
    p['mechanism.initial_positions'] = q0
    return p


# --------------------------------------------------------------------------- YAML output

def _fmt(v):
    if isinstance(v, str):
        return v
    if isinstance(v, (list, tuple)):
        return '[' + ', '.join(_fmt(x) for x in v) + ']'
    text = repr(float(v))
    if 'e' in text and '.' not in text:
        text = text.replace('e', '.0e')         # 1.0e-05: YAML 1.1 reads 1e-05 as a string
    return text


def write_yaml(params, path, header=''):
    """Write a parameter dict as a ROS 2 parameter file in the layout of config/*.yaml."""
    lines = [header.rstrip('\n')] if header else []
    lines += ['/**:', '  ros__parameters:', '    mechanism:']
    for key in ('name', 'gravity', 'base_link', 'links', 'joints', 'active_joints',
                'initial_positions', 'torque_weights'):
        if f'mechanism.{key}' in params:
            lines.append(f'      {key}: {_fmt(params["mechanism." + key])}')
    lines.append('    links:')
    for ln in params['mechanism.links']:
        lines.append(f'      {ln}:')
        for key in ('mass', 'com', 'inertia'):
            lines.append(f'        {key}: {_fmt(params[f"links.{ln}.{key}"])}')
    lines.append('    joints:')
    for jn in params['mechanism.joints']:
        lines.append(f'      {jn}:')
        for key in ('type', 'parent', 'child', 'parent_xyz', 'parent_rpy', 'child_xyz',
                    'child_rpy', 'axis', 'axis2'):
            if f'joints.{jn}.{key}' in params:
                lines.append(f'        {key}: {_fmt(params[f"joints.{jn}.{key}"])}')
    with open(path, 'w', encoding='utf-8') as f:
        f.write('\n'.join(lines) + '\n')


# --------------------------------------------------------------------------- example files

STEWART_HEADER = """\
# Stewart-Gough platform 6-UPS (six degrees of freedom, six actuated legs). Written by
# bench/mechanism_family.py (ups_platform(6); `--write-configs` rewrites this file).
# Each leg i = 0..5: ground -U- lower leg (cylinder) -P- upper leg (rod) -S- platform.
#   U  l<i>_u1 (about x), l<i>_u2 (about y) through the MASSLESS cross l<i>_cross, at the
#      base point b_i on a circle of radius 0.5 m (z = 0). The attachment frame of l<i>_u1
#      (parent_rpy [0, 0.4239, yaw_i]) has its z axis along the leg's home direction, so
#      both U angles are near 0 and the joint would lock only with the leg along that
#      frame's x axis, 90 degrees away (over the test motion |U angle| < 0.1 rad).
#   P  l<i>_p, ACTIVE, along the leg (z): q = leg length (U centre to S centre) - 0.8 m,
#      0.1326 m at home, 0.05 to 0.22 m over the test motion.
#   S  l<i>_s1 (x), l<i>_s2 (y), l<i>_s3 (z) through the MASSLESS helper links l<i>_sa,
#      l<i>_sb, at the platform point c_i on a circle of radius 0.3 m in the platform frame.
#      The platform-side attachment of l<i>_s3 has child_rpy = the leg's home frame, so the
#      relative rotation is the identity at home: the middle angle l<i>_s2 stays within
#      +-0.16 rad over the test motion, far from the gimbal lock at +-pi/2.
# Base points in pairs at 120 j +- 5 degrees, platform points at 120 j + 60 -+ 5 degrees
# (the usual zig-zag, legs of a pair meeting near one platform edge); platform frame at
# height 0.85 m at home, legs 0.9326 m long, 24 degrees from vertical.
# Masses: lower leg 3 kg (COG 0.2 m up the leg, valve block off the axis), upper leg 1.5 kg,
# platform 10 kg with a full inertia (products of inertia, COG off centre).
# DOF: 36 joint freedoms (6 x (2 + 1 + 3)); 31 moving links, so 36 - 31 = 5 loops of 6
# equations: 36 - 30 = 6, the platform's six. The U joints stop the legs spinning about their
# own axes, so no passive joint is idle and the 6 prismatic joints determine the motion.
# Test motion (test/trajectories.py): platform x = 0.04 sin(pi t), y = 0.03 (1 - cos(pi t)),
# z = 0.85 + 0.05 sin(2 pi t) m, roll 0.08 sin(pi t), pitch 0.06 (1 - cos(pi t)), yaw
# 0.10 sin(2 pi t) rad (R = Rz Ry Rx), t in [0, 2] s; leg extensions and their exact
# derivatives by inverse kinematics. Closure condition number below 130 along it.
"""

DELTA_HEADER = """\
# Delta robot (Clavel), three translational degrees of freedom. Written by
# bench/mechanism_family.py (delta_robot(); `--write-configs` rewrites this file).
# Leg i = 0..2 at azimuth 120 i degrees:
#   l<i>_arm_joint  ground - l<i>_arm, ACTIVE, at radius 0.2 m, about the leg frame's y
#               axis (tangential): positive angles move the 0.3 m upper arm down.
#   forearm: a PARALLELOGRAM of two 0.7 m rods r<i>a, r<i>b, attached at the elbow at
#               +-0.04 m along the elbow axis and at the platform at radius 0.05 m, +-0.04 m
#               tangentially. Equal rods with parallel end bars keep the platform's
#               orientation: the platform only translates.
#   each rod: a U at the elbow (r<i><s>_u1 about x, r<i><s>_u2 about y, through the
#               MASSLESS cross r<i><s>_cross; the first axis is the elbow axis, the
#               frame's z the rod's home direction, so the U would lock only with the rod
#               along the elbow axis) and an S at the platform (r<i><s>_s1, _s2, _s3 about
#               x, y, z through the MASSLESS helpers r<i><s>_sa, r<i><s>_sb; the platform
#               side's child_rpy is the rod's home rotation, so the middle angle is 0 at
#               home and within +-0.18 rad over the test motion).
# Why U-S rods and not the real robot's ball joints at both ends: a rod between two
# spherical joints can spin about its own axis, an idle freedom the parameter file cannot
# leave free (the actuators must determine every joint). A U at one end removes just that
# spin and constrains nothing else, so the parallelogram works as in the real robot.
# Why a parallelogram and not Tsai's 3-RUU single rod: it is the delta robot as built,
# and the mechanism of the issue's measurements (33 joints, 5 loops).
# DOF: 3 arms + 6 rods x (2 + 3) = 33 joint freedoms; 28 moving links, so 5 loops of 6
# equations: 33 - 30 = 3.
# Masses: arm 0.35 kg, rods 0.04 kg each, platform 0.5 kg (tool flange below the centre).
# Test motion (test/trajectories.py): platform x = 0.08 sin(2 pi t), y = 0.06 (1 - cos(pi t)),
# z = -0.70 + 0.05 sin(2 pi t) m, t in [0, 2] s; arm angles (0.18 to 0.8 rad) by the
# closed-form delta IK with exact derivatives. Closure condition number below 700 along it.
"""


STEWART_SPHERICAL_HEADER = """\
# Stewart-Gough platform 6-UPS with NATIVE SPHERICAL AND UNIVERSAL JOINTS: the mechanism of
# config/stewart_6ups.yaml with every U written as one `type: universal` joint (l<i>_u:
# about x of the attachment frame, whose z is the leg's home direction, then about y) and
# every S as one `type: spherical` joint (l<i>_s: the upper leg's origin, the S centre, at
# the platform point c_i), instead of revolute joints through massless helper links.
# Written by bench/mechanism_family.py (ups_platform(6, native=True); `--write-configs`
# rewrites this file).
# Spherical and universal joints have no entry in initial_positions or any JointState and no
# angle that could lock. The solver puts the U joints and one S joint into its spanning tree
# (hidden coordinates: two angles per U, a quaternion for the S) and closes the other five
# loops with the S joints (3 equations each); docs/mechanism.md says how. The platform is
# described in its home orientation (frame parallel to the base), where the solver starts it.
# Same masses, geometry and test motion as stewart_6ups.yaml, hence the same torques.
# DOF: 6 prismatic joints + 6 U x 2 + one S quaternion (4, and |q| = 1) = 22 coordinates;
# 5 loops of 3 equations + 1: 22 - 16 = 6.
"""


DELTA_SPHERICAL_HEADER = """\
# Delta robot with NATIVE SPHERICAL AND UNIVERSAL JOINTS: the mechanism of
# config/delta_3rus.yaml with every rod's elbow U written as one `type: universal` joint
# (r<i><s>_u: about the elbow axis, then about y) and its platform S as one
# `type: spherical` joint (r<i><s>_s: the rod's far end at its platform point), instead of
# revolute joints through massless helper links. Written by bench/mechanism_family.py
# (delta_robot(native=True); `--write-configs` rewrites this file).
# Spherical and universal joints have no entry in initial_positions or any JointState and no
# angle that could lock: initial_positions holds the three arm angles only. The solver puts
# the U joints and one S joint into its spanning tree (hidden coordinates) and closes the
# other five loops with the S joints; docs/mechanism.md says how.
# Same masses, geometry and test motion as delta_3rus.yaml, hence the same torques.
# DOF: 3 arm joints + 6 U x 2 + one S quaternion (4, and |q| = 1) = 19 coordinates; 5 loops
# of 3 equations + 1: 19 - 16 = 3.
"""


def write_examples():
    """Rewrite config/stewart_6ups.yaml and config/delta_3rus.yaml from the generators."""
    write_yaml(ups_platform(6, name='stewart_6ups')[0],
               os.path.join(REPO, 'config', 'stewart_6ups.yaml'), STEWART_HEADER)
    write_yaml(delta_robot()[0], os.path.join(REPO, 'config', 'delta_3rus.yaml'), DELTA_HEADER)
    write_yaml(ups_platform(6, name='stewart_6ups_spherical', native=True)[0],
               os.path.join(REPO, 'config', 'stewart_6ups_spherical.yaml'),
               STEWART_SPHERICAL_HEADER)
    write_yaml(delta_robot(name='delta_3rus_spherical', native=True)[0],
               os.path.join(REPO, 'config', 'delta_3rus_spherical.yaml'), DELTA_SPHERICAL_HEADER)


# --------------------------------------------------------------------------- script mode

def members(family):
    out = []
    if family in ('ups', 'all'):
        out += [(f'UPS platform, {k} legs', lambda k=k: ups_platform(k)[0]) for k in (3, 6, 8, 10, 12)]
    if family in ('delta', 'all'):
        out.append(('delta robot (3 legs)', lambda: delta_robot()[0]))
    if family in ('chain', 'all'):
        out += [(f'four-bar chain, {n} loops', lambda n=n: four_bar_chain(n)) for n in range(1, 9)]
    return out


def _peak_mb():
    with open('/proc/self/status') as f:
        return next(int(x.split()[1]) for x in f if x.startswith('VmHWM')) / 1024.0


def measure(index, family):
    """Load and trace one member in this (fresh) process; returns a dict of figures."""
    import cog_id_ros
    from cog_id_ros.core.native import kernels
    label, make = members(family)[index]
    params = make()
    rss0 = _peak_mb()
    t0 = time.perf_counter()
    mech = cog_id_ros.Mechanism.from_parameters(params)
    t1 = time.perf_counter()
    # the kernels of what is solved: S joints written as three revolutes through massless
    # links are solved as spherical joints (core/kinematics/spherical_chains.py)
    ops = kernels.kernels_for(mech.solver_mechanism, 'python').operations
    t2 = time.perf_counter()
    return dict(label=label, joints=len(mech.joints), loops=len(mech.joints) - len(mech.links),
                dof=mech.dof, active=len(mech.active_joints), ops=ops, load=t1 - t0,
                trace=t2 - t1, peak=_peak_mb() - rss0,
                solved=mech.solver_mechanism.n_coordinates)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--max-joints', type=int, default=80,
                    help='skip members with more joints than this (tracing large ones is slow)')
    ap.add_argument('--family', choices=('ups', 'delta', 'chain', 'all'), default='all')
    ap.add_argument('--write-configs', action='store_true',
                    help='rewrite config/stewart_6ups.yaml and config/delta_3rus.yaml, then stop')
    ap.add_argument('--member', type=int, default=None, help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.write_configs:
        write_examples()
        return
    if args.member is not None:            # one member, in a process of its own
        print(json.dumps(measure(args.member, args.family)))
        return
    shown = sys.argv[1:] if argv is None else argv
    print('command: ' + ' '.join([os.path.relpath(sys.executable, REPO), 'bench/mechanism_family.py'] + shown))
    print(f'date: {datetime.datetime.now().isoformat(timespec="seconds")}')
    head = ('member', 'joints', 'loops', 'DOF', 'active', 'solved coordinates',
            'prediction ops', 'closure ops',
            'dynamics ops', 'load ms', 'trace s', 'peak RSS +MB')
    print('| ' + ' | '.join(head) + ' |')
    print('|' + '---|' * len(head))
    skipped = []
    for index, (label, make) in enumerate(members(args.family)):
        n_j = len(make()['mechanism.joints'])
        if n_j > args.max_joints:
            skipped.append(f'{label} ({n_j} joints)')
            continue
        out = subprocess.run([sys.executable, os.path.abspath(__file__), '--family', args.family,
                              '--member', str(index)], capture_output=True, text=True)
        if out.returncode != 0:
            print(f'| {label} | {n_j} | failed: {out.stderr.strip().splitlines()[-1]} |')
            continue
        m = json.loads(out.stdout.strip().splitlines()[-1])
        ops = m['ops']
        row = (label, m['joints'], m['loops'], m['dof'], m['active'], m['solved'],
               f'{ops.get("prediction", 0):,}', f'{ops.get("closure", 0):,}',
               f'{ops.get("dynamics", 0):,}', f'{m["load"] * 1e3:.1f}', f'{m["trace"]:.2f}',
               f'{m["peak"]:.0f}')
        print('| ' + ' | '.join(str(x) for x in row) + ' |', flush=True)
    print('ops: float operations of the traced straight-line kernels '
          "(kernels_for(mech.solver_mechanism, 'python').operations: S joints written as "
          'three revolutes through massless links solved as spherical joints); load: '
          "Mechanism.from_parameters; trace: kernels_for(...); peak RSS: growth of the "
          "process's peak over both.")
    if skipped:
        print(f'skipped (more than --max-joints {args.max_joints} joints): ' + ', '.join(skipped))


if __name__ == '__main__':
    main()
