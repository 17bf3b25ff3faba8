"""InverseDynamics: the solver users call, a thin face over the modules that do the work.

    one sample   inputs.py -> sample_solve.py (continuation, Newton) -> kernels.py
    N samples    inputs.py -> batch.py (arrays, checked by the serial rules)
    per pose     poses.py (the closed poses of cog_poses, ..., equation_of_motion)
    the maths    pipeline.py: eqs. (1)-(7) at a closed pose, run by every path
    joint space  transmission/ (mechanism.joint_space: the map to the motors and back)

Successive calls keep the assembly branch: each is warm-started from the previous one.
Actuator space is actuator_space.py's ActuatorSpaceSolver; this class adds the joint space
of a mechanism that names one (``space='joint'``, :attr:`InverseDynamics.transmission`).
"""
from typing import Optional

import numpy as np

from ..errors import SetpointError
from ..solve.actuator_space import ActuatorSpaceSolver, ArrayLike
from ..solve.batch import Evaluation
from ..solve.whole_body import WholeBodyEfforts, whole_body_torques
from ..transmission.transmission import Transmission

__all__ = ['ArrayLike', 'Evaluation', 'InverseDynamics', 'WholeBodyEfforts']

SPACES = ('actuator', 'joint')


class InverseDynamics(ActuatorSpaceSolver):
    """Active-joint torques of a closed-link mechanism by per-link COG Jacobians.

    All arrays are in ``mechanism.active_joints`` order; shapes (M,) for one sample or
    (N, M) for N samples. Angles are never wrapped. ``backend``: 'auto' (default),
    'reference' (the lane code on floats, nothing traced) or 'python' (traced
    straight-line kernels); all give the same numbers (kernels.py). With
    ``mechanism.joint_space``, :meth:`torques` and :meth:`forward_dynamics` also take the
    motion in joint space (``space='joint'``), and :attr:`transmission` is the map.
    """

    _transmission: Optional[Transmission] = None

    @property
    def transmission(self) -> Transmission:
        """The map between actuator space and mechanism.joint_space (made on first use, on
        this solver's backend, with solvers of its own: its calls do not move this one's
        warm start). MechanismConfigError without a joint_space."""
        if self._transmission is None:
            self._transmission = Transmission(self.mechanism, self.backend)
        return self._transmission

    def torques(self, q: ArrayLike, qd: Optional[ArrayLike] = None,
                qdd: Optional[ArrayLike] = None, space: str = 'actuator') -> np.ndarray:
        """tau = H(q) qdd + B(q, qd) for the active joints: (M,) or (N, M).

        ``space='joint'``: ``q``, ``qd``, ``qdd`` are the positions, velocities and
        accelerations of mechanism.joint_space (D or (N, D)); the result is still the
        actuators' efforts, the exact ones of that motion (the linkage's inertia and
        gravity included).

        Raises ClosureError, SingularConfigurationError or SetpointError for the first sample
        that cannot be served (``.sample`` is its index); the warm start is then unchanged.
        """
        if _space(space) == 'joint':
            return self.transmission.torques(q, qd, qdd)
        return super().torques(q, qd, qdd)

    def forward_dynamics(self, q: ArrayLike, qd: Optional[ArrayLike],
                         tau: Optional[ArrayLike], space: str = 'actuator') -> np.ndarray:
        """The accelerations (M,) or (N, M) the efforts ``tau`` (N m or N, active_joints
        order) produce at positions ``q`` and rates ``qd``, with gravity: eq. (7) solved for
        qdd (docs/simulation.md). ``qd``, ``tau``: zeros when None. ``space='joint'``:
        ``q``, ``qd`` and the accelerations returned are of mechanism.joint_space; ``tau``
        stays the actuators' efforts.

        The pose is solved as :meth:`torques` solves it (warm start, branch, errors); a
        redundant mechanism moves by the generalized force of its efforts alone.
        SingularConfigurationError also for an inertia that cannot be solved.
        """
        if _space(space) == 'joint':
            return self.transmission.forward_dynamics(q, qd, tau)
        return super().forward_dynamics(q, qd, tau)

    def whole_body_torques(self, base_pose: ArrayLike, base_velocity: Optional[ArrayLike],
                           base_acceleration: Optional[ArrayLike], theta: ArrayLike,
                           theta_dot: Optional[ArrayLike] = None,
                           theta_ddot: Optional[ArrayLike] = None,
                           contacts: Optional[list] = None,
                           wrench_weights: Optional[object] = None) -> WholeBodyEfforts:
        """A floating robot (mechanism.floating_base): the actuator efforts, the contact
        wrenches and what is left for the world at the root (``base_wrench``) of a motion of
        the base and the actuators (docs/floating_base.md). ``contacts``: names of
        mechanism.contacts touching now (None: all of them; []: none); ``wrench_weights``:
        per contact 6 or 3 positive weights (a dict by name, or a list in ``contacts``
        order); the wrenches are those of least weighted norm that produce the motion.
        Batch: every argument with a leading N. The pose is solved as :meth:`torques` solves
        it (warm start, branch, errors)."""
        return whole_body_torques(self, base_pose, base_velocity, base_acceleration, theta,
                                  theta_dot, theta_ddot, contacts, wrench_weights)


def _space(space: object) -> str:
    if space not in SPACES:
        raise SetpointError(f"space must be 'actuator' or 'joint', got {space!r}")
    return str(space)
