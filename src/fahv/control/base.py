"""The interfaces of the control layer and their registries: laws, nominal parts, variants.

A control law is one module: a subclass of `ControlLaw` registered with
`register_law`. It declares

- its nominal part, a registered `NominalSource` class (`ControlLaw.nominal`),
  which runs in the nominal_trajectory node and gives the reference (x_r, u_r) and the
  nominal trajectory (x_n, u_n) of every step,
- the design-file section it needs (`ControlLaw.section`, required only when a
  variant of the design uses the law),
- the parameters its controller node takes beyond the common ones
  (`ControlLaw.parameters`, generated into ROS descriptors),
- its offline part (`ControlLaw.design`: extra certified arrays) and how the
  design fills its parameters (`ControlLaw.node_values`),
- its online part: `step(k, x, ref, lanes) -> LawStep` over a batch of B runs, the
  one call the in-process simulator (B = 1), the campaign batches and the controller
  node (B = 1) make.

A nominal part has the same shape (section, parameters, offline design and checks,
node values, a batched `step`) and its own registry, so a new law that brings a
new nominal part is its module(s) plus two registry entries.

A *variant* is what a design file lists and a run is made of: a law plus a notch setting
(`tube_mpc_no_notch` is the law `tube_mpc` with the notch off).
"""

from __future__ import annotations

import functools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from fahv.config import Field, Registry, Section
from fahv.errors import ConfigError
from fahv.lanes import Lanes
from fahv.msg import NominalTrajectory

#: Largest attitude error |alpha - alpha_r|, |theta - theta_r| the paper requires (sec. 5.1) [deg].
ATTITUDE_BOUND_DEG = 0.5


class NominalSource:
    """Base of the nominal part of a control law, for B runs at once.

    Parameters
    ----------
    p : dict
        Validated parameters of the nominal_trajectory node of the first run; the
        values every run of a batch shares (design arrays, settings).
    runs : sequence of dict
        Validated parameters of each of the B runs: their own command (`command.*`)
        and initial measured state `x0`.
    lanes : fahv.lanes.Lanes
        Where a run's failure goes.
    """

    #: Registry name (node parameter `nominal`).
    name: ClassVar[str] = ""
    #: Design-file section of the nominal part (required when a variant's law uses it).
    section: ClassVar[Section | None] = None
    #: Parameters of the nominal_trajectory node it adds (used only with it).
    parameters: ClassVar[tuple[Field, ...]] = ()
    #: True when the nominal part estimates the constant disturbance (so W may leave
    #: the constant part of the parameter error out, `disturbance.constant: estimated`).
    estimates_disturbance: ClassVar[bool] = False

    def __init__(self, p: dict, runs: Sequence[dict], lanes: Lanes) -> None:
        self.p, self.lanes = p, lanes

    @classmethod
    def design(cls, ctx: Any) -> dict[str, np.ndarray]:
        """Offline part and certificate checks: extra arrays of the design (default none).

        Parameters
        ----------
        ctx : fahv.spec.context.DesignContext
            `spec` (the design data and its command), `vehicle`, the `arrays`
            designed so far, `log`.

        Raises
        ------
        DesignError
            If a certificate of the nominal part does not hold.
        """
        return {}

    @classmethod
    def node_values(cls, arrays: dict, case: dict) -> dict[str, Any]:
        """Values of `parameters` from the design arrays and the case data."""
        return {}

    def step(self, k: int, t: float, x: np.ndarray, u_prev: np.ndarray | None) -> NominalTrajectory:
        """Reference and nominal trajectory of step k for the B runs, then advance.

        `output` then `advance`: the simulator and the batch call this; the
        node publishes the output before it advances (the advance is off the step's
        critical path), with the same arithmetic.

        Parameters
        ----------
        k : int
            Step index (t = k Ts).
        t : float
            Simulated time [s].
        x : (B, 9) ndarray
            Measured plant states of step k.
        u_prev : (B, 2) ndarray or None
            Commands of step k - 1 (None at k = 0).

        Returns
        -------
        fahv.msg.NominalTrajectory
        """
        out = self.output(k, t, x, u_prev)
        self.advance()
        return out

    def output(
        self, k: int, t: float, x: np.ndarray, u_prev: np.ndarray | None
    ) -> NominalTrajectory:
        """Reference and nominal trajectory of step k (arguments as `step`).

        Must be followed by `advance` before the output of step k + 1.
        """
        raise NotImplementedError

    def advance(self) -> None:
        """Move the nominal to step k + 1 after `output` of step k (default: nothing)."""


