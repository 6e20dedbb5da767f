"""More parameter directions in the eight-state vertices: W_8, Z_8, attitude and onset.

Usage: python scripts/parameter_directions_study.py [--pair PAIR.npz] [--k K ...]
                                                    [--w-scale S] [--attitude-support DEG]
                                                    [--iterations N] [--no-onset]

The eight-state pair's vertices hold the scheduling box's 64 corners times 2^k corners of
the parameter box along its first k directions (:func:`fahv.design.certificate.
parameter_directions`), times rho_f at both ends of [rho_min, 1]; what the other
directions leave is the parameter part of W_8's bound
(:func:`fahv.design.eight_state.product_bound`). For each k the script first bounds the
stored pair's own product set (the parameter part and the interpolation part of each row,
as multiples of the stored W_8, and the stored gain's exact level over the larger vertex
set), then re-closes the pair on the stored scheduling box from W_8 = S x the stored W_8
(:func:`fahv.design.eight_state.close_pair`, optionally with Z_8's supports in alpha and
theta bounded, item 5) and prints the design's onset bound for it (item 3).

docs/control_design.md, "Seven parameter directions: item 5 certified on case1.yaml".
"""

import argparse
import time
from pathlib import Path

import numpy as np

from fahv.control.nominal_mpc import estimator_gains
from fahv.design.along_nominal import SchedulingBox, nominal_vertices
from fahv.design.certificate import vertex_levels
from fahv.design.eight_state import (
    EIGHT_STATES,
    EightStatePair,
    altitude_bound,
    close_pair,
    onset_bound,
    product_bound,
)
from fahv.design.feasibility import input_room
from fahv.errors import DesignError
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import trim_map
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY

TS, N_SUB = 0.02, 5  # case1.yaml's period and RK4 sub-steps


def rows(label, values):
    """One line of per-row values (V ... eta_2_dot)."""
    print(f"  {label:<28}" + " ".join(f"{v:.3f}" for v in values), flush=True)


def main() -> None:
    """Run the study of the module docstring."""
    here = Path(__file__).resolve().parents[1]
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pair", type=Path, default=here / "tests/data/closed_tube_h_reset.npz")
    ap.add_argument("--k", type=int, nargs="+", default=[5, 6, 7, 8])
    ap.add_argument("--w-scale", type=float, default=0.5,
                    help="the closure starts from this multiple of the stored W_8")  # fmt: skip
    ap.add_argument("--attitude-support", type=float, default=None, metavar="DEG",
                    help="bound Z_8's supports in alpha and theta (item 5)")  # fmt: skip
    ap.add_argument("--iterations", type=int, default=4)
    ap.add_argument("--interior", type=int, default=256)
    ap.add_argument("--no-closure", action="store_true", help="bound the stored pair only")
    ap.add_argument("--no-onset", action="store_true", help="skip the onset bound")
    o = ap.parse_args()
    t0 = time.perf_counter()
    d = dict(np.load(o.pair))
    veh, unc = load_vehicle(), dict(PAPER_UNCERTAINTY)
    tm = trim_map(veh, 13, 13)
    box = SchedulingBox(d["lo"], d["hi"], d["other_half"])
    nominal = SchedulingBox(d["nominal_lo"], d["nominal_hi"], d["nominal_other_half"])
    tp = build_tp_model(veh, "cm", 4, 5, 21, 21)
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    rho = float(d["rho_min"])
    room = input_room(veh, rho_f=rho)
    W8 = d["W"]
    gamma, gamma_e = estimator_gains(TS, 0.1, TS)
    est = {"gamma_e": gamma_e, "directions": tp.discretize(TS).B[:, :, 1],
           "projection_scale": tp.state_scale}  # fmt: skip
    state_max = None
    if o.attitude_support is not None:  # as design_pair does for certify_attitude
        state_max = np.full(8, np.inf)
        state_max[1:3] = np.radians(o.attitude_support)
    sz0 = np.sqrt(np.diag(d["N"]))
    ref = EightStatePair(d["F"], d["N"], W8, float(d["H"]), float(d["lam"]), d["bound"], 0.0,
                         int(d["moves"]), 0.0, 0.0)  # fmt: skip
    print(
        f"stored pair: W_8 (V ... eta_2_dot) {' '.join(f'{w:.3g}' for w in W8)}; supports "
        f"alpha / theta {np.degrees(sz0[1]):.4f} / {np.degrees(sz0[2]):.4f} deg, tightening "
        f"{ref.tightening[0]:.4f} / {np.degrees(ref.tightening[1]):.3f} deg",
        flush=True,
    )
    for k in o.k:
        nv = nominal_vertices(box, veh, tm, unc, rho, TS, N_SUB, scale, k, d["w_design"],
                              d["col_scale"], hessians=False)  # fmt: skip
        A, B = nv.vertices()
        ab = altitude_bound(nv, A, B, d["F"], d["N"], int(d["moves"]))
        par, interp = product_bound(nv, d["F"], d["N"], ab.H)
        level = vertex_levels(A[:, 1:, 1:] + B[:, 1:, :] @ d["F"], d["N"], W8).max()
        print(f"k = {k}: {A.shape[0]} vertices ({time.perf_counter() - t0:.0f} s); the stored "
              f"pair's exact level over them {level:.6f}", flush=True)  # fmt: skip
        rows("parameter part / W_8", par[1:] / W8)
        rows("interpolation part / W_8", interp[1:] / W8)
        rows("bound / W_8", ab.bound / W8)
        if o.no_closure:
            continue
        try:
            pair = close_pair(nv, nominal, o.w_scale * W8, scale[:9], scale[9:], room,
                              float(d["lam"]), int(d["moves"]), iterations=o.iterations,
                              w_ref=d["w_design"], state_max=state_max,
                              log=lambda s: print("  " + s, flush=True))  # fmt: skip
        except DesignError as exc:
            print(f"  not closed: {exc} ({time.perf_counter() - t0:.0f} s)", flush=True)
            continue
        sz = np.sqrt(np.diag(pair.N8))
        print(f"  closed: level {pair.level:.6f}, tightening {pair.tightening[0]:.4f} / "
              f"{np.degrees(pair.tightening[1]):.3f} deg, supports alpha / theta "
              f"{np.degrees(sz[1]):.4f} / {np.degrees(sz[2]):.4f} deg "
              f"({time.perf_counter() - t0:.0f} s)", flush=True)  # fmt: skip
        rows("W_8 / stored W_8", pair.W8 / W8)
        rows("supports / stored", sz / sz0)
        print("  " + " ".join(EIGHT_STATES), flush=True)
        if not o.no_onset:
            ob = onset_bound(nv, pair, veh, tm, unc, gamma, TS, N_SUB, interior=o.interior, **est)
            print(*ob.lines(), sep="\n  ", flush=True)
        out = Path(f"/tmp/parameter_directions_k{k}.npz")
        np.savez(out, F=pair.F8, N=pair.N8, W=pair.W8, H=pair.H, lam=pair.lam, k=k)
        print(f"  pair saved to {out} ({time.perf_counter() - t0:.0f} s)", flush=True)


if __name__ == "__main__":
    main()
