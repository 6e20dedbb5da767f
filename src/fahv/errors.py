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
    """A configuration value (design, scenario or campaign file, node parameter) is invalid."""


class SpecError(ConfigError):
    """A design file, a scenario file or the run spec they form is missing or malformed.

    Or it holds an unknown or out-of-range key (the message names the file and the key).
    """


class ParameterError(ConfigError):
    """A node parameter is missing, of the wrong type or shape, non-finite or out of range."""


class RunError(FahvError, RuntimeError):
    """A closed-loop run or a recorded run file cannot be used."""


class RunInterrupted(FahvError):
    """A run was stopped by SIGINT / SIGTERM; its recording (if any) is finalised.

    Parameters
    ----------
    step : int
        Steps completed (and recorded) when the run stopped.
    n_steps : int
        Steps the run would have had.
    run : path or None
        Run folder written, None when the run was not recorded.
    """

    def __init__(self, step: int, n_steps: int, run=None) -> None:
        self.step, self.n_steps, self.run = int(step), int(n_steps), run
        where = f"run written to {run}" if run is not None else "nothing recorded"
        super().__init__(f"interrupted at step {self.step} of {self.n_steps}; {where}")


class CampaignError(ConfigError):
    """A campaign file or a campaign folder is missing, malformed or inconsistent."""
