"""W-Z closure of the tube along the nominal (docs/control_design.md, "The error along ...").

With the nominal on the nominal vehicle's nonlinear CM (``mpc.nominal_model: cm``), the
tube error is linearised along the nominal (:mod:`fahv.design.along_nominal`): the
vertices are the nominal vehicle's Jacobians at the 64 corners of a scheduling box
(the whole envelope in h, V; the nominal's attitude and applied-input deviations from
the trim), shifted along K parameter directions, with the fault vertices of rho_min;
W bounds what they leave. Iterates W <- max(W, GROW bound) with the tube LMI (24)
re-solved (constraint generation over the vertices) until the bound lies inside W.

Usage (after `fahv design offline_design/case1_vertex.yaml`):
    .venv/bin/python scripts/along_nominal_study.py [--k K] [--scale S] [--w0 F]
        [--grow G] [--iterations I] [--lam L] [--save FILE]
        [--integral X] [--eps E1,...,E9]
--scale S multiplies the nominal ranges (attitude +/-0.4 deg, Phi -0.12..+1.1,
delta_e -1..+7 deg from the trim, q +/-0.7 deg/s, flexible states); --w0 F starts at
F times the design's W. About 5 minutes for the vertex data, 2 minutes per iteration.
--integral X: the integral form (no second-order part): the nominal keeps the ranges
above (h, V: the envelope shrunk by the tube), the scheduling box is them grown by X
times the supports of Z and F Z of the closed pair in tests/data (the iteration stops
if its own Z outgrows that). --eps: a part of W that does not shrink with Z (the
disturbance estimate's error), per row in units of that pair's W, added to the bound.
--onset L: the onset of a loss L (0.24: the design's) as pulse generators of the tube
(:func:`fahv.design.along_nominal.onset_pulse` over the nominal box, --pulses of them,
what they leave added to the bound): the tube LMI is solved RPI for W plus the pulse,
which keeps e in Z through the onset and the estimate's lag. --flex Y grows the box's q and
flexible half-widths by Y (instead of X) times the supports.
"""

import argparse
import dataclasses
import time
import warnings
from pathlib import Path

import numpy as np

from fahv.design.along_nominal import (
    SchedulingBox,
    bound_along_nominal,
    nominal_vertices,
    onset_pulse,
    segment_supports,
)
from fahv.design.artefacts import load_design
from fahv.design.certificate import worst_level
from fahv.design.feasibility import input_room
from fahv.errors import DesignError
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import TrimMap
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.synthesis.feedback import design_tube

ROOT = Path(__file__).resolve().parents[1]
DEG = np.pi / 180.0


def case1_box(envelope, scale: float = 1.0) -> SchedulingBox:
    """The scheduling box of Case 1's nominal MPC (ranges of the module docstring)."""
    lo = np.array([envelope.h_min, envelope.V_min, -0.4 * DEG * scale, -0.4 * DEG * scale,
                   -0.12 * scale, -1.0 * DEG * scale])  # fmt: skip
    hi = np.array([envelope.h_max, envelope.V_max, 0.4 * DEG * scale, 0.4 * DEG * scale,
                   1.1 * scale, 7.0 * DEG * scale])  # fmt: skip
    return SchedulingBox(lo, hi, np.array([0.7 * DEG, 0.5, 3.5, 0.3, 3.5]) * scale)


def case1_context():
    """Case 1's saved design: (arrays, case dict, vehicle, TP model, trim map)."""
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    d = load_design(ROOT / "offline_design" / "artefacts" / "case1_vertex")
    a, c = d.arrays, d.case
    veh = load_vehicle()
    tp = build_tp_model(veh, "cm", *c["vertices"], *c["samples"])
    return a, c, veh, tp, TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])


def grown(box: SchedulingBox, s6, s5, x: float) -> SchedulingBox:
    """``box`` grown by x times the supports s6 (6,) and s5 (5,) on every side."""
    return SchedulingBox(box.lo - x * s6, box.hi + x * s6, box.other_half + x * s5)


def closure_options(doc: str, k: int, w0: float, integral: float) -> argparse.ArgumentParser:
    """The options every W-Z closure study takes.

    Parameter directions, start, growth, iterations, lam, where to save the pair, the
    integral form's box.
    """
    ap = argparse.ArgumentParser(description=doc.splitlines()[0])
    ap.add_argument("--k", type=int, default=k)
    ap.add_argument("--w0", type=float, default=w0)
    ap.add_argument("--grow", type=float, default=1.05)
    ap.add_argument("--iterations", type=int, default=6)
    ap.add_argument("--lam", type=float, default=0.995)
    ap.add_argument("--save", default="")
    ap.add_argument("--integral", type=float, default=integral)
    return ap


