"""Exceptions raised by fahv. Each names the input at fault and what was expected."""


class FahvError(Exception):
    """Base class of every error fahv raises on purpose."""


class VehicleDataError(FahvError, ValueError):
    """A vehicle data file is missing, malformed, or holds a non-physical value."""


class EnvelopeError(FahvError, ValueError):
    """A flight condition (h, V) lies outside the flight envelope."""


class TrimError(FahvError, RuntimeError):
    """No equilibrium exists within the input limits, or the solver did not converge."""


class DesignError(FahvError, RuntimeError):
    """An offline design step failed or a certificate did not hold."""


class ConfigError(FahvError, ValueError):
    """A configuration value (case file, campaign file, node parameter) is invalid."""


class CaseError(ConfigError):
    """A case file is missing, malformed, or holds an unknown or out-of-range key."""


class ParameterError(ConfigError):
    """A node parameter is missing, of the wrong type or shape, non-finite or out of range."""


class RunError(FahvError, RuntimeError):
    """A closed-loop run or a recorded run file cannot be used."""


class CampaignError(ConfigError):
    """A campaign file or a campaign folder is missing, malformed or inconsistent."""
