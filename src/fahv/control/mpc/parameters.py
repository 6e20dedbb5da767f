"""Node parameters of the nominal MPC: their declarations and their values from a design.

The nominal_trajectory node's `mpc.*` parameters: the design file's `mpc` section
(`fahv.control.mpc.settings.MPC_SECTION_FIELDS`) under `mpc.`, the attitude bounds the
design chose, the design's nominal boxes (`mpc.u_box`, `mpc.hv_box`, `mpc.x_box`) and the
run's start of the disturbance estimate (`mpc.est_start`).
"""

from __future__ import annotations

import dataclasses

import numpy as np

from fahv.config import Field
from fahv.control.mpc.estimator import EST_STARTS
from fahv.control.mpc.settings import MPC_SECTION_FIELDS, X_BOX_TO_STATE

#: Node parameter `mpc.att_max`: the bounds the design chose (alpha, theta).
ATT_MAX_PARAMETER = Field(
    "mpc.att_max", "floats", "bounds on the nominal |alpha - alpha_r| and |theta - theta_r| "
    "(from the nominal trim) of the QP's attitude rows, from the design (the default only "
    "fills the parameter of runs without the nominal MPC)", unit="deg", lo=0.0,
    lo_open=True, hi=10.0, length=2, default=(0.35, 0.35),
)  # fmt: skip

#: Node parameter `mpc.u_box`: the nominal box's input ranges the design assumed.
U_BOX_PARAMETER = Field(
    "mpc.u_box", "floats", "rows on the manoeuvre part of the nominal input (the input minus "
    "the set point's steady input, trim plus estimate shift): Phi lo, Phi hi, delta_e lo, "
    "delta_e hi (Phi -, delta_e deg), from the design's nominal box less the box corners' "
    "trim offsets (tube.form eight_state); all 0: no rows", lo=-30.0, hi=30.0, length=4,
    default=(0.0, 0.0, 0.0, 0.0),
)  # fmt: skip

#: Node parameter `mpc.hv_box`: the nominal box's h and V ranges the design assumed.
HV_BOX_PARAMETER = Field(
    "mpc.hv_box", "floats", "the nominal's altitude and speed range: h lo, h hi [ft], V lo, "
    "V hi [ft/s], from the design's nominal box (tube.form eight_state: the envelope less "
    "eight_state.h_margin, V_margin); the set point stays in it and rows keep the predicted "
    "nominal in it; all 0: none", lo=0.0, hi=1e6, length=4, default=(0.0, 0.0, 0.0, 0.0),
)  # fmt: skip

#: Node parameter `mpc.x_box`: the range of the nominal's other states the certificate covers.
X_BOX_PARAMETER = Field(
    "mpc.x_box", "floats", "the range the tube's certificate covers for the nominal's alpha, "
    "theta [deg], q [deg/s], eta_1, eta_1_dot, eta_2, eta_2_dot (from the nominal vehicle's "
    "trim at the nominal's own h, V): 7 lows then 7 highs, from the design (tube.form "
    "eight_state: the scheduling box less the tube); rows keep the predicted nominal in it; "
    "all 0: none", lo=-1e3, hi=1e3, length=14, default=(0.0,) * 14,
)  # fmt: skip

#: Node parameter `mpc.est_start`: how the state-disturbance estimate starts.
EST_START_PARAMETER = Field(
    "mpc.est_start", "str", "start of the state-disturbance estimate: first (the first "
    "residual initialises it, a loop on the exact state), mean (the mean of the residuals "
    "so far until the filter's own gain takes over) or zero (from d = 0 with the filter's "
    "gain), both for a loop on a state estimate: scenario key estimator.nominal_est_start)",
    choices=EST_STARTS, default=EST_STARTS[0],
)  # fmt: skip

#: Node parameters of the nominal MPC: its case section's keys under `mpc.` (`att_max`
#: as the design's bounds), the design's `mpc.u_box`, `mpc.hv_box` and `mpc.x_box`, and
#: the run's `mpc.est_start`.
MPC_NODE_PARAMETERS = (
    *(
        ATT_MAX_PARAMETER if f.name == "att_max" else dataclasses.replace(f, name=f"mpc.{f.name}")
        for f in MPC_SECTION_FIELDS
    ),
    U_BOX_PARAMETER,
    HV_BOX_PARAMETER,
    X_BOX_PARAMETER,
    EST_START_PARAMETER,
)


def node_values(arrays: dict, case: dict) -> dict:
    """`mpc.*` node parameters from the case's `mpc` section (defaults if absent).

    Parameters
    ----------
    arrays : dict
        The design's arrays: `att_max` (2,) [rad] (the design's attitude bounds,
        `fahv.control.mpc.attitude.attitude_bounds`) and, where the design has them,
        `x_box` (2, 7), `hv_box` (2, 2) [ft, ft/s], `u_box` (2, 2) [Phi, delta_e rad].
    case : dict
        The validated design file (its `mpc` section).

    Returns
    -------
    dict
        Node parameter name -> value (lists of floats; angles in degrees).
    """
    mpc = case.get("mpc") or {f.name: f.default for f in MPC_SECTION_FIELDS}
    out = {
        f"mpc.{k}": ([float(x) for x in v] if isinstance(v, tuple | list) else v)
        for k, v in mpc.items()
    }
    out["mpc.att_max"] = [float(v) for v in np.degrees(arrays["att_max"])]
    xb = arrays.get("x_box")  # (2, 7) [lo, hi] of the certified range (states 2..8)
    out["mpc.x_box"] = (
        [0.0] * 14 if xb is None else [float(v) for v in (xb / X_BOX_TO_STATE).reshape(-1)]
    )  # fmt: skip
    hv = arrays.get("hv_box")  # (2, 2) [[h lo, V lo], [h hi, V hi]] of the design
    out["mpc.hv_box"] = (
        [0.0] * 4 if hv is None
        else [float(hv[0, 0]), float(hv[1, 0]), float(hv[0, 1]), float(hv[1, 1])]
    )  # fmt: skip
    box = arrays.get("u_box")  # (2, 2) [[Phi lo, de lo], [Phi hi, de hi]] of the design
    out["mpc.u_box"] = (
        [0.0] * 4 if box is None
        else [float(box[0, 0]), float(box[1, 0]),
              float(np.degrees(box[0, 1])), float(np.degrees(box[1, 1]))]
    )  # fmt: skip
    return out
