"""The tube along the nominal with h outside its RPI condition (docs/control_design.md).

The W-Z iteration at the size the onset of a loss needs diverges in the h row: the
kinematic integrator h_dot = V sin(theta - alpha) is held by the tube only through theta
and q, and its W grows with the box. This study takes h out of the tube: the tube is
designed on the other eight states (V, alpha, theta, q, eta_1, eta_1_dot, eta_2,
eta_2_dot) with F blind to e_h, and the altitude error is bounded instead by a reset of
the nominal's h to the measured altitude at every re-plan (M fast steps apart; *assumed*
here, not implemented in the controller):

    |e_h| <= H = M (max over the vertices and Z_8 of |a_h e_8 + b_h F e_8| + w_h),

with the h row's own disturbance w_h. The error e_h then enters the other rows as a
disturbance: max over the vertices of |A_rh| H, added to their W. The disturbance bound
is the integral form's (parameter residual and interpolation, no second-order part) over
the product set {|e_h| <= H} x Z_8, each support exact for the product. Iterates W_8 <-
max(W_8, GROW bound) with the tube LMI re-solved until the bound lies inside W_8, then
prints the exact worst one-step level of the eight-state tube.

Usage (after `fahv design offline_design/case1_vertex.yaml`):
    .venv/bin/python scripts/h_reset_study.py [--integral X] [--k K] [--w0 F]
        [--h-margin FT] [--iterations I]
--save FILE writes the closed pair (and its boxes) for tests/design/test_along_nominal.py.
--integral X: the box is the nominal ranges grown by X times the supports of the stored
pair along the nominal (as in along_nominal_study.py); --h-margin: the nominal's h range
is the envelope shrunk by this [ft], the box's h range the envelope. --resolve S: start
from the stored eight-state pair instead, over its nominal box grown for S times its
tube, and re-solve the iteration there from S times its W_8 (a pair S times the size,
sought rather than scaled); --box-scale B builds that box for B times the tube instead.
"""

import time

import numpy as np
from along_nominal_study import ROOT, case1_box, case1_context, closure_options, grown

import fahv.design.along_nominal as an
import fahv.design.eight_state as es
from fahv.design.certificate import worst_level
from fahv.design.feasibility import input_room
from fahv.errors import DesignError
from fahv.plant.uncertainty import PAPER_UNCERTAINTY


def closure(o, a, tp, nv, nominal, room, W8):
    """The W_8-Z_8 iteration (:func:`fahv.design.eight_state.close_pair`), study options.

    Prints each iteration and the closed pair, or why it did not close (then None).
    """
    try:
        pair = es.close_pair(nv, nominal, W8, tp.state_scale, tp.input_scale, room, o.lam,
                             o.moves, grow=o.grow, iterations=o.iterations, w_ref=a["w_max"],
                             log=lambda line: print(line, flush=True))  # fmt: skip
    except DesignError as exc:
        print(f"not closed: {exc}")
        return None
    N8 = pair.N8
    print(f"closed: slack per row {np.array2string(pair.slack, precision=3)}; exact "
          f"worst one-step level {pair.level:.6f}; Z_8 supports V {np.sqrt(N8[0, 0]):.3f} "
          f"ft/s, alpha {np.degrees(np.sqrt(N8[1, 1])):.4f} deg, theta "
          f"{np.degrees(np.sqrt(N8[2, 2])):.4f} deg, q "
          f"{np.degrees(np.sqrt(N8[3, 3])):.4f} deg/s")  # fmt: skip
    return pair.F8, pair.N8, pair.W8, pair.H, pair.lam, pair.bound


def main():
    """Run the study of the module docstring."""
    ap = closure_options(__doc__, 5, 0.15, 22.0)
    ap.add_argument("--h-margin", type=float, default=150.0)
    ap.add_argument("--moves", type=int, default=25)
    ap.add_argument("--loss", type=float, default=0.24)
    ap.add_argument("--gamma", type=float, default=0.2)
    ap.add_argument("--scales", type=lambda v: [float(x) for x in v.split(",") if x],
                    default=[1.5, 2.0, 3.0, 5.0])  # fmt: skip
    ap.add_argument("--resolve", type=float, default=0.0)
    ap.add_argument("--box-scale", type=float, default=0.0)
    o = ap.parse_args()
    a, c, veh, tp, tm = case1_context()
    rho = float(c["tube"]["rho_min"])
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    room = input_room(veh, rho_f=rho)
    if o.resolve > 0.0:
        return resolve(o, a, c, veh, tp, tm, rho, scale, room)
    env = case1_box(veh.envelope)
    stored = np.load(ROOT / "tests" / "data" / "closed_tube_along_nominal.npz")
    s6, s5 = an.segment_supports(stored["F"], stored["N"])
    shrink = np.r_[-o.h_margin, -s6[1] * o.integral, np.zeros(4)]
    nominal = grown(env, shrink, np.zeros(5), 1.0)
    box = grown(nominal, np.r_[0.0, s6[1:]] * o.integral, s5 * o.integral, 1.0)
    box = an.SchedulingBox(np.r_[env.lo[0], box.lo[1:]], np.r_[env.hi[0], box.hi[1:]],
                           box.other_half)  # fmt: skip
    cols = np.concatenate([np.sqrt(np.diag(a["N"])),
                           np.sqrt(np.einsum("ij,jk,ik->i", a["F"], a["N"], a["F"]))])  # fmt: skip
    t0 = time.time()
    nv = an.nominal_vertices(box, veh, tm, dict(PAPER_UNCERTAINTY), rho, c["Ts"],
                             c["plant_substeps"], scale, o.k, a["w_max"], cols,
                             hessians=False)  # fmt: skip
    A, _ = nv.vertices()
    print(f"vertex data: {A.shape[0]} vertices ({time.time() - t0:.0f} s); A_hh in "
          f"[{A[:, 0, 0].min():.6f}, {A[:, 0, 0].max():.6f}]", flush=True)  # fmt: skip
    pair = closure(o, a, tp, nv, nominal, room, a["w_max"][1:] * o.w0)
    if pair is None:
        return
    F8, N8, W8, H, lam, need8 = pair
    if o.save:
        save_pair(o, a, nv.box, nominal, rho, cols, F8, N8, W8, H, lam, need8)
    onset(o, nv, nominal, veh, tm, c, rho, scale, a["w_max"], cols, F8, N8, W8, H, lam)


