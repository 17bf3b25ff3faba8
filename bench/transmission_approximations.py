"""How far the usual transmission approximations are from the exact motor torques, over a
walking-like joint-space motion (docs/transmission.md prints the table).

    .venv/bin/python bench/transmission_approximations.py

For the parallel ankle, the four-bar knee and the TALOS-like leg, a motion of the joint
space (mechanism.joint_space) at 1 Hz, and three ways to the motors' torques:

  (a) constant ratio   tau_m = J(q0)^T tau_q: J frozen at the assembled (home) pose, tau_q
                       the exact joint-space efforts (the whole mechanism's)
  (b) massless linkage tau_m = J(q)^T tau_q_serial: J at each pose, tau_q_serial the
                       joint-space efforts of the serial chain alone (the rods' and cranks'
                       mass and inertia set to 0: the same mechanism loaded with them 0)
  (c) exact            Transmission.torques (= InverseDynamics.torques(space='joint'))

Per example: the largest and the RMS error of (a) and (b) over every sample and motor,
relative to the exact peak |tau_m|. Prints a markdown table.
"""
import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), '..'))
import cog_id_ros  # noqa: E402
from cog_id_ros.description.params_file import (  # noqa: E402
    DEFAULT_NODE_NAME,
    load_params_file,
)

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
SAMPLES = 401           # over one period (1 s)
W = 2.0 * math.pi       # 1 Hz

#: per example: parameter file, the linkage's links (made massless for (b)), and the motion
#: of each joint-space joint as (offset from home, amplitude, phase, shape): 'sin' is
#: offset + a sin(wt + phase), 'bend' offset + a (1 - cos(wt)) (a knee 0 .. 2a)
EXAMPLES = {
    'parallel ankle': ('config/parallel_ankle.yaml',
                       ['rod_left', 'rod_right', 'crank_left', 'crank_right'],
                       {'ankle_pitch': (0.0, 0.3, 0.0, 'sin'),
                        'ankle_roll': (0.0, 0.15, 0.5 * math.pi, 'sin')}),
    'four-bar knee': ('config/four_bar_knee.yaml', ['crank', 'coupler'],
                      {'knee': (0.0, 0.35, 0.0, 'bend')}),
    'TALOS-like leg': ('config/talos_like_leg.yaml', ['rod_1', 'rod_2', 'moteur'],
                       {'motor_hip_y': (0.0, 0.3, 0.0, 'sin'),
                        'motor_knee': (0.0, 0.35, 0.0, 'bend'),
                        'free_ankle': (0.0, 0.3, 0.0, 'sin'),
                        'motor_ankle': (0.0, 0.15, 0.5 * math.pi, 'sin')}),
}


def joint_motion(mech, spec, n=SAMPLES):
    """(q, qd, qdd) (n, D) of the joint space: each joint about its assembled position."""
    t = np.linspace(0.0, 1.0, n)
    home = np.array([mech.assembled_positions[mech.joint_index[j]] for j in mech.joint_space])
    q, qd, qdd = (np.tile(home, (n, 1)), np.zeros((n, len(home))), np.zeros((n, len(home))))
    for k, name in enumerate(mech.joint_space):
        if name not in spec:
            continue
        offset, a, phase, shape = spec[name]
        x = W * t + phase
        if shape == 'sin':
            q[:, k] += offset + a * np.sin(x)
            qd[:, k] = a * W * np.cos(x)
            qdd[:, k] = -a * W * W * np.sin(x)
        else:
            q[:, k] += offset + a * (1.0 - np.cos(x))
            qd[:, k] = a * W * np.sin(x)
            qdd[:, k] = a * W * W * np.cos(x)
    return q, qd, qdd