@dataclass(frozen=True)
class LawStep:
    """What a law computes at one step for B runs.

    Attributes
    ----------
    u : (B, 2) ndarray
        Commands [Phi, delta_e rad].
    e : (B, n) ndarray
        Tube error x - x_r - x_n (or x - x_r without a tube).
    level : (B,) ndarray
        e' N^-1 e (<= 1 inside the tube Z; NaN without a tube).
    lmi_failed : (B,) int ndarray
        Steps so far with the state outside the law's largest ellipsoid (the RMPC
        baseline's E_1; zeros for the tube laws).
    """

    u: np.ndarray
    e: np.ndarray
    level: np.ndarray
    lmi_failed: np.ndarray


@functools.cache
def no_lmi_failed(n_runs: int) -> np.ndarray:
    """Zero `LawStep.lmi_failed` (n_runs,) of a law without ellipsoids (read-only, shared).

    Raises
    ------
    ValueError
        If `n_runs` is negative.
    """
    out = np.zeros(n_runs, dtype=np.int64)
    out.setflags(write=False)
    return out


class ControlLaw:
    """Base of every control law (B runs at once).

    Parameters
    ----------
    p : dict
        Validated parameters of the controller node (shared by the runs of a batch):
        the common ones (`Ts`, `law`, `tau`, `F` (2, n), `N` (n, n)) and the
        law's own `parameters`.
    n_runs : int
        Number of runs B the law steps together.
    """

    #: Registry name (node parameter `law`).
    name: ClassVar[str] = ""
    #: Controller node (executable) that runs the law.
    node: ClassVar[str] = "tube_mpc"
    #: The nominal part: a registered NominalSource class.
    nominal: ClassVar[type[NominalSource]]
    #: False for a law without a tube (its tau is 1 and its tube level NaN).
    has_tube: ClassVar[bool] = True
    #: True if the law can form its error's q through the notch (the nominal's q through
    #: a replica of the filter, with the case key `tube.filter_nominal_q`), so that the
    #: design may certify the loop through the notch
    #: (`fahv.tube.notch_loop.notch_tube`); otherwise the measured q alone is
    #: filtered and only the loop's stability is checked.
    filters_nominal_q: ClassVar[bool] = False
    #: True if the offline part (`design`) reads only what the design model makes
    #: (the trim map `trim_*`, the design point's trim `x0`, the input room
    #: `u_room`): a design may then start it as soon as its model is made, on its Dask
    #: cluster beside the tube's stages (`fahv.design.stages.early_laws_stage`).
    model_only: ClassVar[bool] = False
    #: Design-file section the law needs (required only when a variant uses the law).
    section: ClassVar[Section | None] = None
    #: Parameters of the controller node the law adds (each used only with the law).
    parameters: ClassVar[tuple[Field, ...]] = ()

    def __init__(self, p: dict, n_runs: int = 1) -> None:
        self.p, self.n_runs = p, n_runs

    @classmethod
    def design(cls, ctx: Any) -> dict[str, np.ndarray]:
        """Offline part: extra arrays of the design (default none).

        Parameters
        ----------
        ctx : object
            The design context of `fahv.design.pipeline.run_design`
            (`fahv.spec.context.DesignContext`: `spec` data, `vehicle`,
            the `arrays` designed so far, `log`).

        Returns
        -------
        dict
            Name -> ndarray, added to the design's arrays (and to its hash).
        """
        return {}

    @classmethod
    def node_values(cls, arrays: dict, case: dict) -> dict[str, Any]:
        """Values of `parameters` from the design arrays and the case data."""
        return {}

    def step(self, k: int, x: np.ndarray, ref: NominalTrajectory, lanes: Lanes) -> LawStep:
        """Commands of step k for B runs.

        Parameters
        ----------
        k : int
            Step index (t_k = k Ts).
        x : (B, n) ndarray
            Measured controller states (q' for q with the notch; plus the notch states
            x_q for the 11-state ECM design).
        ref : fahv.msg.NominalTrajectory
            Reference and nominal trajectory of step k (x_r, u_r, x_n, u_n).
        lanes : fahv.lanes.Lanes
            Where a run's failure goes.

        Returns
        -------
        LawStep
        """
        raise NotImplementedError