def save_pair(o, a, box, nominal, rho, cols, F8, N8, W8, H, lam, need8):
    """Write the closed pair and its boxes to ``--save`` (for the CI tests)."""
    np.savez(o.save, W=W8, F=F8, N=N8, H=H, moves=o.moves, lam=lam, w_design=a["w_max"],
             lo=box.lo, hi=box.hi, other_half=box.other_half, nominal_lo=nominal.lo,
             nominal_hi=nominal.hi, nominal_other_half=nominal.other_half, k=o.k,
             rho_min=rho, col_scale=cols, bound=need8)  # fmt: skip
    print(f"closed pair written to {o.save}", flush=True)


def resolve(o, a, c, veh, tp, tm, rho, scale, room):
    """--resolve S: the stored pair's box grown for S times its tube, the pair re-solved.

    The vertices are rebuilt over the nominal box of tests/data/closed_tube_h_reset.npz
    grown by 1.01 S times the supports of its product set; the iteration starts from S
    times its W_8, so that a pair S times the stored one is sought rather than scaled.
    """
    st = dict(np.load(ROOT / "tests" / "data" / "closed_tube_h_reset.npz"))
    nominal = an.SchedulingBox(st["nominal_lo"], st["nominal_hi"], st["nominal_other_half"])
    box = es.box_for((st["lo"][0], st["hi"][0]), nominal, st["F"], st["N"], float(st["H"]),
                    o.box_scale or o.resolve)  # fmt: skip
    t0 = time.time()
    nv = an.nominal_vertices(box, veh, tm, dict(PAPER_UNCERTAINTY), rho, c["Ts"],
                             c["plant_substeps"], scale, int(st["k"]), a["w_max"],
                             st["col_scale"], hessians=False)  # fmt: skip
    print(
        f"vertex data over the box for {o.resolve:g} times the stored pair: "
        f"{nv.vertices()[0].shape[0]} vertices ({time.time() - t0:.0f} s)",
        flush=True,
    )
    pair = closure(o, a, tp, nv, nominal, room, o.resolve * st["W"])
    if pair is None:
        return
    F8, N8, W8, H, lam, need8 = pair
    if o.save:
        save_pair(o, a, nv.box, nominal, rho, st["col_scale"], F8, N8, W8, H, lam, need8)
    onset(o, nv, nominal, veh, tm, c, rho, scale, a["w_max"], st["col_scale"], F8, N8, W8, H,
          lam)  # fmt: skip


def onset(o, nv, nominal, veh, tm, c, rho, scale, row_scale, cols, F8, N8, W8, H, lam):
    """The onset of --loss against the closed pair, and the pair scaled by --scales."""
    metric = np.zeros((9, 9))
    metric[0, 0], metric[1:, 1:] = H**2, N8
    op = an.onset_pulse(nominal, veh, tm, dict(PAPER_UNCERTAINTY), 1.0 - o.loss, c["Ts"],
                        c["plant_substeps"], metric, g=1, interior=4096)  # fmt: skip
    J8 = op.jumps[:, 1:]
    jz = float(np.sqrt(np.einsum("si,ij,sj->s", J8, np.linalg.inv(N8), J8).max()))
    slow = np.sqrt(1.0 - lam)
    print(f"onset of a {100 * o.loss:g} % loss: ||J||_Z8 up to {jz:.3f} (h part of the jump "
          f"up to {np.abs(op.jumps[:, 0]).max():.4f} ft); needs s >= "
          f"{1 + jz / (o.gamma - slow):.2f} (gamma {o.gamma:g}), {1 + jz / (1 - slow):.2f} "
          "(one-step estimate)", flush=True)  # fmt: skip
    for sc in o.scales:
        box = es.box_for((nv.box.lo[0], nv.box.hi[0]), nominal, F8, N8, H, sc)
        nv_s = an.nominal_vertices(box, veh, tm, dict(PAPER_UNCERTAINTY), rho, c["Ts"],
                                   c["plant_substeps"], scale, o.k, row_scale, cols,
                                   hessians=False)  # fmt: skip
        A, B = nv_s.vertices()
        ab = es.altitude_bound(nv_s, A, B, F8, sc * sc * N8, o.moves)
        Hs, need8 = ab.H, ab.bound
        level, _ = worst_level(A[:, 1:, 1:], B[:, 1:, :], F8, sc * sc * N8, sc * W8)
        ratio = need8 / (sc * W8)
        print(f"s = {sc:g}: worst level {level:.5f}; H {Hs:.1f} ft; bound / (s W_8) "
              + " ".join(f"{r:.3f}" for r in ratio)
              + ("  closed" if level <= 1 and np.all(ratio <= 1) else "  NOT closed"),
              flush=True)  # fmt: skip


if __name__ == "__main__":
    main()
