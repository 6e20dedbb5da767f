"""Case 1 in closed loop on the tube with h outside it (docs/control_design.md).

The eight-state pair of ``scripts/h_reset_study.py`` (tests/data/closed_tube_h_reset.npz)
is closed on assumptions about the loop it runs in: the nominal on the nominal vehicle's
CM, its altitude reset to the measured one at every re-plan (``mpc.h_reset``), the
ancillary gain F blind to e_h, the nominal inside the pair's nominal box, and the
disturbance estimate's error within W_8's slack. This study runs that loop: Case 1's
design with the pair's F and tightening in place of the design's, ``mpc.nominal_model
cm``, ``mpc.h_reset``, rate rows ``mpc.du_max``, on the case's vehicle and on corners of
the sec. 5.1 box, with elevator losses at several onsets. Per run it prints settling,
attitude, the QP counters (the re-plan after each reset), and what the certificate
assumes, measured along the run:

* the eight-state level e_8' N_8^-1 e_8 (<= 1: inside Z_8) overall, before the loss and
  from its onset on, and |e_h| / H (<= 1: inside the reset's bound);
* the nominal's largest reach beyond the pair's nominal box, per coordinate, in units
  of the box's half-width (<= 0: inside).

Usage (after `fahv design offline_design/case1_vertex.yaml`):
    .venv/bin/python scripts/h_reset_loop_study.py [--rates P:E] [--losses L,...]
        [--onsets T,...] [--corners C] [--corner-ids I,...] [--duration S] [--no-reset]
        [--att-max DEG] [--pair FILE]
--pair: another eight-state pair (``scripts/h_reset_study.py --save``); the stored one
by default.
"""

import argparse
import itertools
import time

import numpy as np
from along_nominal_study import ROOT

from fahv.design.along_nominal import SchedulingBox
from fahv.design.artefacts import load_design
from fahv.design.eight_state import EightStatePair
from fahv.loop.params import flat_parameter
from fahv.loop.simulate import simulate
from fahv.model.trim import TrimMap
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY, perturb
from fahv.runs.metrics import metrics

PAIR = ROOT / "tests" / "data" / "closed_tube_h_reset.npz"


def pair_overrides(pair: dict, veh, rates, reset: bool) -> dict:
    """Node parameter overrides that put the eight-state pair into Case 1's loop.

    F (2, 9) is the pair's F_8 with a zero column for h; N (9, 9) is diag(H^2, N_8)
    (the node's tube level is then a bound, not the product set's level, which this
    study computes itself); the nominal MPC's input limits are the actuator limits
    tightened by the support of F_8 Z_8 (eq. 30).
    """
    nan = float("nan")  # figures of the closure the stored file does not carry
    es = EightStatePair(pair["F"], pair["N"], pair["W"], float(pair["H"]), float(pair["lam"]),
                        pair["bound"], nan, int(pair["moves"]), nan, nan)  # fmt: skip
    F, N, t = es.F, es.N, es.tightening
    lo, hi = veh.limits.u_min + t, veh.limits.u_max - t
    mpc = {"mpc.nominal_model": "cm", "mpc.h_reset": reset, "mpc.du_max": list(rates),
           **flat_parameter("u_lo", lo), **flat_parameter("u_hi", hi)}  # fmt: skip
    return {
        "tube_mpc": {**flat_parameter("F", F), **flat_parameter("N", N)},
        "nominal_trajectory": mpc,
    }


def assumption_figures(run, pair: dict, tm) -> dict:
    """What the pair assumes, measured along one run (module docstring).

    Returns l8 (N,) the eight-state levels, eh (N,) |e_h| / H, and reach (11,) the
    nominal's largest excursion beyond the nominal box per coordinate (h, V, alpha,
    theta, Phi, delta_e, then q and the flexible states) in units of the box's
    half-width (<= 0: inside).
    """
    e = run.x - run.x_r - run.x_n[:, :9]
    N8_inv = np.linalg.inv(pair["N"])
    l8 = np.einsum("ki,ij,kj->k", e[:, 1:], N8_inv, e[:, 1:])
    eh = np.abs(e[:, 0]) / float(pair["H"])
    F = np.hstack([np.zeros((2, 1)), pair["F"]])
    X = run.x_r + run.x_n[:, :9]
    v = run.u - e @ F.T  # the nominal input: u = v + F e (tau = 1)
    x_t, u_t = tm.at(X[:, 0], X[:, 1])
    s = np.column_stack([X[:, 0], X[:, 1], X[:, 2] - x_t[:, 2], X[:, 3] - x_t[:, 3],
                         v - u_t])  # fmt: skip
    box = SchedulingBox(pair["nominal_lo"], pair["nominal_hi"], pair["nominal_other_half"])
    half = 0.5 * (box.hi - box.lo)
    reach6 = np.maximum(box.lo - s, s - box.hi).max(axis=0) / half
    oth = np.abs(X[:, 4:9] - x_t[:, 4:9]).max(axis=0)
    reach5 = (oth - box.other_half) / box.other_half
    return {"l8": l8, "eh": eh, "reach": np.r_[reach6, reach5]}


