"""The loop margins of a stored design: its notch settings over its plant points.

`margin_study` evaluates the loop of `fahv.analysis.margins` for every notch
setting of the design's tube variants (`notch_settings`: the notch as designed at
omega_1, none, at omega_2, and at omega_1 with the paper's eps_p), broken at delta_e and
at q: at the design point every setting, over the LPV vertices the variant as designed
and no notch (every setting on request), and at the corners of the parameter box the
closed loop's stability at every corner and the margins at the corner whose airframe is
the most unstable.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field, replace

import numpy as np

from fahv.analysis.margins import (
    BREAKS,
    PAPER_EPS_P,
    LoopMargins,
    Plants,
    closed_loop,
    corner_signs,
    frequency_grid,
    loop_margins,
    loop_systems,
    spectral_radius,
    worst_case,
)
from fahv.bounds.plant_step import jacobians
from fahv.control.base import LAWS, VARIANTS, variant_notch
from fahv.model.lpv import PolytopicLPV
from fahv.model.notch import NotchFilter
from fahv.model.trim import TrimMap
from fahv.plant.rk4 import perturbed_records
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.spec.artefacts import variant_gain_key


@dataclass(frozen=True)
class NotchSetting:
    """One notch setting of the loop: a tube variant's filter on q and its gain.

    Attributes
    ----------
    label : str
        Short name for tables ("off", "omega_1", "omega_2", "omega_1, eps_p 0.5").
    variant : str
        The design's variant it belongs to.
    notch : fahv.model.notch.NotchFilter or None
        The filter (None: q fed back as measured).
    F : (m, n) ndarray
        The gain the variant runs (tau F; `F_<variant>` if the design made one).
    """

    label: str
    variant: str
    notch: NotchFilter | None
    F: np.ndarray = field(repr=False)


def notch_settings(design) -> list[NotchSetting]:
    """The notch settings of a design's tube variants, and the paper's eps_p at omega_1.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
        A nine-state design (the ECM design models the filter in its plant).

    Returns
    -------
    list of NotchSetting
        One per tube variant (`rmpc` has none), then, if the notch at omega_1 does not
        already have it, that notch with eps_p = `PAPER_EPS_P`.

    Raises
    ------
    ValueError
        If the design is not on the CM (`design_model` cm).
    """
    if design.case["design_model"] != "cm":
        raise ValueError(f"margins: a design on the CM is needed, this one's design_model is "
                         f"'{design.case['design_model']}' (the ECM models the notch in its "
                         "plant)")  # fmt: skip
    case, a = design.case, design.arrays
    tau = float(case["tube"]["tau"])
    out = []
    for name in case["variants"]:
        v = VARIANTS[name]
        if not LAWS[v.law].has_tube:
            continue
        nt = variant_notch(case["notch"], v.notch, a["omega_flex"])
        label = "off" if nt is None else ("omega_2" if v.notch == "mode2" else "omega_1")
        F = tau * np.asarray(a.get(variant_gain_key(name), a["F"]), float)
        out.append(NotchSetting(label, name, None if nt is None else NotchFilter(**nt), F))
    first = next((s for s in out if s.label == "omega_1"), None)
    if first is not None and first.notch.eps_p != PAPER_EPS_P:
        paper = replace(first.notch, eps_p=PAPER_EPS_P)
        out.append(NotchSetting(f"omega_1, eps_p {PAPER_EPS_P:g}", first.variant, paper,
                                first.F))  # fmt: skip
    return out


def design_point_plant(design) -> Plants:
    """The LPV model (eq. 12) at the design step's (h0, V0), one point.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design

    Returns
    -------
    Plants
        The point "design point".
    """
    a, step = design.arrays, design.case["design_step"]
    lpv = PolytopicLPV(*(a[k] for k in ("A", "B", "h_grid", "V_grid", "W_h", "W_V")))
    A, B = lpv.systems([step["h0"]], [step["V0"]])
    return Plants(("design point",), A, B)


def vertex_plants(design) -> Plants:
    """The design's LPV vertices A_i, B_i (eq. 12).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design

    Returns
    -------
    Plants
        Points "vertex 0" ... "vertex R-1".
    """
    A, B = design.arrays["A"], design.arrays["B"]
    return Plants(tuple(f"vertex {i}" for i in range(len(A))), A, B)


def corner_plants(design, vehicle) -> Plants:
    """One-period Jacobians of every corner vehicle of the parameter box at the design point.

    Each corner of the sec. 5.1 box (times the design's `uncertainty.scale`) linearised
    at the nominal vehicle's trim at (h0, V0) by central differences through the plant's
    RK4 (`fahv.bounds.plant_step.jacobians`): the Jacobian of the tube error along
    the nominal, as the design forms its vertices.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    vehicle : fahv.model.vehicle.Vehicle
        The nominal vehicle the design was made for.

    Returns
    -------
    Plants
        Points "corner 0" ... (2^10 for the sec. 5.1 box), the corners in the order of
        `fahv.analysis.margins.corner_signs` over `PAPER_UNCERTAINTY`.
    """
    a, case = design.arrays, design.case
    rel = {k: v * float(case["uncertainty"]["scale"]) for k, v in PAPER_UNCERTAINTY.items()}
    signs = corner_signs(len(rel))
    recs = perturbed_records(vehicle.params, rel, signs)
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    x_r, u_r = tm.at([case["design_step"]["h0"]], [case["design_step"]["V0"]])
    C = len(recs)
    scale = np.r_[a["Dx"], a["Du"]]
    J = jacobians(np.repeat(x_r, C, 0), np.repeat(u_r, C, 0), recs, case["Ts"],
                  case["plant_substeps"], scale)  # fmt: skip
    return Plants(tuple(f"corner {c}" for c in range(C)), J[:, :, :9], J[:, :, 9:])


@dataclass
class MarginStudy:
    """The margins of one design (`margin_study`).

    Attributes
    ----------
    design_name : str
    Ts : float
        Control period [s].
    omega_flex : (2,) ndarray
        Flexible-mode frequencies omega_1, omega_2 [rad/s].
    settings : list of NotchSetting
    design_point : list of LoopMargins
        Every setting and break at the design point.
    vertices : list of LoopMargins
        The worst case over the LPV vertices, per setting evaluated and break.
    corners : list of LoopMargins
        At the corner of the parameter box whose airframe is the most unstable (largest
        open-loop spectral radius), per setting and break (its `point` names it).
    corner_rho : dict
        {setting label: (2^P,) closed-loop spectral radius at every corner}.
    vertex_rows : list of LoopMargins
        Every vertex's margins (the rows of `vertices`).
    """

    design_name: str
    Ts: float
    omega_flex: np.ndarray
    settings: list
    design_point: list = field(default_factory=list)
    vertices: list = field(default_factory=list)
    corners: list = field(default_factory=list)
    corner_rho: dict = field(default_factory=dict)
    vertex_rows: list = field(default_factory=list)

    def table_rows(self) -> list[LoopMargins]:
        """Design point, vertices' worst case and screened corner, by break and setting."""
        rows = self.design_point + self.vertices + self.corners
        order = {s.label: i for i, s in enumerate(self.settings)}
        return sorted(rows, key=lambda r: (BREAKS.index(r.break_at), order[r.notch]))


def _evaluate(plants: Plants, setting: NotchSetting, Ts, w, w1, break_at) -> list[LoopMargins]:
    """Margins of one setting and break at every point of `plants`."""
    rho = spectral_radius(closed_loop(plants.A, plants.B, setting.F, setting.notch, Ts))
    systems = loop_systems(plants, setting.F, setting.notch, Ts, break_at)
    return [loop_margins(L, r, w, w1, (break_at, setting.label, name))
            for L, r, name in zip(systems, rho, plants.names, strict=True)]  # fmt: skip


def margin_study(design, vehicle, every_setting: bool = False, corners: bool = True,
                 name: str = "") -> MarginStudy:  # fmt: skip
    """The loop margins of a stored design (module docstring).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
        A nine-state design.
    vehicle : fahv.model.vehicle.Vehicle
        Its nominal vehicle (for the parameter box corners).
    every_setting : bool
        Evaluate every notch setting over the vertices, not only the first setting with
        the notch at omega_1 and the first without a notch.
    corners : bool
        Check the parameter box corners.
    name : str
        Design name for the report.

    Returns
    -------
    MarginStudy

    Raises
    ------
    ValueError
        If the design is not on the CM (`design_model` cm).
    """
    Ts, wf = float(design.case["Ts"]), np.asarray(design.arrays["omega_flex"], float)
    study = MarginStudy(name, Ts, wf, notch_settings(design))
    w, w1 = frequency_grid(Ts, wf), float(wf[0])
    point, verts = design_point_plant(design), vertex_plants(design)
    main = {s.label for s in study.settings if s.label in ("off", "omega_1")}
    cp = corner_plants(design, vehicle) if corners else None
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # python-control's notes on its numerics
        for break_at in BREAKS:
            for s in study.settings:
                study.design_point += _evaluate(point, s, Ts, w, w1, break_at)
                if every_setting or s.label in main:
                    rows = _evaluate(verts, s, Ts, w, w1, break_at)
                    study.vertex_rows += rows
                    study.vertices.append(worst_case(rows, f"worst of {len(rows)} vertices"))
                if cp is not None:
                    study.corners.append(_worst_corner(study, cp, s, w, w1, break_at))
    return study


def _worst_corner(study: MarginStudy, cp: Plants, s: NotchSetting, w, w1, break_at):
    """Margins at the corner of the most unstable airframe; records every closed-loop radius.

    The corner screened is the one whose A has the largest spectral radius (the fastest
    short-period divergence): a screen, not the worst case of the margins over the
    corners, which would take python-control 2^10 evaluations per loop.
    """
    if s.label not in study.corner_rho:
        study.corner_rho[s.label] = spectral_radius(closed_loop(cp.A, cp.B, s.F, s.notch,
                                                                study.Ts))  # fmt: skip
    c = int(np.argmax(spectral_radius(cp.A)))
    one = Plants((f"corner {c} (most unstable airframe)",), cp.A[c : c + 1],
                 cp.B[c : c + 1])  # fmt: skip
    return _evaluate(one, s, study.Ts, w, w1, break_at)[0]
