"""cog_id_ros.core: closed-link inverse dynamics by per-link COG Jacobians (numpy only).

Where the paper's equations live:
  eq. (1)-(7)  pipeline.py        inverse_dynamics(): the whole method at a closed pose, in
                                  the paper's order; equation_of_motion(): H and B
  eq. (1)-(4)  cog_jacobian.py    g_i, G_i = dg_i/dtheta_m, Gdot_i thetadot_m
  eq. (5)      newton_euler.py    F_i = M_i qddot_i + b_i
  eq. (7)^-1   forward_dynamics.py  the accelerations the efforts produce (H, B solved)
and what they stand on: closure.py (loop equations, Newton), joint_motion.py (actuator to
joint rates), kinematics.py (tree, poses, twists), joints.py (each kind of joint's part in
them), spatial.py / lane_linalg.py (algebra). mechanism.py reads a mechanism; assembly.py
and degrees_of_freedom.py analyse it at load.
Who runs them: sample_solve.py (one sample: continuation, Newton, checks) calling the
kernels of kernels.py; batch.py (N samples on arrays); actuator_space.py (the solver of
actuator space); inputs.py (what it accepts); forward_solve.py (forward dynamics of one
sample or N); transmission.py (joint space: the map between the joints a controller
commands and the motors); inverse_dynamics.py (the solver users call, InverseDynamics, in
either space); simulation.py (Simulation: RK4 on the independent coordinates, the loops
closed at every stage).

The modules are in concept folders, each importing only those before it: linalg/
(spatial algebra, lanes), kinematics/ (tree, joints, parameters), closure/ (loop
equations, Newton, continuation, joint rates), model/ (mechanism, assembly, its joint
space checked), dynamics/ (COG Jacobians, Newton-Euler, pipeline.py, forward dynamics),
native/ (kernels and their backends), solve/ (the solvers of actuator space),
transmission/ (joint space and actuator space), simulation/, api/ (InverseDynamics).
errors.py and value_types.py stay here, below them all.
"""
from .api.inverse_dynamics import Evaluation, InverseDynamics
from .errors import (
    REASONS,
    ClosureError,
    CogIdError,
    MechanismConfigError,
    SetpointError,
    SingularConfigurationError,
)
from .model.mechanism import AssemblyWarning, Mechanism
from .simulation.simulation import Simulation
from .transmission.transmission import Transmission

__all__ = ['REASONS', 'AssemblyWarning', 'ClosureError', 'CogIdError', 'Evaluation',
           'InverseDynamics', 'Mechanism',
           'MechanismConfigError', 'SetpointError', 'Simulation', 'SingularConfigurationError',
           'Transmission']
