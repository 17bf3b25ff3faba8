"""The gyroscopic term w x I w of eq. (5) against the Pinocchio reference.

In a one-DOF mechanism it never reaches the actuator torque (each link's G_i column is
parallel to its motion and w . (w x I w) = 0), so the example mechanisms cannot see it;
a spatial two-DOF pan-tilt with an unbalanced, asymmetric head does.
"""
import numpy as np
from pinocchio_reference import Oracle

import cog_id_ros

PAN_TILT = """
/**:
  ros__parameters:
    mechanism:
      name: pan_tilt
      links: [yoke, head]
      joints: [pan, tilt]
      active_joints: [tilt, pan]           # not in joints order, on purpose
    links:
      yoke:
        mass: 0.8
        com: [0.01, 0.0, 0.05]
        inertia: [2.0e-3, 3.0e-3, 1.5e-3, 1.0e-4, 0.0, 2.0e-4]
      head:
        mass: 1.2
        com: [0.05, 0.02, 0.01]
        inertia: [4.0e-3, 9.0e-3, 7.0e-3, 5.0e-4, -3.0e-4, 2.0e-4]
    joints:
      pan:
        type: revolute
        parent: ground
        child: yoke
        parent_xyz: [0.0, 0.0, 0.3]
      tilt:
        type: revolute
        parent: yoke
        child: head
        parent_xyz: [0.0, 0.0, 0.1]
        parent_rpy: [1.5707963267948966, 0.0, 0.0]
        axis: [0, 0, 1]
"""


def test_gyroscopic_torques_match_the_reference(tmp_path):
    path = tmp_path / 'pan_tilt.yaml'
    path.write_text(PAN_TILT)
    solver = cog_id_ros.InverseDynamics(cog_id_ros.Mechanism.from_params_file(str(path)))
    oracle = Oracle(str(path))
    t = np.linspace(0.0, 2.0, 41)
    tilt, pan = 0.3 * np.sin(2 * t), 2.0 * t + 0.5 * np.sin(3 * t)
    q = np.column_stack([tilt, pan])
    qd = np.column_stack([0.6 * np.cos(2 * t), 2.0 + 1.5 * np.cos(3 * t)])
    qdd = np.column_stack([-1.2 * np.sin(2 * t), -4.5 * np.sin(3 * t)])
    tau = solver.torques(q, qd, qdd)
    q_all = solver.solve_positions(q)
    reference = np.array([oracle.active_torques(q_all[k], qd[k], qdd[k]) for k in range(len(t))])
    assert np.max(np.abs(tau - reference)) < 1e-8 * np.max(np.abs(reference))
    # and the term is really exercised here: without it the torques would differ visibly
    no_spin = np.array([oracle.active_torques(q_all[k], np.zeros(2), qdd[k]) for k in range(len(t))])
    assert np.max(np.abs(reference - no_spin)) > 1e-2 * np.max(np.abs(reference))
