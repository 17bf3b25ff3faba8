"""cog_id_ros: closed-link inverse dynamics by per-link COG Jacobians, for ROS 2.

    mech = cog_id_ros.Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    solver = cog_id_ros.InverseDynamics(mech)
    tau = solver.torques(q, qd, qdd)
"""
from .core import (
    REASONS,
    AssemblyWarning,
    ClosureError,
    CogIdError,
    Evaluation,
    InverseDynamics,
    MechanismConfigError,
    SetpointError,
    SingularConfigurationError,
)
from .description import Mechanism

__version__ = '0.1.0'
__all__ = ['REASONS', 'AssemblyWarning', 'ClosureError', 'CogIdError', 'Evaluation',
           'InverseDynamics', 'Mechanism', 'MechanismConfigError', 'SetpointError',
           'SingularConfigurationError', '__version__']
