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
in (F, P) jointly. This study designs it by a sequence of convex steps:

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

import cvxpy as cp
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from notch_certificate_study import design_nominal_vertices  # noqa: E402

import fahv.design.eight_state as es  # noqa: E402
from fahv.design.case import load_case  # noqa: E402
from fahv.design.certificate import (  # noqa: E402
    notch_certificate,
    notch_closed_loop,
    notch_loop_scale,
    vertex_levels,
)
from fahv.model.notch import NotchFilter  # noqa: E402
from fahv.synthesis.feedback import BUDGET_MARGIN, SDP_SOLVER, invariant_ellipsoid  # noqa: E402

IQ = 3  # q in the eight states
LAM = 0.995  # contraction factor of the S-procedure, as the design's notch certificate


def joint_step(A0, B0, T, P0, W8, N8, tight, chosen):
    """One convex step around the ellipsoid P0 (module docstring): (F, P, gamma) or None.

    A0 (R, 10, 10) and B0 (R, 10, 2) are the loop's vertices without feedback, T (8, 10)
    its output map; P0 (10, 10) the last ellipsoid; only the ``chosen`` vertices held.
    """
    n, nx = T.shape
    m = B0.shape[2]
    L = np.linalg.cholesky(0.5 * (P0 + P0.T))
    Li = np.linalg.inv(L)
    Aw, Bw, Tw = Li[None] @ A0 @ L[None], Li[None] @ B0, T @ L
    E = Li @ np.vstack([np.diag(W8), np.zeros((nx - n, n))])
    Ni = np.linalg.inv(np.linalg.cholesky(N8))
    P = cp.Variable((nx, nx), symmetric=True)
    G = cp.Variable((nx, nx))
    M = cp.Variable((n, n))
    Y = cp.Variable((m, n))
    g2 = cp.Variable()
    mu = cp.Variable((len(chosen), n), nonneg=True)
    GG = G + G.T - P
    proj = Ni @ L[:n] @ P @ L[:n].T @ Ni.T
    cons = [P >> 1e-9 * np.eye(nx), Tw @ G == M @ Tw, 0.5 * (proj + proj.T) << g2 * np.eye(n),
            cp.sum(mu, axis=1) <= (1.0 - LAM) * (1.0 - BUDGET_MARGIN)]  # fmt: skip
    for j in range(m):
        row = cp.reshape(Y[j] @ Tw, (1, nx), order="C")
        blk = cp.bmat([[cp.reshape(g2 * tight[j] ** 2, (1, 1), order="C"), row], [row.T, GG]])
        cons.append(0.5 * (blk + blk.T) >> 0)
    for r, i in enumerate(chosen):
        AG = Aw[i] @ G + Bw[i] @ Y @ Tw
        blk = cp.bmat([[LAM * GG, np.zeros((nx, n)), AG.T],
                       [np.zeros((n, nx)), cp.diag(mu[r]), E.T],
                       [AG, E, P]])  # fmt: skip
        cons.append(0.5 * (blk + blk.T) >> 0)
    prob = cp.Problem(cp.Minimize(g2), cons)
    try:
        prob.solve(solver=SDP_SOLVER)
    except cp.error.SolverError:
        return None
    if prob.status not in ("optimal", "optimal_inaccurate"):
        return None
    F = Y.value @ np.linalg.inv(M.value)
    return F, L @ (0.5 * (P.value + P.value.T)) @ L.T, float(np.sqrt(g2.value))


def certified(chk, tight) -> bool:
    """The design's own conditions: level <= 1, s <= 1, supports within F_8 Z_8's."""
    return chk.level <= 1.0 and chk.s <= 1.0 and bool(np.all(np.asarray(chk.supports) <= tight))


def describe(chk, tight) -> str:
    """s, level and supports against F_8 Z_8's tightening (not the new gain's own)."""
    return (f"s {chk.s:.4f}, level {chk.level:.6f}, input supports {chk.supports[0]:.4f} / "
            f"{np.degrees(chk.supports[1]):.3f} deg (tightening {tight[0]:.4f} / "
            f"{np.degrees(tight[1]):.3f} deg), spectral radius {chk.rho:.6f}: "
            + ("certified" if certified(chk, tight) else "NOT certified"))  # fmt: skip