def massless(path, links, workdir):
    """The mechanism of ``path`` with ``links``' mass and inertia 0 (native form: their
    links.* entries; URDF form: a copy of the URDF with their <inertial> zeroed)."""
    params = load_params_file(os.path.join(ROOT, path), DEFAULT_NODE_NAME)
    base = os.path.dirname(os.path.join(ROOT, path))
    urdf = params.get('mechanism.urdf_file')
    if not urdf:
        for link in links:
            params[f'links.{link}.mass'] = 0.0
            params[f'links.{link}.inertia'] = [0.0] * 6
        return cog_id_ros.Mechanism.from_parameters(params, base_dir=base)
    tree = ET.parse(os.path.join(base, urdf))
    for link in tree.getroot().iter('link'):
        if link.get('name') in links:
            inertial = link.find('inertial')
            inertial.find('mass').set('value', '0')
            for key in ('ixx', 'ixy', 'ixz', 'iyy', 'iyz', 'izz'):
                inertial.find('inertia').set(key, '0')
    tree.write(os.path.join(workdir, 'massless.urdf'))
    params['mechanism.urdf_file'] = os.path.join(workdir, 'massless.urdf')
    loops = params.get('mechanism.loop_closure_file')
    if loops:
        params['mechanism.loop_closure_file'] = os.path.join(base, loops)
    return cog_id_ros.Mechanism.from_parameters(params, base_dir=workdir)


def errors(name, path, links, spec, workdir):
    mech = cog_id_ros.Mechanism.from_params_file(os.path.join(ROOT, path))
    q, qd, qdd = joint_motion(mech, spec)
    tr = cog_id_ros.Transmission(mech)
    exact = tr.torques(q, qd, qdd)                                   # (c)
    tau_q = tr.joints.torques(q, qd, qdd)                            # exact joint-space
    home = np.array([mech.assembled_positions[j] for j in mech.active_index])
    j0 = tr.jacobian(home)
    constant = tau_q @ j0                                            # (a): J(q0)^T tau_q
    light = massless(path, links, workdir)
    serial = cog_id_ros.Transmission(light).torques(q, qd, qdd)      # (b)
    peak = float(np.abs(exact).max())
    row = {'example': name, 'motors': len(mech.active_joints), 'peak': peak,
           'linkage_mass': sum(mech.link_mass[mech.links.index(k)] for k in links),
           'moving_mass': float(sum(mech.link_mass))}
    for key, approx in (('a', constant), ('b', serial)):
        err = np.abs(approx - exact)
        row[key + '_max'] = float(err.max()) / peak
        row[key + '_rms'] = float(np.sqrt(np.mean(err ** 2))) / peak
        own = err.max(axis=0) / np.abs(exact).max(axis=0)        # each motor by its own peak
        row[key + '_own'] = (float(own.max()), mech.active_joints[int(np.argmax(own))])
    # the motion's joint range, for the table
    row['range'] = ', '.join(f'{j} {q[:, k].min():+.2f}..{q[:, k].max():+.2f}'
                             for k, j in enumerate(mech.joint_space) if j in spec)
    return row


def main():
    rows = []
    with tempfile.TemporaryDirectory() as workdir:
        for name, (path, links, spec) in EXAMPLES.items():
            rows.append(errors(name, path, links, spec, workdir))
    print('| example (motion at 1 Hz, rad) | exact peak motor torque | linkage / moving mass | '
          '(a) constant ratio: max, RMS | (b) massless linkage: max, RMS | worst motor by its '
          'own peak: (a), (b) |')
    print('|---|---|---|---|---|---|')
    for r in rows:
        print(f"| {r['example']} ({r['range']}) | {r['peak']:.4g} N m | "
              f"{r['linkage_mass']:.3g} / {r['moving_mass']:.3g} kg | "
              f"{100 * r['a_max']:.2f} %, {100 * r['a_rms']:.2f} % | "
              f"{100 * r['b_max']:.2f} %, {100 * r['b_rms']:.2f} % | "
              f"{100 * r['a_own'][0]:.2f} % ({r['a_own'][1]}), "
              f"{100 * r['b_own'][0]:.2f} % ({r['b_own'][1]}) |")
    print('\nerrors relative to the exact peak motor torque of each example (every sample, '
          f'every motor; {SAMPLES} samples over 1 s); the last column: the motor whose error '
          'is largest against its own peak')


if __name__ == '__main__':
    main()
