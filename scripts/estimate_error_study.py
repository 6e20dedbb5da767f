"""The disturbance estimate's error along Case 1 against the rate rows of the nominal MPC.

With the nominal on the nominal vehicle's CM (``mpc.nominal_model: cm``) the tube error
obeys e+ = J_p [e; P F e] + w2(e) + eps, where eps_k+1 = r_k+1 - d_k is what the disturbance
estimate d has not yet taken of the residual r_k = x_k - f_0(x_k-1, u_k-1) (f_0 one
period of the nominal CM, u the controller's command of step k-1, exactly as the
nominal_trajectory node filters it). The closed pair along the nominal
(tests/data/closed_tube_along_nominal.npz) assumes eps = 0; this study measures eps over
full Case 1 runs for several ``mpc.du_max`` (rate rows on the nominal input), with
settling and attitude, so that the rate a certified tube needs can be read off.

Usage (after `fahv design offline_design/case1_vertex.yaml`):
    .venv/bin/python scripts/estimate_error_study.py [--rates P:E,...] [--est-tau T,...]
--rates: comma-separated Phi:delta_e[deg] pairs per move (0:0 no rate rows);
--est-tau: the estimate's time constants [s]. Prints one line per run: settling h / V
after the step, h / V error at the end, max attitude error, QP counters, and max |eps|
per row as a multiple of the closed pair's W over the estimate's start-up (t < 5 est_tau:
it starts at d = 0 while the dispersed vehicle's residual is there from t = 0), the
manoeuvre (from then to the fault onset) and from the onset on, where it also prints
the largest level eps' N^-1 eps of one step's eps in the closed pair's Z and in the
design's Z (--rho sets the loss).
"""

import argparse
import time
from pathlib import Path

import numpy as np

from fahv.control.nominal_mpc import DisturbanceEstimator
from fahv.design.artefacts import load_design
from fahv.loop.simulate import simulate
from fahv.model.vehicle import load_vehicle
from fahv.plant.rk4 import params_records, rk4_cm
from fahv.runs.metrics import metrics

ROOT = Path(__file__).resolve().parents[1]
ROWS = ("h", "V", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")


def estimate_error(run, Ts: float, n_sub: int, est_tau: float) -> np.ndarray:
    """The estimate's error (N, 9) over each step, recomputed as the node computes d.

    eps_k+1 = r_k+1 - d_k: the nominal moves from step k to k+1 with the estimate d_k of
    step k, the plant with the residual r_k+1 of that step. r_k = x_k - f_0(x_k-1,
    u_k-1) with the nominal vehicle's RK4 (the plant's kernel) and the controller's
    commands clipped to the actuator limits; d_k = d_k-1 + gamma (r_k - d_k-1), gamma =
    Ts / est_tau, d_0 = 0; eps_0 = 0.
    """
    veh = load_vehicle()
    rec = params_records([veh.params] * (run.x.shape[0] - 1))
    u = np.clip(run.u[:-1], veh.limits.u_min, veh.limits.u_max)
    f0 = rk4_cm(np.ascontiguousarray(run.x[:-1]), np.ascontiguousarray(u), rec, Ts, n_sub)
    r = run.x[1:] - f0
    est = DisturbanceEstimator(1, 9, min(1.0, Ts / est_tau))  # the node's estimate
    eps = np.zeros_like(run.x)
    for k in range(r.shape[0]):
        eps[k + 1] = r[k] - est.d[0]  # the step k -> k+1 moves the nominal with d_k
        est.update_residual(r[k][None])
    return eps


def main():
    """Run Case 1 for each rate and estimate time constant of the command line."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--design", default=str(ROOT / "offline_design" / "artefacts" / "case1_vertex"))
    ap.add_argument("--rates", default="0:0,0.05:0.5,0.02:0.2,0.01:0.1")
    ap.add_argument("--est-tau", default="0.5")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--rho", type=float, default=0.0, help="fault rho_f (0: the case's)")
    o = ap.parse_args()
    design = load_design(o.design)
    pair = np.load(ROOT / "tests" / "data" / "closed_tube_along_nominal.npz")
    W, N_inv = pair["W"], np.linalg.inv(pair["N"])
    Nd_inv = np.linalg.inv(design.arrays["N"])
    Ts, n_sub = design.case["Ts"], design.case["plant_substeps"]
    limits = load_vehicle().limits
    print("rows:", ", ".join(ROWS))
    for tau in (float(v) for v in o.est_tau.split(",")):
        for pair in o.rates.split(","):
            du = [float(v) for v in pair.split(":")]
            ov = {"nominal_trajectory": {"mpc.nominal_model": "cm", "mpc.du_max": du,
                                         "mpc.est_tau": tau}}  # fmt: skip
            if o.rho > 0.0:
                ov["fault_injector"] = {"rho_f": o.rho}
            t0 = time.perf_counter()
            run = simulate(design, "tube_mpc", o.duration, overrides=ov)
            wall = time.perf_counter() - t0
            m = metrics(run, limits)
            eps_abs = estimate_error(run, Ts, n_sub, tau)
            eps = np.abs(eps_abs) / W
            onset = m["t_fault_s"] if np.isfinite(m["t_fault_s"]) else run.t[-1] + 1.0
            start = run.t < 5.0 * tau  # the estimate starts at d = 0: a start-up transient
            climb, fault = ~start & (run.t < onset), run.t >= onset
            print(
                f"du_max {du[0]:g} / {du[1]:g} deg, est_tau {tau:g} s: settling "
                f"{m['settling_time_h_s']:.1f} / {m['settling_time_V_s']:.1f} s, "
                f"end {m['h_err_final_ft']:+.2f} ft / {m['V_err_final_fps']:+.2f} ft/s, attitude "
                f"{m['alpha_err_max_deg']:.3f} / {m['theta_err_max_deg']:.3f} deg, QPs "
                f"{run.qp_counts.tolist()}, tube level {np.nanmax(run.tube_level):.3f} "
                f"({wall:.0f} s)"
            )
            print("  |eps| / W, start-up: " + " ".join(f"{v:.1f}" for v in eps[start].max(axis=0)))
            print("  |eps| / W, manoeuvre: " + " ".join(f"{v:.2f}" for v in eps[climb].max(axis=0)))
            if fault.any():
                print("  |eps| / W, fault: " + " ".join(f"{v:.1f}" for v in eps[fault].max(axis=0)))
                lv = np.einsum("ki,ij,kj->k", eps_abs[fault], N_inv, eps_abs[fault])
                lv_d = np.einsum("ki,ij,kj->k", eps_abs[fault], Nd_inv, eps_abs[fault])
                print(f"  one step of eps from the onset on, level eps' N^-1 eps: {lv.max():.1f} "
                      f"in the closed pair's Z, {lv_d.max():.4f} in the design's Z; e reached "
                      f"{np.nanmax(run.tube_level[fault]):.4f} of the design's Z")  # fmt: skip


if __name__ == "__main__":
    main()
