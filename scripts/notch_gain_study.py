"""A tube gain designed with the notch in the loop: item 5 and the certified notch together.

`case1_attitude.yaml`'s pair bounds Z_8's attitude supports (item 5), but its gain F_8
does not tolerate the notch's lag: the loop through the notch of eps_p 0.1 has no
invariant ellipsoid (docs/control_design.md, "The attitude-certified pair through the
certified notch"). The certificate the notch law needs
(:func:`fahv.design.certificate.notch_certificate`) asks only that an ellipsoid E(P) of
the loop in xi = [e_8; chi] be RPI for W_8 at every vertex, with its projection inside
Z_8 (s <= 1) and its input support within F_8 Z_8's (the tightening). The gain on
e' = (e_8 with q' for q) is therefore free. It is a static output feedback of the loop,
u - v = F T xi (:func:`fahv.design.certificate.notch_closed_loop`), which is not convex
in (F, P) jointly. The design kernel :func:`fahv.design.certificate.notch_gain` (with
:func:`fahv.synthesis.feedback.output_feedback_step`; ``fahv design`` runs it with
``eight_state.notch_gain: designed``) takes a sequence of convex steps:

- the RPI condition in its dilated form (de Oliveira, Bernussou & Geromel 1999, for
  discrete time), with a slack G in place of P where the loop acts::

      [[lam (G + G' - P), 0, (A_i G + B_i F T G)'], [0, diag(mu_i), E'],
       [A_i G + B_i F T G, E, P]] >= 0,   sum mu_i <= 1 - lam,

  which implies the S-procedure condition of E(P) (G' P^-1 G >= G + G' - P);
- the output structure on the slack (Crusius & Trofino 1999): T G = M T makes
  F T G = Y T with Y = F M, so the block is linear in (P, G, M, Y, mu); F = Y M^-1;
- in coordinates whitened by the last ellipsoid P_0, where G = P = P_0 with M = I,
  F = F_0 is feasible: each step starts from the last certificate and can only improve
  the objective, the factor gamma with the projection inside gamma Z_8 and the input
  supports ([[gamma^2 t_j^2, Y_j T], [T' Y_j', G + G' - P]] >= 0) within gamma times
  the tightening;
- constraint generation over the 4096 vertices (the worst of the exact levels added),
  and every result re-checked exactly (:func:`notch_certificate`: the worst one-step
  level over every vertex and every corner of W_8, s, the supports);
- continuation in the notch's pole damping eps_p: the first start is the pair's F_8 at
  a shallow notch whose loop has an ellipsoid (eps_p 0.05), each certified gain starts
  the next eps_p.

A certified loop keeps e_8 in Z_8 and the applied input within the tightening, but its
input deviation is K xi, not F_8 e_8, so W_8's bound over the product set is recomputed
for the loop's own joint set of (e_8, u - v), [[I, 0], K] P [[I, 0], K]'
(:func:`fahv.design.eight_state.altitude_bound` with ``joint``): the loop is closed on
its own assumptions if that bound lies inside W_8. The attitude requirement then
follows as for the pair (the projection lies in Z_8). Not redone here: the onset bound
(item 3, not certified either way) uses F_8's loop.

This study runs the kernel on a designed pair's artefacts for a list of notches, each
as the last step of the continuation from the gain before it, to find how far the
certified range reaches:

    python scripts/notch_gain_study.py CASE ARTEFACTS [--from EPS_P0] [EPS_P ...]

CASE is an eight-state case, ARTEFACTS the folder of its design (design.npz,
design.json); EPS_P the notch dampings in order (default 0.05 0.07 0.1). Each certified
gain is saved to ARTEFACTS/notch_gain_eps_p_<eps_p>.npz (F, P, the joint shape C);
``--from EPS_P0`` starts from the gain saved for EPS_P0 instead of F_8.
"""

from __future__ import annotations

import json
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from notch_certificate_study import design_nominal_vertices  # noqa: E402

import fahv.design.eight_state as es  # noqa: E402
from fahv.design.case import load_case  # noqa: E402
from fahv.design.certificate import notch_gain  # noqa: E402
from fahv.model.notch import NotchFilter  # noqa: E402

IQ = 3  # q in the eight states
LAM = 0.995  # contraction factor of the S-procedure, as the design's notch certificate


def main(argv: list[str]) -> int:
    """Design and check a notch gain for each eps_p in turn; print the closure."""
    case = load_case(argv[0])
    art = Path(argv[1])
    rest = argv[2:]
    start = None
    if rest[:1] == ["--from"]:  # resume from a gain this study saved
        start = np.load(art / f"notch_gain_eps_p_{float(rest[1])}.npz")["F"]
        rest = rest[2:]
    eps_list = [float(v) for v in rest] or [0.05, 0.07, 0.1]
    arrays = np.load(art / "design.npz")
    cert = json.loads((art / "design.json").read_text())["summary"]["certificate"]
    F8, N8, W8 = arrays["F"][:, 1:], arrays["N"][1:, 1:], np.asarray(cert["W_8"])
    t0 = time.perf_counter()
    nv, _ = design_nominal_vertices(case)
    A, B = nv.vertices()
    A8, B8 = A[:, 1:, 1:], B[:, 1:, :]
    moves = case["mpc"]["M"]
    print(f"{A.shape[0]} vertices of {case['name']} [{time.perf_counter() - t0:.0f} s]")
    own = es.altitude_bound(nv, A, B, F8, N8, moves)
    print(f"the pair's own loop (F_8 on the measured q): H {own.H:.3f} ft, bound / W_8 "
          + " ".join(f"{v:.3f}" for v in own.bound / W8))  # fmt: skip
    n = case["notch"]
    tight = np.sqrt(np.einsum("ij,jk,ik->i", F8, N8, F8))
    F = F8 if start is None else start
    for eps_p in eps_list:
        t0 = time.perf_counter()
        nf = NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], eps_p)
        print(f"eps_p {eps_p}:", flush=True)
        # the pair's tightening, F_8 Z_8's, is kept whatever gain F starts the step
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            got = notch_gain(A8, B8, F, N8, W8, nf, case["Ts"], IQ, LAM, tightening=tight,
                             log=lambda line: print("  " + line, flush=True))  # fmt: skip
        if got is None or not got.loop.certified:
            print(f"eps_p {eps_p}: NOT certified [{time.perf_counter() - t0:.0f} s]")
            return 1
        F, P = got.F, got.P
        C = got.joint(nf, case["Ts"], IQ)
        ab = es.altitude_bound(nv, A, B, F8, N8, moves, joint=C)
        ratio = ab.bound / W8
        att = np.degrees(np.sqrt(np.diag(P)[1:3]))
        print(f"eps_p {eps_p}: [{time.perf_counter() - t0:.0f} s] {got.loop.line()}; "
              f"alpha / theta supports {att[0]:.3f} / {att[1]:.3f} deg (Z_8: "
              f"{np.degrees(np.sqrt(N8[1, 1])):.3f} / {np.degrees(np.sqrt(N8[2, 2])):.3f}); "
              f"W_8 over the loop's own set: H {ab.H:.3f} ft, bound / W_8 "
              + " ".join(f"{v:.3f}" for v in ratio)
              + f": {'closed' if np.all(ratio <= 1.0) else 'NOT closed'}", flush=True)  # fmt: skip
        np.savez(art / f"notch_gain_eps_p_{eps_p}.npz", F=F, P=P, C=C, F8=F8, N8=N8, W8=W8)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
