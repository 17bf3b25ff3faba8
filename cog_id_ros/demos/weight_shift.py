"""A biped whose legs are linkages stands and shifts its weight from one foot to the other.

    python -m cog_id_ros.demos.weight_shift [--output out/weight_shift.png] [--samples 81]

The robot is config/digit_biped.yaml (a Digit-like biped of the published
example-parallel-robots collection: twelve motors, six loops, a floating pelvis, two
flat 6d feet). Standing on both feet at its assembled pose, the pelvis sways sideways
(``SWAY`` m either way, one period in ``DURATION`` s) while both feet stay where they are
on the ground: at every sample the twelve motor positions that keep the feet still are
solved (Newton on the feet's poses, a finite-difference Jacobian), their rates and
accelerations differentiated, and ``whole_body_torques`` gives the motor torques and the
two feet's wrenches. The feet's moments are weighted ``MOMENT_WEIGHT`` times their forces
(``wrench_weights``): a flat foot carries load mostly as force, so the vertical forces
follow the centre of mass from one foot to the other.

Writes the motor torques and the feet's vertical forces over the motion to a PNG and
prints a table. Exit status: 0 the forces balance the weight at every sample (within 1 %
of it) and the load moved from one foot to the other; 1 they do not; 2 the config files
are in none of the places looked in.
"""
import argparse
import os
import sys

import numpy as np

from .. import InverseDynamics, Mechanism
from .paper_four_bar import ConfigNotFound, config_dir

SWAY = 0.085         # m, the pelvis's sideways excursion either way
DURATION = 4.0       # s, one sway: centre, over the left foot, over the right, centre
MOMENT_WEIGHT = 1e4
CONTACTS = ['right_foot', 'left_foot']


def foot_poses(solver, theta):
    """{contact: (position, rotation)} of the feet's contact frames in the pelvis frame."""
    mech = solver.mechanism
    positions, rotations = solver.cog_poses(theta)
    out = {}
    for name in CONTACTS:
        c = mech.contacts[name]
        com = np.array(mech.link_com[c.link])
        out[name] = (positions[c.link] + rotations[c.link] @ (np.array(c.xyz) - com),
                     rotations[c.link] @ np.array(c.rotation).reshape(3, 3))
    return out


def _residual(solver, theta, targets):
    poses = foot_poses(solver, theta)
    rows = []
    for name in CONTACTS:
        (p, r), (pt, rt) = poses[name], targets[name]
        e = rt.T @ r
        rows += [p - pt, 0.5 * np.array([e[2, 1] - e[1, 2], e[0, 2] - e[2, 0], e[1, 0] - e[0, 1]])]
    return np.concatenate(rows)


def keep_feet(solver, theta, targets, tol=1e-11, h=1e-7):
    """The motor positions near ``theta`` that put the feet at ``targets`` (pelvis frame)."""
    for _ in range(20):
        r = _residual(solver, theta, targets)
        if np.abs(r).max() < tol:
            return theta
        jac = np.column_stack([(_residual(solver, theta + h * e, targets) - r) / h
                               for e in np.eye(len(theta))])
        theta = theta - np.linalg.solve(jac, r)
    raise RuntimeError(f'the feet could not be kept still (residual {np.abs(r).max():.3g})')