def design_gain(A, B, F, N8, W8, tight, nf, Ts, rounds=8):
    """Start from F's ellipsoid at this notch, then joint steps; (F, P, check) or None."""
    D = notch_loop_scale(N8, nf, Ts, IQ)  # as notch_tube scales the loop's states
    w_xi = np.r_[W8, 0.0, 0.0]
    Acl, K = notch_closed_loop(A, B, F, nf, Ts, IQ)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        ell = invariant_ellipsoid(Acl, W8, D, N8, K, 100.0 * tight,
                                  lambda P: vertex_levels(Acl, P, w_xi), LAM)  # fmt: skip
    if ell is None:
        print(f"  eps_p {nf.eps_p}: no ellipsoid for the start gain", flush=True)
        return None
    P = ell.P
    chk = notch_certificate(A, B, F, N8, W8, nf, Ts, IQ, P, "study")
    print(f"  start (the previous gain): {describe(chk, tight)}", flush=True)
    A0, _ = notch_closed_loop(A, B, np.zeros_like(F), nf, Ts, IQ)
    B0 = np.concatenate([B, np.zeros((B.shape[0], 2, B.shape[2]))], axis=1)
    _, T = notch_closed_loop(A[:1], np.zeros((1,) + A.shape[1:]), np.eye(A.shape[1]), nf, Ts, IQ)
    best = np.inf
    for k in range(rounds):
        if certified(chk, tight):
            return F, P, chk
        t0 = time.perf_counter()
        Acl, _ = notch_closed_loop(A, B, F, nf, Ts, IQ)
        rho = np.abs(np.linalg.eigvals(Acl)).max(axis=1)
        lev = vertex_levels(Acl, P, w_xi)
        chosen = np.union1d(np.argsort(-rho)[:20], np.argsort(-lev)[:20])
        while True:  # constraint generation: the exact level, not the LMI, decides
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                got = joint_step(A0, B0, T, P, W8, N8, tight, chosen)
            if got is None:
                print(f"  round {k}: the step's LMI failed on {len(chosen)} vertices", flush=True)
                return None
            Fn, Pn, g = got
            levn = vertex_levels(notch_closed_loop(A, B, Fn, nf, Ts, IQ)[0], Pn, w_xi)
            bad = np.setdiff1d(np.flatnonzero(levn > 1.0), chosen)
            if bad.size == 0:
                break
            chosen = np.union1d(chosen, bad[np.argsort(-levn[bad])[:40]])
        F, P = Fn, Pn
        chk = notch_certificate(A, B, F, N8, W8, nf, Ts, IQ, P, "study")
        print(f"  round {k} ({len(chosen)} vertices held, gamma {g:.4f}, "
              f"{time.perf_counter() - t0:.0f} s): {describe(chk, tight)}", flush=True)  # fmt: skip
        if g > best - 1e-3:
            break  # stalled
        best = g
    return (F, P, chk) if certified(chk, tight) else None


def joint_shape(F, P, nf, Ts, n=8) -> np.ndarray:
    """The loop's joint shape of (e_8, u - v) over E(P): [[I, 0], K] P [[I, 0], K]'."""
    _, K = notch_closed_loop(np.zeros((1, n, n)), np.zeros((1, n, 2)), F, nf, Ts, IQ)
    J = np.vstack([np.hstack([np.eye(n), np.zeros((n, 2))]), K])
    return J @ P @ J.T


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
    tight = np.sqrt(np.einsum("ij,jk,ik->i", F8, N8, F8))
    own = es.altitude_bound(nv, A, B, F8, N8, moves)
    print(f"the pair's own loop (F_8 on the measured q): H {own.H:.3f} ft, bound / W_8 "
          + " ".join(f"{v:.3f}" for v in own.bound / W8))  # fmt: skip
    n = case["notch"]
    F = F8 if start is None else start
    for eps_p in eps_list:
        t0 = time.perf_counter()
        nf = NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], eps_p)
        print(f"eps_p {eps_p}:", flush=True)
        got = design_gain(A8, B8, F, N8, W8, tight, nf, case["Ts"])
        if got is None:
            print(f"eps_p {eps_p}: NOT certified [{time.perf_counter() - t0:.0f} s]")
            return 1
        F, P, chk = got
        C = joint_shape(F, P, nf, case["Ts"])
        ab = es.altitude_bound(nv, A, B, F8, N8, moves, joint=C)
        ratio = ab.bound / W8
        att = np.degrees(np.sqrt(np.diag(P)[1:3]))
        print(f"eps_p {eps_p}: [{time.perf_counter() - t0:.0f} s] {describe(chk, tight)}; "
              f"alpha / theta supports {att[0]:.3f} / {att[1]:.3f} deg (Z_8: "
              f"{np.degrees(np.sqrt(N8[1, 1])):.3f} / {np.degrees(np.sqrt(N8[2, 2])):.3f}); "
              f"W_8 over the loop's own set: H {ab.H:.3f} ft, bound / W_8 "
              + " ".join(f"{v:.3f}" for v in ratio)
              + f": {'closed' if np.all(ratio <= 1.0) else 'NOT closed'}", flush=True)  # fmt: skip
        np.savez(art / f"notch_gain_eps_p_{eps_p}.npz", F=F, P=P, C=C, F8=F8, N8=N8, W8=W8)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
