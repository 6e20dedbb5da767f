"""The one interface of every control law, and the registries of laws and variants.

A control law is one module: a subclass of :class:`ControlLaw` registered with
:func:`register_law`. It declares

- the case-file section it needs (:attr:`ControlLaw.section`, required only when a
  variant of the case uses the law),
- the parameters its controller node takes beyond the common ones
  (:attr:`ControlLaw.parameters`, generated into ROS descriptors),
- its offline part (:meth:`ControlLaw.design`: extra certified arrays) and how the
  design fills its parameters (:meth:`ControlLaw.node_values`),
- its online part: ``step(k, x, ref) -> (u, status)``, the one call the in-process
  simulator, the controller node and the benchmarks make.

A *variant* is what a case lists and a run is made of: a law plus a notch setting
(``tube_mpc_no_notch`` is the law ``tube_mpc`` with the notch off).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from fahv.config import Field, Registry, Section
from fahv.control.reference import NominalOutput


class ControlLaw:
    """Base of every control law.

    Parameters
    ----------
    p : dict
        Validated parameters of the controller node: the common ones (``Ts``,
        ``law``, ``tau``, ``F`` (2, n), ``N`` (n, n)) and the law's own
        :attr:`parameters`.
    """

    #: Registry name (node parameter ``law``).
    name: ClassVar[str] = ""
    #: Controller node (executable) that runs the law.
    node: ClassVar[str] = "tube_mpc"
    #: Mode of the nominal_trajectory node: ``mpc`` (online tracking MPC,
    #: :mod:`fahv.control.nominal_mpc`), ``governor`` (nominal system with the
    #: reference governor, eq. 20/46) or ``command`` (trim of the raw command).
    reference: ClassVar[str] = "governor"
    #: Case-file section the law needs (required only when a variant uses the law).
    section: ClassVar[Section | None] = None
    #: Parameters of the controller node the law adds (each used only with the law).
    parameters: ClassVar[tuple[Field, ...]] = ()

    def __init__(self, p: dict) -> None:
        self.p = p

    @classmethod
    def design(cls, ctx: Any) -> dict[str, np.ndarray]:
        """Offline part: extra arrays of the design (default none).

        Parameters
        ----------
        ctx : object
            The design context of :func:`fahv.design.pipeline.run_design`
            (:class:`fahv.design.pipeline.DesignContext`: ``case`` data, ``vehicle``,
            the ``arrays`` designed so far, ``log``).

        Returns
        -------
        dict
            Name -> ndarray, added to the design's arrays (and to its hash).
        """
        return {}

    @classmethod
    def node_values(cls, arrays: dict, case: dict) -> dict[str, Any]:
        """Values of :attr:`parameters` from the design arrays and the case data."""
        return {}

    def step(self, k: int, x: np.ndarray, ref: NominalOutput) -> tuple[np.ndarray, dict]:
        """Command of step k.

        Parameters
        ----------
        k : int
            Step index (t_k = k Ts).
        x : (n,) ndarray
            Measured controller state (q' for q with the notch; plus the notch states
            x_q for the 11-state ECM design).
        ref : NominalOutput
            Reference and nominal trajectory of step k.

        Returns
        -------
        u : (2,) ndarray
            [Phi, delta_e rad].
        status : dict
            ``e`` (n,) tube error (or x - x_r), ``level`` (<= 1 inside the tube; NaN
            when the law has no tube), optionally ``lmi_solves``, ``lmi_fallback``,
            ``lmi_failed`` counters and ``label`` (the law name reported).
        """
        raise NotImplementedError


@dataclass(frozen=True)
class Variant:
    """A run configuration a case may list.

    Attributes
    ----------
    name : str
    law : str
        Registered control law.
    notch : {"case", "off", "mode2"}
        Notch as in the case file, switched off, or centred on flexible mode 2.
    description : str
    """

    name: str
    law: str
    notch: str = "case"
    description: str = ""


#: Control laws by name.
LAWS: Registry[type[ControlLaw]] = Registry("control law")
#: Variants by name.
VARIANTS: Registry[Variant] = Registry("variant")


def register_law(cls: type[ControlLaw], variants: tuple[Variant, ...] = ()) -> type[ControlLaw]:
    """Register a law, a variant of the same name, and ``variants``; returns ``cls``.

    Raises
    ------
    ConfigError
        If a name is taken.
    """
    LAWS.register(cls.name, cls)
    for v in (Variant(cls.name, cls.name, "case", cls.__doc__.splitlines()[0]), *variants):
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