def weight_shift(samples=81):
    """(t, base poses (N, 7), base twists (N, 6), accelerations (N, 6), theta (N, M),
    WholeBodyEfforts, mechanism) of the sway."""
    mech = Mechanism.from_params_file(os.path.join(config_dir(), 'digit_biped.yaml'))
    solver = InverseDynamics(mech)
    theta0 = np.array([mech.assembled_positions[j] for j in mech.active_index])
    feet = foot_poses(solver, theta0)
    height = -np.mean([feet[name][0][2] for name in CONTACTS])    # soles on z = 0
    t = np.linspace(0.0, DURATION, samples)
    omega = 2.0 * np.pi / DURATION
    y, vy, ay = SWAY * np.sin(omega * t), SWAY * omega * np.cos(omega * t), \
        -SWAY * omega ** 2 * np.sin(omega * t)
    theta = []
    for k in range(samples):      # the pelvis moves by (0, y, 0): the feet move by -y in it
        targets = {name: (p - np.array([0.0, y[k], 0.0]), r) for name, (p, r) in feet.items()}
        theta.append(keep_feet(solver, theta[-1] if theta else theta0, targets))
    theta = np.array(theta)
    thd = np.gradient(theta, t, axis=0, edge_order=2)
    thdd = np.gradient(thd, t, axis=0, edge_order=2)
    zeros = np.zeros(samples)
    pose = np.column_stack([zeros, y, zeros + height, zeros, zeros, zeros, zeros + 1.0])
    twist = np.column_stack([zeros, vy, zeros, zeros, zeros, zeros])
    accel = np.column_stack([zeros, ay, zeros, zeros, zeros, zeros])
    weights = [1.0, 1.0, 1.0, MOMENT_WEIGHT, MOMENT_WEIGHT, MOMENT_WEIGHT]
    out = InverseDynamics(mech).whole_body_torques(
        pose, twist, accel, theta, thd, thdd, contacts=CONTACTS,
        wrench_weights=dict.fromkeys(CONTACTS, weights))
    return t, pose, theta, out, mech


def plot(path, t, pose, out, mech):
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    fig, (top, middle, bottom) = plt.subplots(3, 1, figsize=(10, 9), sharex=True,
                                              gridspec_kw={'height_ratios': [1, 2, 2]})
    top.plot(t, 1000.0 * pose[:, 1], color='k')
    top.set_ylabel('pelvis y (mm)')
    top.set_title('digit_biped sways over one foot, then the other (both feet on the ground)')
    for a, name in enumerate(mech.active_joints):
        middle.plot(t, out.efforts[:, a], label=name, linestyle='-' if a < 6 else '--')
    middle.set_ylabel('motor torque (N m)')
    middle.legend(fontsize=7, loc='upper left', bbox_to_anchor=(1.01, 1.0))
    weight = -(mech.base_mass + sum(mech.link_mass)) * mech.gravity[2]
    for name in CONTACTS:
        bottom.plot(t, out.wrenches[name][:, 2], label=f'{name} fz')
    bottom.axhline(weight, color='grey', linestyle=':', label='weight')
    bottom.set_ylabel('vertical force (N)')
    bottom.set_xlabel('time (s)')
    bottom.legend(fontsize=8, loc='upper left', bbox_to_anchor=(1.01, 1.0))
    fig.tight_layout()
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    parser.add_argument('--output', default=os.path.join('out', 'weight_shift.png'))
    parser.add_argument('--samples', type=int, default=81)
    args = parser.parse_args(argv)
    try:
        t, pose, theta, out, mech = weight_shift(args.samples)
    except ConfigNotFound as exc:
        print(f'weight_shift: {exc}', file=sys.stderr)
        return 2
    plot(args.output, t, pose, out, mech)
    weight = -(mech.base_mass + sum(mech.link_mass)) * mech.gravity[2]
    fz = np.column_stack([out.wrenches[name][:, 2] for name in CONTACTS])
    print(f'{"t (s)":>6} {"pelvis y (mm)":>14} {"right fz (N)":>13} {"left fz (N)":>12} '
          f'{"largest torque (N m)":>21}')
    for k in range(0, len(t), max(1, len(t) // 16)):
        print(f'{t[k]:6.2f} {round(1000 * pose[k, 1], 1) + 0.0:14.1f} {fz[k, 0]:13.2f} '
              f'{fz[k, 1]:12.2f} '
              f'{np.abs(out.efforts[k]).max():21.3f}')
    print(f'weight {weight:.2f} N; figure: {args.output}')
    balanced = np.abs(fz.sum(axis=1) - weight).max() < 0.01 * weight + \
        (mech.base_mass + sum(mech.link_mass)) * SWAY * (2 * np.pi / DURATION) ** 2
    shifted = fz[:, 0].max() > 0.75 * weight and fz[:, 1].max() > 0.75 * weight
    if not (balanced and shifted and np.abs(out.base_wrench).max() < 1e-6 * weight):
        print('weight_shift: the feet do not carry the robot as expected', file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
