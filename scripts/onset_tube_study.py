"""A tube shaped for the onset's jump: Z_8 designed to contain the first step of a loss.

Usage: python scripts/onset_tube_study.py [--pair PAIR.npz] [--loss L] [--kappa K ...]
                                          [--k K] [--w-scale S]
                                          [--attitude-support DEG] [--grow-box 6 x D]
                                          [--grow-other 5 x D]

Item 3's bound (`fahv.design.eight_state.onset_bound`) keeps e in Z_8 through the onset
if min(c, c_w) + the jump's pulse peak <= 1. On the closed pairs the first jump of a 24 %
loss alone is about 2.1 times Z_8, so no analysis of those pairs certifies more than a
few per cent (docs/control_design.md, "Sharper onset analyses"). Those analyses kept
the tube gain F_8. Here the tube LMI (24) designs F and Z together with the jumps as a
constraint: every jump J / rho_f at the loss lies in kappa Z (``contain`` of
:func:`fahv.synthesis.feedback.design_tube`), and W_8 is re-bounded over the pair's own
product set until it closes (:func:`fahv.design.eight_state.close_pair`) on the stored
pair's scheduling box. For each kappa the script prints the closure (or where it stops:
the LMI, the box, the iterations), the tightening and supports against the stored
pair's, and, when it closes, the design's onset bound on the new pair (the certified
loss).

docs/control_design.md, "A tube shaped for the onset's jump (measured 2026-11-25, stop 48)".
"""

import argparse
import time
from pathlib import Path

import numpy as np

from fahv.control.nominal_mpc import estimator_gains
from fahv.design.along_nominal import SchedulingBox, nominal_vertices, onset_jumps
from fahv.design.eight_state import EIGHT_STATES, EightStatePair, close_pair, onset_bound
from fahv.design.feasibility import input_room
from fahv.errors import DesignError
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import trim_map
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY

TS, N_SUB = 0.02, 5  # case1.yaml's period and RK4 sub-steps


def report(label, pair, ref_pair):
    """One block of lines: tightening, supports / the stored pair's."""
    sz, tf = np.sqrt(np.diag(pair.N8)), pair.tightening
    rz, rt = np.sqrt(np.diag(ref_pair.N8)), ref_pair.tightening
    print(f"  {label}: tightening {tf[0]:.4f} / {np.degrees(tf[1]):.3f} deg "
          f"(stored pair {rt[0]:.4f} / {np.degrees(rt[1]):.3f} deg); alpha support "
          f"{np.degrees(sz[1]):.3f} deg; W_8 / stored W_8 "
          + " ".join(f"{v:.2f}" for v in pair.W8 / ref_pair.W8), flush=True)  # fmt: skip
    print("    supports / the stored pair's: "
          + ", ".join(f"{n} {v:.2f}" for n, v in zip(EIGHT_STATES, sz / rz, strict=True)),
          flush=True)  # fmt: skip


