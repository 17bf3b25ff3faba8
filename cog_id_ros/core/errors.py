"""Exceptions of cog_id_ros: each carries what a user needs to act on it."""


class CogIdError(Exception):
    """Base class of every error raised by cog_id_ros."""


class MechanismConfigError(CogIdError, ValueError):
    """A parameter file or dict that cannot be honoured.

    ``parameter`` is the dotted parameter name (e.g. ``links.link2.mass``); the message
    starts with it: ``links.link2.mass: must be >= 0, got -1.0``.
    """

    def __init__(self, parameter, message):
        self.parameter = parameter
        super().__init__(f'{parameter}: {message}')


class SetpointError(CogIdError, ValueError):
    """A setpoint array that is malformed: wrong shape, NaN or Inf."""

    def __init__(self, message, sample=None):
        self.sample = sample
        super().__init__(message)


class ClosureError(CogIdError):
    """The loops cannot be closed at this setpoint (``residual`` says by how much).

    Also raised for a redundant setpoint that disagrees with the closure by more than
    ``mechanism.setpoint_tolerance``; ``residual`` is then that disagreement.
    """

    def __init__(self, message, residual, sample=None):
        self.residual = float(residual)
        self.sample = sample
        super().__init__(message)


class SingularConfigurationError(CogIdError):
    """The closure Jacobian is (nearly) singular here: ``condition_number`` says how badly."""

    def __init__(self, message, condition_number, sample=None):
        self.condition_number = float(condition_number)
        self.sample = sample
        super().__init__(message)