def main():
    """Run the closure of the module docstring with the command-line options."""
    ap = closure_options(__doc__, 3, 0.01, 0.0)
    ap.add_argument("--scale", type=float, default=1.0)
    ap.add_argument("--eps", default="")
    ap.add_argument("--onset", type=float, default=0.0)
    ap.add_argument("--pulses", type=int, default=2)
    ap.add_argument("--flex", type=float, default=0.0)
    o = ap.parse_args()
    a, c, veh, tp, tm = case1_context()
    rho = float(c["tube"]["rho_min"])
    box = nominal = case1_box(veh.envelope, o.scale)
    stored = np.load(ROOT / "tests" / "data" / "closed_tube_along_nominal.npz")
    eps = np.zeros(9)
    if o.eps:
        eps = np.array([float(v) for v in o.eps.split(",")]) * stored["W"]
    if o.integral > 0.0:
        s6, s5 = segment_supports(stored["F"], stored["N"])
        # the nominal's h, V: the envelope shrunk by the tube; the box: the envelope
        nominal = grown(box, np.r_[-s6[:2], np.zeros(4)] * o.integral, np.zeros(5), 1.0)
        flex = o.flex if o.flex > 0.0 else o.integral
        box = grown(nominal, s6, s5 * flex / o.integral, o.integral)
        print("integral form: box = nominal ranges grown by "
              f"{o.integral:g} x the stored pair's supports; eps / stored W "
              + " ".join(f"{v:.2f}" for v in eps / stored["W"]), flush=True)  # fmt: skip
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    t_design = np.sqrt(np.einsum("ij,jk,ik->i", a["F"], a["N"], a["F"]))
    cols = np.concatenate([np.sqrt(np.diag(a["N"])), t_design])
    t0 = time.time()
    nv = nominal_vertices(box, veh, tm, dict(PAPER_UNCERTAINTY), rho, c["Ts"],
                          c["plant_substeps"], scale, o.k, a["w_max"], cols)  # fmt: skip
    A, B = nv.vertices()
    print(f"vertex data: {A.shape[0]} vertices, {sum(nv.n_vehicles)} vehicles "
          f"({time.time() - t0:.0f} s)", flush=True)  # fmt: skip
    room = input_room(veh, rho_f=rho)
    W = a["w_max"] * o.w0
    pulse, rest = None, np.zeros(9)
    if o.onset > 0.0:
        t0 = time.time()
        op = onset_pulse(nominal, veh, tm, dict(PAPER_UNCERTAINTY), 1.0 - o.onset, c["Ts"],
                         c["plant_substeps"], stored["N"], o.pulses)  # fmt: skip
        pulse, rest = op.G, op.remainder
        lev = np.einsum("si,ij,sj->s", op.jumps, np.linalg.inv(stored["N"]), op.jumps)
        print(f"onset of a {100 * o.onset:g} % loss: {len(op.jumps)} jumps ({time.time() - t0:.0f}"
              f" s), level in the stored pair's Z up to {lev.max():.3g}; generators / stored W:\n"
              + "".join("  " + " ".join(f"{v:.2f}" for v in gl / stored["W"]) + "\n"
                        for gl in pulse)
              + "  remainder / stored W: " + " ".join(f"{v:.3f}" for v in rest / stored["W"]),
              flush=True)  # fmt: skip
    for it in range(o.iterations):
        t1 = time.time()
        try:
            tube = design_tube(A, B, W, tp.state_scale, tp.input_scale, room, (o.lam,),
                               w_ref=a["w_max"], active=96, pulse=pulse)  # fmt: skip
        except DesignError as exc:
            print(f"iteration {it}: tube LMI infeasible ({exc})")
            return
        try:
            b = bound_along_nominal(nv, tube.F, tube.N, nominal if o.integral > 0 else None)
        except DesignError as exc:
            print(f"iteration {it}: {exc}")
            return
        if o.eps or o.onset:
            b = dataclasses.replace(b, total=b.total + eps + rest)
        print(
            f"iteration {it} ({time.time() - t1:.0f} s, {tube.n_blocks} of {A.shape[0]} blocks "
            f"active): tightening {tube.tightening[0]:.5f} / {np.degrees(tube.tightening[1]):.4f}"
            f" deg, support of Z in alpha {np.degrees(tube.z_box[2]):.5f} deg\n"
            + "".join(
                f"  {name:>14} / W: " + " ".join(f"{v:.3f}" for v in part / W) + "\n"
                for name, part in (
                    ("parameters", b.parameters),
                    ("interpolation", b.interpolation),
                    ("second order", b.second_order),
                    ("estimate", eps),
                    ("pulse remainder", rest),
                    ("bound", b.total),
                )
            ),  # fmt: skip
            end="",
            flush=True,
        )
        if b.margin is not None:
            print(f"  box margin over nominal + Z: {b.margin.min():+.2f} x the supports "
                  "(smallest coordinate)", flush=True)  # fmt: skip
        if np.all(b.total <= W):
            if pulse is not None:
                level, _ = worst_level(A, B, tube.F, tube.N, W, pulse=pulse)
                sz = np.sqrt(np.diag(tube.N))
                print(f"  exact worst one-step level with the pulse {level:.6f}; supports of Z"
                      f" (alpha, theta deg; q deg/s): {np.degrees(sz[2]):.4f}, "
                      f"{np.degrees(sz[3]):.4f}, {np.degrees(sz[4]):.4f}; pulse multipliers "
                      f"{np.array2string(tube.mu_pulse, precision=3)}", flush=True)  # fmt: skip
            print(
                "closed: slack per row " + " ".join(f"{s:+.3f}" for s in (W - b.total) / W)
                + f"; smallest vertex-block eigenvalue {tube.min_eigs.min():.3g} over all "
                f"{A.shape[0]} vertices; W / design W "
                + " ".join(f"{r:.4g}" for r in W / a["w_max"])
            )  # fmt: skip
            if o.save:
                np.savez(o.save, W=W, F=tube.F, N=tube.N, lam=tube.lam, w_design=a["w_max"],
                         lo=box.lo, hi=box.hi, other_half=box.other_half, k=o.k, rho_min=rho,
                         nominal_lo=nominal.lo, nominal_hi=nominal.hi, eps=eps,
                         nominal_other_half=nominal.other_half,
                         col_scale=cols, bound=b.total, parameters=b.parameters,
                         interpolation=b.interpolation, second_order=b.second_order)  # fmt: skip
                print(f"closed pair written to {o.save}")
            return
        W = np.maximum(W, o.grow * b.total)
    print("not closed within the iterations")


if __name__ == "__main__":
    main()