def main() -> None:
    """Run the study of the module docstring."""
    here = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pair", type=Path, default=here / "tests/data/closed_tube_h_reset.npz")
    ap.add_argument("--loss", type=float, default=0.24)
    ap.add_argument("--kappa", type=float, nargs="+", default=[1.0, 0.5])
    ap.add_argument("--iterations", type=int, default=4)
    ap.add_argument("--interior", type=int, default=256)
    ap.add_argument("--k", type=int, default=None, help="parameter directions (the pair's)")
    ap.add_argument("--w-scale", type=float, default=1.0,
                    help="the closure starts from this multiple of the stored W_8")  # fmt: skip
    ap.add_argument(
        "--grow-other",
        type=float,
        nargs=5,
        default=[0.0] * 5,
        help="added to the box's half-widths in q [rad/s] and the flexible states",
    )
    ap.add_argument(
        "--grow-box",
        type=float,
        nargs=6,
        default=[0.0] * 6,
        help="taken from the box's lower and added to its upper ends in h, V, alpha, theta, "
        "Phi, delta_e [ft, ft/s, rad, rad, -, rad]",
    )
    ap.add_argument(
        "--steady-lams",
        type=float,
        nargs="+",
        default=[0.995, 0.993, 0.998],
        help="contraction factors tried for the steady set (the onset bound's c_w)",
    )
    ap.add_argument(
        "--attitude-support",
        type=float,
        default=None,
        metavar="DEG",
        help="bound Z_8's supports in alpha and theta too (item 5: 0.5 deg less mpc.att_max)",
    )
    ap.add_argument("--no-reference", action="store_true", help="skip the stored pair's bound")
    o = ap.parse_args()
    t0 = time.perf_counter()
    d = dict(np.load(o.pair))
    veh, unc = load_vehicle(), dict(PAPER_UNCERTAINTY)
    tm = trim_map(veh, 13, 13)
    g = np.asarray(o.grow_box)
    box = SchedulingBox(d["lo"] - g, d["hi"] + g, d["other_half"] + np.asarray(o.grow_other))
    nominal = SchedulingBox(d["nominal_lo"], d["nominal_hi"], d["nominal_other_half"])
    tp = build_tp_model(veh, "cm", 4, 5, 21, 21)
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    rho = float(d["rho_min"])
    nv = nominal_vertices(box, veh, tm, unc, rho, TS, N_SUB, scale,
                          int(d["k"]) if o.k is None else o.k,
                          d["w_design"], d["col_scale"], hessians=False)  # fmt: skip
    room = input_room(veh, rho_f=rho)
    ref = EightStatePair(d["F"], d["N"], d["W"], float(d["H"]), float(d["lam"]), d["bound"],
                         0.0, int(d["moves"]), 0.0, 0.0)  # fmt: skip
    gamma, gamma_e = estimator_gains(TS, 0.1, TS)
    est = {"gamma_e": gamma_e, "directions": tp.discretize(TS).B[:, :, 1],
           "projection_scale": tp.state_scale}  # fmt: skip
    print(f"vertex data {nv.n_vertices} vertices ({time.perf_counter() - t0:.0f} s)", flush=True)
    if not o.no_reference:
        ob = onset_bound(nv, ref, veh, tm, unc, gamma, TS, N_SUB, interior=o.interior, **est)
        print("stored pair:", *ob.lines(), sep="\n  ", flush=True)
    J, _ = onset_jumps(box, veh, tm, unc, 1.0 - o.loss, TS, N_SUB, o.interior)
    J8 = J[:, 1:] / (1.0 - o.loss)
    print(f"{len(J8)} jumps at a {100 * o.loss:.0f} % loss ({time.perf_counter() - t0:.0f} s)",
          flush=True)  # fmt: skip
    state_max = None
    if o.attitude_support is not None:  # as eight_state_pair does for certify_attitude
        state_max = np.full(8, np.inf)
        state_max[1:3] = np.radians(o.attitude_support)
    for kappa in o.kappa:
        print(f"kappa {kappa}: every jump inside {kappa} Z_8", flush=True)
        try:
            pair = close_pair(nv, nominal, o.w_scale * d["W"], scale[:9], scale[9:], room,
                              float(d["lam"]), int(d["moves"]), iterations=o.iterations,
                              w_ref=d["w_design"], contain=J8 / kappa, state_max=state_max,
                              log=lambda s: print("  " + s, flush=True))  # fmt: skip
        except DesignError as exc:
            print(f"  not closed: {exc} ({time.perf_counter() - t0:.0f} s)", flush=True)
            continue
        report("closed", pair, ref)
        ob = onset_bound(nv, pair, veh, tm, unc, gamma, TS, N_SUB, interior=o.interior,
                         steady_lams=o.steady_lams, **est)  # fmt: skip
        print(*ob.lines(), sep="\n  ", flush=True)
        print(f"  ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
