"""Exceptions of cog_id_ros: each carries what a user needs to act on it.

Every error raised for a sample has a machine-readable ``reason`` (a key of
:data:`REASONS`), so callers (the node, the offline tool) never search message text.
"""

#: why a sample (a setpoint, a trajectory point, a CSV row) could not be served
REASONS = {
    'malformed': 'wrong shape or type: not one number per active joint',
    'non_finite': 'NaN or infinity in a position, velocity or acceleration',
    'out_of_range': 'a finite value too large to compute with (the torques would overflow)',
    'limit': "an active joint's position outside its limits (joints.<name>.lower / upper)",
    'closure': 'the loops cannot be closed at this pose',
    'singular': 'the pose is singular (closure Jacobian condition number too large; for '
                'forward dynamics also an inertia that cannot be solved)',
    'inconsistent': 'redundant actuation: the active coordinates disagree with the loop closure '
                    'on the assembly branch the solver is on',
    'unreachable': 'the pose cannot be reached from the previous one by continuation',
}


class CogIdError(Exception):
    """Base class of every error raised by cog_id_ros."""

    #: a key of REASONS for errors about a sample; 'config' for MechanismConfigError (a
    #: parameter, not a sample); None otherwise
    reason: str | None = None


class MechanismConfigError(CogIdError, ValueError):
    """A parameter file or dict that cannot be honoured.

    ``parameter`` is the dotted parameter name (e.g. ``links.link2.mass``); the message
    starts with it: ``links.link2.mass: must be >= 0, got -1.0``.
    """

    reason = 'config'

    def __init__(self, parameter: str, message: str) -> None:
        self.parameter = parameter
        super().__init__(f'{parameter}: {message}')


class SetpointError(CogIdError, ValueError):
    """A setpoint that is malformed (wrong shape or type), not finite, or out of range.

    ``reason``: 'malformed', 'non_finite', 'out_of_range' or 'limit'.
    """

    def __init__(self, message: str, sample: int | None = None, reason: str = 'malformed') -> None:
        assert reason in ('malformed', 'non_finite', 'out_of_range', 'limit'), reason
        self.sample = sample
        self.reason = reason
        super().__init__(message)


class ClosureError(CogIdError):
    """The loops cannot be closed at this setpoint (``residual`` says by how much).

    ``reason`` 'closure'; 'unreachable' when the pose may exist but cannot be reached
    from the previous one by continuation (too far, or across a dead centre);
    'inconsistent' for a redundant setpoint that disagrees with the closure by more than
    ``mechanism.setpoint_tolerance`` (``residual`` is then that disagreement), on the
    assembly branch the solver is on (the message says when the loops close at it in
    another assembly mode).
    """

    def __init__(self, message: str, residual: float, sample: int | None = None,
                 reason: str = 'closure') -> None:
        assert reason in ('closure', 'unreachable', 'inconsistent'), reason
        self.residual = float(residual)
        self.sample = sample
        self.reason = reason
        super().__init__(message)


class SingularConfigurationError(CogIdError):
    """The closure Jacobian is (nearly) singular here, or for forward dynamics the inertia
    (forward_dynamics.py): ``condition_number`` says how badly."""

    reason = 'singular'

    def __init__(self, message: str, condition_number: float, sample: int | None = None) -> None:
        self.condition_number = float(condition_number)
        self.sample = sample
        super().__init__(message)