@dataclass(frozen=True)
class Variant:
    """A run configuration a design file may list: a law with a notch setting.

    Attributes
    ----------
    name : str
    law : str
        Registered control law.
    notch : {"design", "off", "mode2"}
        Notch as in the design file, switched off, or centred on flexible mode 2.
    description : str
    """

    name: str
    law: str
    notch: str = "design"
    description: str = ""


def variant_notch(design_notch, setting: str, omega_flex) -> dict | None:
    """The notch filter (eq. 38) a variant runs with on the q feedback, or None.

    Parameters
    ----------
    design_notch : mapping
        The design's `notch` section (`enabled`, `omega_z`, `eps_z`, `omega_p`,
        `eps_p`; rad/s and -).
    setting : {"design", "off", "mode2"}
        `Variant.notch`.
    omega_flex : (2,) array_like
        Flexible mode frequencies of the design [rad/s]; `mode2` centres the notch on
        the second.

    Returns
    -------
    dict or None
        `omega_z`, `eps_z`, `omega_p`, `eps_p` as floats; None when the notch is
        off (in the design or by the variant).
    """
    if not design_notch["enabled"] or setting == "off":
        return None
    notch = {k: float(design_notch[k]) for k in ("omega_z", "eps_z", "omega_p", "eps_p")}
    if setting == "mode2":
        w2 = float(np.asarray(omega_flex, float)[1])
        notch.update(omega_z=w2, omega_p=w2)
    return notch


#: Control laws by name.
LAWS: Registry[type[ControlLaw]] = Registry("control law")
#: Nominal parts by name.
NOMINAL_SOURCES: Registry[type[NominalSource]] = Registry("nominal source")


def register_nominal(cls: type[NominalSource]) -> type[NominalSource]:
    """Register a nominal part under its `name`; returns `cls`.

    Raises
    ------
    ConfigError
        If the name is taken by another class.
    """
    if NOMINAL_SOURCES.get(cls.name) is not cls:
        NOMINAL_SOURCES.register(cls.name, cls)
    return cls


#: Variants by name.
VARIANTS: Registry[Variant] = Registry("variant")


def register_law(cls: type[ControlLaw], variants: tuple[Variant, ...] = ()) -> type[ControlLaw]:
    """Register a law, a variant of the same name, and `variants`; returns `cls`.

    Raises
    ------
    ConfigError
        If a name is taken, or the law's nominal part is not a registered NominalSource.
    """
    nominal = getattr(cls, "nominal", None)
    if not (isinstance(nominal, type) and issubclass(nominal, NominalSource)):
        raise ConfigError(f"control law '{cls.name}' must name its nominal part (a NominalSource)")
    if NOMINAL_SOURCES.get(nominal.name) is not nominal:
        raise ConfigError(
            f"control law '{cls.name}': nominal part '{nominal.name}' is not registered "
            "(register_nominal)"
        )
    LAWS.register(cls.name, cls)
    for v in (Variant(cls.name, cls.name, "design", cls.__doc__.splitlines()[0]), *variants):
        VARIANTS.register(v.name, v)
    return cls


def unregister_law(name: str) -> None:
    """Remove a law and every variant that uses it (tests)."""
    for v in [v for v in VARIANTS if VARIANTS[v].law == name]:
        VARIANTS.unregister(v)
    LAWS.unregister(name)


def law_of(variant: str) -> type[ControlLaw]:
    """The law class of a variant.

    Raises
    ------
    ConfigError
        On an unknown variant.
    """
    return LAWS[VARIANTS[variant].law]
