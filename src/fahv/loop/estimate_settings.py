"""The nominal MPC's settings on a loop that estimates the state.

The design's nominal MPC is made for the exact state. On the estimate its disturbance
estimate, its start and its attitude and elevator rate rows are those of the design's
`estimate` section (an estimate design, `fahv.design.estimate`), where it has one, or of
the scenario's `estimator` section, which replaces them when set.
"""

from __future__ import annotations

from fahv.errors import ConfigError
from fahv.spec.schema import NO_ESTIMATOR, estimator_kind, estimator_value


def estimate_defaults(c: dict, a) -> dict:
    """The estimator section's nominal settings an estimate design gives (0: the design's).

    A design with an `estimate` section (`fahv.design.estimate`) sets the nominal's
    disturbance estimate on the estimate and its rows tightened by the probabilistic
    reachable set; a scenario's own non-zero `estimator.nominal_*` keys replace them.

    Returns
    -------
    dict
        `nominal_est_tau`, `nominal_est_tau_elevator` [s], `nominal_est_start`,
        `nominal_att_max` (2,) [deg] and `nominal_du_max_elevator` [deg] (absent: none).
    """
    est = c.get("estimate")
    if not est or "estimate_att_max_deg" not in a:
        return {}
    return {"nominal_est_tau": float(est["nominal_est_tau"]),
            "nominal_est_tau_elevator": float(est["nominal_est_tau_elevator"]),
            "nominal_est_start": est["nominal_est_start"],
            "nominal_att_max": [float(r) for r in a["estimate_att_max_deg"]],
            "nominal_du_max_elevator": float(a["estimate_du_max_elevator"])}


def nominal_on_estimate(nominal: dict, c: dict, a) -> dict:
    """The nominal node's parameters with the settings for a loop on the estimate.

    Parameters
    ----------
    nominal : dict
        The nominal law's node values from the design (`mpc.est_tau`, `mpc.att_max` [deg],
        ...); returned updated.
    c : dict
        The run spec; its `estimator` section's `nominal_est_tau`,
        `nominal_est_tau_elevator`, `nominal_est_start` and `nominal_att_max` replace the
        design's values when the flight computer estimates the state (0: the design's;
        an estimate design's own settings, `estimate_defaults`, where it has them).
    a : mapping
        The design's arrays.

    Raises
    ------
    fahv.errors.ConfigError
        If `estimator.nominal_att_max` exceeds the design's attitude rows: rows wider
        than the design's would take the nominal outside the range its tube covers.
    """
    if "mpc.est_tau" not in nominal or estimator_kind(c) == NO_ESTIMATOR:
        return nominal
    own = estimate_defaults(c, a)
    for key in ("est_tau", "est_tau_elevator"):
        tau_s = float(estimator_value(c, f"nominal_{key}")) or own.get(f"nominal_{key}", 0.0)
        if tau_s > 0.0:
            nominal[f"mpc.{key}"] = tau_s
    nominal["mpc.est_start"] = ((c.get("estimator") or {}).get("nominal_est_start")
                                or own.get("nominal_est_start")
                                or estimator_value(c, "nominal_est_start"))  # fmt: skip
    att = float(estimator_value(c, "nominal_att_max"))
    if "mpc.att_max" in nominal:
        design_rows = [float(v) for v in nominal["mpc.att_max"]]
        if att > max(design_rows) + 1e-9:
            raise ConfigError(
                f"estimator.nominal_att_max = {att} deg exceeds the design's attitude rows "
                f"{design_rows} deg (mpc.att_max): wider rows leave the range the tube covers"
            )
        rows = [att] * len(design_rows) if att > 0.0 else own.get("nominal_att_max")
        if rows is not None:
            nominal["mpc.att_max"] = [min(r, d) for r, d in zip(rows, design_rows, strict=True)]
    if "nominal_du_max_elevator" in own and "mpc.du_max" in nominal:
        du = [float(v) for v in nominal["mpc.du_max"]]
        nominal["mpc.du_max"] = [du[0], min(du[1], own["nominal_du_max_elevator"])]
    return nominal
