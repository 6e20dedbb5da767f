"""What each stage of a design makes: one frozen record per stage, in the paper's order.

The stages of `fahv.design.stages` are functions of these records, so that what a
stage reads is its arguments and what it makes is its result (units unscaled unless
stated). Every record carries the certificate lines its stage prints (`lines`,
formatted by `fahv.certificate.report`); the pipeline logs them in order.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fahv.bounds.coverage import LossCoverage
from fahv.bounds.disturbance import DisturbanceSet
from fahv.bounds.domain import SchedulingBox
from fahv.model.notch import NotchFilter
from fahv.model.tp_model import DiscretePolytope, TPModel
from fahv.model.trim import TrimMap
from fahv.synthesis.feedback import TubeDesign
from fahv.synthesis.nominal import NominalDesign
from fahv.tube.tube_set import TubeSet


@dataclass(frozen=True)
class DesignModel:
    """The design model and its LPV form (sec. 3.1, eq. 11), the trim map, the design step.

    Attributes
    ----------
    notch : NotchFilter
        The design's notch filter (eq. 38).
    model_notch : NotchFilter or None
        The notch the design model carries (the ECM's, eq. 40), None for the CM.
    tp : TPModel
        The TP model of the design model.
    disc : DiscretePolytope
        Its vertices discretised at Ts.
    Dx, Du : ndarray
        State and input scaling of the LMIs.
    step : dict
        The design step as a step command (`fahv.design.stages.step_command`).
    omega_flex : (2,) ndarray
        Flexible mode frequencies at the design point [rad/s].
    trim : TrimMap
        The trim map of the design model.
    x_start, x_end : ndarray
        The trims at the design step's start and end.
    lines : tuple of str
    """

    notch: NotchFilter
    model_notch: NotchFilter | None
    tp: TPModel
    disc: DiscretePolytope
    Dx: np.ndarray
    Du: np.ndarray
    step: dict
    omega_flex: np.ndarray
    trim: TrimMap
    x_start: np.ndarray
    x_end: np.ndarray
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class Disturbance:
    """The disturbance set W by sampling (eq. 13-19) over the parameter box.

    Attributes
    ----------
    uncertainty : dict[str, float]
        Relative half-widths of the parameter box (the sec. 5.1 box times
        `uncertainty.scale`).
    W : DisturbanceSet
    lines : tuple of str
    """

    uncertainty: dict
    W: DisturbanceSet
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class VertexTube:
    """F and Z of LMI (24) over the fault vertices (eq. 15) and the adjustable gains (eq. 48).

    Attributes
    ----------
    rho_f : float
        Smallest elevator effectiveness the tube covers (`tube.rho_min`).
    Af, Bf : ndarray
        The TP vertices with the elevator at full and at rho_f effectiveness.
    room : (2,) ndarray
        Input room of the healthy trim over the envelope.
    room_f : (2,) ndarray
        The same with the faulty vehicle's elevator trim (the tube objective's weights).
    tau : float
        Adjustable factor (eq. 48).
    tube : TubeDesign
    eigs : ndarray
        Eigenvalues of the re-checked LMI blocks (`fahv.synthesis.feedback.verify_tube`).
    lines : tuple of str
    """

    rho_f: float
    Af: np.ndarray
    Bf: np.ndarray
    room: np.ndarray
    room_f: np.ndarray
    tau: float
    tube: TubeDesign
    eigs: np.ndarray
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class NotchVariants:
    """The tube variants that feed q through a notch, by what the design checks of them.

    Attributes
    ----------
    certified : dict
        `{variant: NotchFilter}` whose loop is certified in its own states.
    stable_only : dict
        `{variant: NotchFilter}` whose loop is checked for stability only.
    """

    certified: dict = field(default_factory=dict)
    stable_only: dict = field(default_factory=dict)


@dataclass(frozen=True)
class FormTube:
    """The tube the law runs on, as the design's tube form made it (`tube.form`).

    Attributes
    ----------
    F : (2, n) ndarray
        Ancillary gain.
    N : (n, n) ndarray
        Shape of Z = {e' N^-1 e <= 1}.
    tightening : (2,) ndarray
        Support of F Z per input (eq. 30, before the factor tau).
    lam : float
        Contraction factor of its LMI (24).
    notch_loops : tuple of fahv.tube.notch_loop.NotchLoop
        The vertex tube's loops through a notch (the tube set keeps its own).
    tube_set : TubeSet or None
        The eight-state tube set (`tube.form: eight_state`).
    nominal, box : SchedulingBox or None
        With the tube set: the nominal box and the scheduling box it is closed over.
    hv_box : (2, 2) ndarray or None
        With the tube set: the nominal's h, V range (`mpc.hv_box`).
    col_scale : (11,) ndarray or None
        With the tube set: the column scale of its parameter directions.
    lines : tuple of str
    """

    F: np.ndarray
    N: np.ndarray
    tightening: np.ndarray
    lam: float
    notch_loops: tuple = ()
    tube_set: TubeSet | None = None
    nominal: SchedulingBox | None = None
    box: SchedulingBox | None = None
    hv_box: np.ndarray | None = None
    col_scale: np.ndarray | None = None
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class Tightening:
    """The tightened inputs (eq. 30; eq. 53 with tau < 1) and the loss they cover.

    Attributes
    ----------
    u_n_max : (2,) ndarray
        Room left to the nominal input, room - tau F Z's support.
    u_lo, u_hi : (2,) ndarray
        Tightened absolute input limits (asymmetric).
    coverage : LossCoverage
        The largest elevator loss whose faulty trim fits them over the parameter box.
    lines : tuple of str
    """

    u_n_max: np.ndarray
    u_lo: np.ndarray
    u_hi: np.ndarray
    coverage: LossCoverage
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class Nominal:
    """The nominal gain K and ellipsoid E(Q) (LMI 32-35) sized for the design step.

    Attributes
    ----------
    design : NominalDesign
    certificate : dict
        Its re-check (`fahv.synthesis.nominal.verify_nominal`).
    lines : tuple of str
    """

    design: NominalDesign
    certificate: dict
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class FormCertificate:
    """The tube form's certificate over its own domain.

    Attributes
    ----------
    summary : dict
        The design summary's `certificate` (JSON-able).
    arrays : dict
        Arrays the law needs from it (the QP's rows, a gain designed for a notch loop).
    lines : tuple of str
    """

    summary: dict
    arrays: dict = field(default_factory=dict)
    lines: tuple[str, ...] = ()


@dataclass(frozen=True)
class EarlyLaws:
    """Offline parts started on the design's Dask cluster right after the model stage.

    Attributes
    ----------
    parts : dict
        `{law name: distributed.Future}`, each of `(arrays, lines)`
        (`fahv.design.stages.offline_part`); empty when no Dask client is active.
    """

    parts: dict = field(default_factory=dict)
