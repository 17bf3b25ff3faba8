"""cog_id_ros: closed-link inverse dynamics by per-link COG Jacobians, for ROS 2.

    mech = cog_id_ros.Mechanism.from_params_file('config/paper_four_bar_a.yaml')
    solver = cog_id_ros.InverseDynamics(mech)
    tau = solver.torques(q, qd, qdd)

The names below are imported when first used (PEP 562): importing the package, or one of
its programs (``cog_id_node``), imports nothing heavy, so that a program can take charge of
Ctrl-C before numpy, SciPy and rclpy are imported (cog_id_ros/ros/main.py).
"""
# typing.TYPE_CHECKING without importing typing (3 ms); type checkers know this spelling
TYPE_CHECKING = False
if TYPE_CHECKING:   # what __getattr__ below gives, for type checkers and linters
    from .core import (
        REASONS,
        AssemblyWarning,
        ClosureError,
        CogIdError,
        Evaluation,
        InverseDynamics,
        MechanismConfigError,
        SetpointError,
        Simulation,
        SingularConfigurationError,
        Transmission,
    )
    from .description import Mechanism

__version__ = '0.1.0'
__all__ = ['REASONS', 'AssemblyWarning', 'ClosureError', 'CogIdError', 'Evaluation',
           'InverseDynamics', 'Mechanism', 'MechanismConfigError', 'SetpointError',
           'Simulation', 'SingularConfigurationError', 'Transmission', '__version__']

#: the names of __all__ the core gives (Mechanism is the description's: it reads files too)
_FROM_CORE = frozenset(__all__) - {'Mechanism', '__version__'}


def __getattr__(name):
    if name in _FROM_CORE:
        from . import core
        value = getattr(core, name)
    elif name == 'Mechanism':
        from .description import Mechanism as value
    else:
        raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
    globals()[name] = value     # imported once: from now on an ordinary attribute
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