def corner_parameters(veh, n: int, ids=()) -> list[tuple[str, dict]]:
    """The case's draw, then n corners of the sec. 5.1 box and the corners ``ids``.

    The n corners come in a fixed random order; ``ids`` index the corners in
    :func:`itertools.product` order of the sorted parameter names (-1 first). Returns
    (label, plant parameter overrides) per vehicle.
    """
    names = sorted(PAPER_UNCERTAINTY)
    corners = list(itertools.product((-1.0, 1.0), repeat=len(names)))
    order = np.random.default_rng(7).permutation(len(corners))
    out = [("case", {})]
    for i in [*order[:n], *ids]:
        vp = perturb(veh.params, PAPER_UNCERTAINTY, dict(zip(names, corners[i], strict=True)))
        out.append((f"corner {i}", {f"params.{k}": float(getattr(vp, k)) for k in names}))
    return out


def main():
    """Run the study of the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rates", default="0.02:0.2")
    ap.add_argument("--losses", default="0.1")
    ap.add_argument("--onsets", default="100")
    ap.add_argument("--corners", type=int, default=0)
    ap.add_argument("--corner-ids", default="")
    ap.add_argument("--duration", type=float, default=0.0)
    ap.add_argument("--no-reset", action="store_true")
    ap.add_argument("--att-max", type=float, default=0.0)
    ap.add_argument("--pair", default=str(PAIR))
    o = ap.parse_args()
    design = load_design(ROOT / "offline_design" / "artefacts" / "case1_vertex")
    a, veh = design.arrays, load_vehicle()
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    pair = dict(np.load(o.pair))
    p, e = (float(v) for v in o.rates.split(":"))
    base = pair_overrides(pair, veh, (p, e), not o.no_reset)
    if o.att_max > 0.0:  # the QP's attitude rows [deg] (the case's: 0.40)
        base["nominal_trajectory"]["mpc.att_max"] = [o.att_max, o.att_max]
    print(
        f"pair: H {float(pair['H']):.2f} ft, tightening "
        f"{np.sqrt(pair['F'][0] @ pair['N'] @ pair['F'][0]):.4f} / "
        f"{np.degrees(np.sqrt(pair['F'][1] @ pair['N'] @ pair['F'][1])):.3f} deg; rates "
        f"{p:g} / {e:g} deg per move; reset {'on' if not o.no_reset else 'OFF'}",
        flush=True,
    )
    dur = o.duration or None
    ids = [int(v) for v in o.corner_ids.split(",") if v]
    for label, plant in corner_parameters(veh, o.corners, ids):
        for loss, onset in itertools.product(
            (float(v) for v in o.losses.split(",")), (float(v) for v in o.onsets.split(","))
        ):
            ov = {k: dict(v) for k, v in base.items()}
            ov["fault_injector"] = {"rho_f": 1.0 - loss, "t_onset": onset}
            if plant:
                ov["plant"] = plant
            t0 = time.time()
            run = simulate(design, "tube_mpc", duration=dur, overrides=ov)
            m = metrics(run, veh.limits)
            f = assumption_figures(run, pair, tm)
            pre = run.t < onset
            post = ~pre
            qp = run.qp_counts.tolist()
            print(f"vehicle {label}, loss {100 * loss:g} % at "
                  f"{onset:g} s ({time.time() - t0:.0f} s): settling {m['settling_time_h_s']:.1f}"
                  f" / {m['settling_time_V_s']:.1f} s; end {m['h_err_final_ft']:+.2f} ft "
                  f"{m['V_err_final_fps']:+.2f} ft/s; attitude {m['alpha_err_max_deg']:.3f} / "
                  f"{m['theta_err_max_deg']:.3f} deg (own trim "
                  f"{m.get('alpha_err_own_trim_max_deg', float('nan')):.3f} / "
                  f"{m.get('theta_err_own_trim_max_deg', float('nan')):.3f}); QP "
                  f"solves/shifted/terminal/recovered {qp}\n"
                  f"  l8 max {f['l8'].max():.3f} (before the loss "
                  f"{f['l8'][pre].max() if pre.any() else float('nan'):.3f}, from its onset "
                  f"{f['l8'][post].max() if post.any() else float('nan'):.3f}; first 1 s "
                  f"{f['l8'][run.t < 1.0].max():.3f}); |e_h| / H max {f['eh'].max():.3f}; "
                  f"nominal beyond its box (half-widths) "
                  + " ".join(f"{r:+.2f}" for r in f["reach"]), flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
