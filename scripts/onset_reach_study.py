"""Three sharper analyses of a loss onset on the eight-state pair (item 3): none certifies it.

Usage: python scripts/onset_reach_study.py [PAIR.npz] [LOSS]

The design's onset bound (`fahv.design.eight_state.onset_bound`) is a norm recursion in
Z_8's own norm: e = e_w + e_p, e_w in c Z_8 (the steady level), ||e_p||_Z_8 bounded by the
pulse peak of the jump J and the estimate's remaining error. On the stored pair
(default: tests/data/closed_tube_h_reset.npz, whose box case1.yaml's design reproduces)
this script measures what three sharper tools give for the same argument:

1. **A contractive ellipsoid shaped for the jump, inside kappa Z_8.** Any E(Q) with
   A_i Q A_i' <= a^2 Q at every closed-loop vertex and every jump inside it holds e_p at
   the pulse peak in its own norm; e stays in Z_8 if c + peak kappa <= 1, kappa the
   smallest factor with Q <= kappa^2 N_8. The LMI (minimise kappa^2) is solved with
   constraint generation over the 4096 vertices and the jumps, and re-checked exactly.
   Since J must lie inside E(Q) within kappa Z_8, kappa >= ||J||_Z_8: whatever the shape,
   c + ||J||_Z_8 <= 1 is the ceiling of any analysis that keeps e in Z_8 from the
   steady level (the design prints it: the one-step loss).
2. **A contractive ellipsoid that lets e leave Z_8**, shaped to use least of the
   scheduling box's room beyond the nominal box and c Z_8 (and of the input room): the
   onset's reachable set peak x E(Q) against that room, and the elevator tightening it
   would need.
3. **A zonotope reach** of e_p along arbitrary switching among the vertices (interval
   bound of the vertices' spread around their centre, generator reduction), in scaled
   and in modal coordinates, with rho_f fixed at either end: does it stay bounded?

docs/control_design.md, "Sharper onset analyses (measured 2026-11-25, stop 45)".
"""

import sys
import time
from pathlib import Path

import cvxpy as cp
import numpy as np

from fahv.control.nominal_mpc import elevator_share
from fahv.design.along_nominal import SchedulingBox, nominal_vertices, onset_jumps
from fahv.design.eight_state import product_bound, pulse_peak
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import trim_map
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.synthesis.lmi import SDP_SOLVER

TS, N_SUB, GAMMA = 0.02, 4, 0.2  # the case's period, RK4 sub-steps, estimate gain
NAMES = ("V", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")


def contraction(Acl, Q):
    """||L^-1 A_i L||_2 per vertex, Q = L L'."""
    L = np.linalg.cholesky(Q)
    return np.linalg.norm(np.linalg.solve(L, Acl @ L), 2, axis=(1, 2))


def norms(Q, V):
    """||v||_Q of the rows of V."""
    L = np.linalg.cholesky(Q)
    return np.sqrt((np.linalg.solve(L, V.T) ** 2).sum(axis=0))


def ellipsoid(Acl, J, a, D, rows=None, room=None, within=None, active=64, rounds=40):
    """The ellipsoid of least tau; None if infeasible.

    min tau s.t. A_i Q A_i' <= a^2 Q, J_s in E(Q), and g' Q g <= tau room^2 (rows) or
    Q <= tau within; vertex and jump blocks generated; solved on e / D.
    """
    n = Acl.shape[1]
    As = Acl * D[None, None, :] / D[None, :, None]
    Js = J / D
    v_held = list(np.argsort(-np.linalg.norm(As, 2, axis=(1, 2)))[:active])
    j_held = list(np.argsort(-np.linalg.norm(Js, axis=1))[:active])
    for _ in range(rounds):
        Q, tau = cp.Variable((n, n), symmetric=True), cp.Variable()
        if within is not None:
            cons = [tau * (within / np.outer(D, D)) - Q >> 0]
        else:
            cons = [(g * D) @ Q @ (g * D) <= tau * r**2 for g, r in zip(rows, room, strict=True)]
        for i in v_held:
            AQ = As[i] @ Q
            cons.append(cp.bmat([[a**2 * Q, AQ], [AQ.T, Q]]) >> 1e-7 * np.eye(2 * n))
        for s in j_held:
            js = Js[s][:, None]
            cons.append(cp.bmat([[np.ones((1, 1)), js.T], [js, Q]]) >> 0)
        prob = cp.Problem(cp.Minimize(tau), cons)
        prob.solve(solver=SDP_SOLVER)
        if prob.status not in ("optimal", "optimal_inaccurate") or Q.value is None:
            return None
        Qs = 0.5 * (Q.value + Q.value.T)
        ca, jn = contraction(As, Qs), norms(Qs, Js)
        bad_v = [i for i in np.argsort(-ca)[:active] if ca[i] > a * (1 + 1e-6) and i not in v_held]
        bad_j = [s for s in np.argsort(-jn)[:active] if jn[s] > 1 + 1e-6 and s not in j_held]
        if not bad_v and not bad_j:
            return Qs * np.outer(D, D)
        v_held += bad_v
        j_held += bad_j
    return None


def measured(Acl, Q, J, rest):
    """Exact contraction, largest jump and rest norms in E(Q), and the pulse peak."""
    aq, jq, jr = (float(v.max()) for v in (contraction(Acl, Q), norms(Q, J), norms(Q, rest)))
    return aq, jq, jr, pulse_peak(aq, jq, [(0.0, 1.0), (jr, GAMMA)])


def oriented_box(S, D):
    """Generators (n, n) of a symmetric zonotope holding the rows of S.

    Principal axes of S / D, half-widths the largest |coordinate| along each.
    """
    Ss = S / D
    V = np.linalg.svd(Ss, full_matrices=False)[2].T
    return (V * np.abs(Ss @ V).max(axis=0)) * D[:, None]


def zonotope_growth(Acl, T, Gj, Gr, D, steps=(1, 10, 25, 50), m_max=80):
    """Largest support / D of the zonotope reach of e_p at the given steps.

    In coordinates e = T x: e_p+ in A_c e_p + box(max_i |(A_i - A_c) g| per generator)
    + (1 - gamma)^k R. Returns the vertices' spread relative to A_c and {step: support}.
    """
    Ti = np.linalg.inv(T)
    At = Ti @ Acl @ T
    Ac = 0.5 * (At.max(axis=0) + At.min(axis=0))
    dA = At - Ac
    G, GR, out = Ti @ Gj, Ti @ Gr, {}
    for k in range(max(steps) + 1):
        if k in steps:
            out[k] = float((np.abs(T @ G).sum(axis=1) / D).max())
        spread = np.abs(np.einsum("vij,jm->vim", dA, G)).max(axis=0).sum(axis=1)
        G = np.hstack([Ac @ G, np.diag(spread), (1 - GAMMA) ** (k + 1) * GR])
        if G.shape[1] > m_max:  # the smallest generators into their interval hull
            o = np.argsort(np.linalg.norm(T @ G / D[:, None], axis=0))
            cut = G.shape[1] - m_max + G.shape[0]
            G = np.hstack([G[:, o[cut:]], np.diag(np.abs(G[:, o[:cut]]).sum(axis=1))])
    spread_rel = float(np.abs(dA).max(axis=0).sum() / np.abs(Ac).sum())
    return spread_rel, out


def modal(A):
    """A real modal basis of A (columns)."""
    w, V = np.linalg.eig(A)
    cols, used = [], set()
    for i in range(len(w)):
        if i in used:
            continue
        used.add(i)
        if abs(w[i].imag) > 1e-12:
            free = [j for j in range(len(w)) if j not in used]
            j = min(free, key=lambda j: abs(w[j] - w[i].conj()))
            used.add(j)
            cols += [V[:, i].real, V[:, i].imag]
        else:
            cols.append(V[:, i].real)
    return np.array(cols).T


def main(path: Path, loss: float) -> None:
    """Print the three analyses (module docstring)."""
    t0 = time.perf_counter()
    d = dict(np.load(path))
    veh, unc = load_vehicle(), dict(PAPER_UNCERTAINTY)
    tm = trim_map(veh)
    box = SchedulingBox(d["lo"], d["hi"], d["other_half"])
    nominal = SchedulingBox(d["nominal_lo"], d["nominal_hi"], d["nominal_other_half"])
    tp = build_tp_model(veh, "cm", 4, 5, 21, 21)
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    nv = nominal_vertices(box, veh, tm, unc, float(d["rho_min"]), TS, N_SUB, scale, int(d["k"]),
                          d["w_design"], d["col_scale"], hessians=False)  # fmt: skip
    A, B = nv.vertices()
    F8, N8, W8, H = d["F"], d["N"], d["W"], float(d["H"])
    Acl = A[:, 1:, 1:] + B[:, 1:, :] @ F8
    J, _ = onset_jumps(box, veh, tm, unc, 1.0 - loss, TS, N_SUB, 1024)
    J = J / (1.0 - loss)
    J8 = J[:, 1:]
    Bd = tp.discretize(TS).B[:, :, 1]  # the estimate's possible elevator columns
    rest = np.concatenate([(J - elevator_share(J, b, tp.state_scale)[:, None] * b)[:, 1:]
                           for b in Bd])  # fmt: skip
    par, interp = product_bound(nv, F8, N8, H)
    c = float(((par[1:] + interp[1:] + np.abs(A[:, 1:, 0]).max(axis=0) * H) / W8).max())
    sZ = np.sqrt(np.diag(N8))
    tF = np.sqrt(np.diag(F8 @ N8 @ F8.T))
    a8, j8 = float(contraction(Acl, N8).max()), float(norms(N8, J8).max())
    print(f"pair {path.name}, {100 * loss:.1f} % loss: {len(J8)} jumps, {len(Acl)} vertices; "
          f"steady level c {c:.3f}; Z_8 norm: contraction {a8:.5f}, worst jump {j8:.3f}, "
          f"ceiling c + ||J|| = {c + j8:.3f} (certified loss at most "
          f"{100 * loss * (1 - c) / j8:.2f} % for any analysis that keeps e in Z_8)")  # fmt: skip
    print("1. contractive ellipsoid for the jump, inside kappa Z_8:")
    for a in (0.995, 0.998):
        Q = ellipsoid(Acl, J8, a, sZ, within=N8)
        if Q is None:
            print(f"   a {a}: infeasible")
            continue
        aq, jq, jr, peak = measured(Acl, Q, J8, rest)
        L8 = np.linalg.cholesky(N8)
        kappa = np.linalg.eigvalsh(np.linalg.solve(L8, np.linalg.solve(L8, Q).T)).max()
        kappa = float(np.sqrt(kappa))
        print(f"   a {a}: contraction {aq:.5f}, jump {jq:.4f}, estimate's rest {jr:.3f}, peak "
              f"{peak:.3f}, kappa {kappa:.3f}: level bound {c + peak * kappa:.3f}, certified loss "
              f"{100 * loss * (1 - c) / (peak * kappa):.2f} % (first order)")  # fmt: skip
    print("2. contractive ellipsoid letting e leave Z_8, against the scheduling box's room:")
    lo, hi, oth = box.margin_to(nominal)
    m6 = np.minimum(lo, hi)
    room = np.r_[m6[1:4], oth, m6[4:6]] - c * np.r_[sZ, tF]
    rows = np.vstack([np.eye(8), F8])
    for a in (0.995, 0.998):
        Q = ellipsoid(Acl, J8, a, sZ, rows=rows, room=room)
        if Q is None:
            print(f"   a {a}: infeasible")
            continue
        aq, jq, jr, peak = measured(Acl, Q, J8, rest)
        sup = peak * np.sqrt(np.einsum("ij,jk,ik->i", rows, Q, rows))
        print(
            f"   a {a}: peak {peak:.3f}; reach / room per coordinate ("
            + ", ".join(NAMES)
            + ", Phi, delta_e): "
            + np.array2string(sup / room, precision=2)
        )
        print(f"     supports / Z_8's: {np.array2string(sup[:8] / sZ, precision=2)}; elevator "
              f"tightening needed {np.degrees(c * tF[1] + sup[9]):.2f} deg (F_8 Z_8's "
              f"{np.degrees(tF[1]):.2f} deg)")  # fmt: skip
    print("3. zonotope reach of e_p (largest support / Z_8's at steps 1, 10, 25, 50):")
    Gj, Gr = oriented_box(J8, sZ), oriented_box(rest, sZ)
    half = len(Acl) // 2
    for label, Av in (("rho_f = rho_min", Acl[:half]), ("rho_f = 1", Acl[half:]), ("both", Acl)):
        for coords, T in (("scaled", np.diag(sZ)), ("modal", modal(Av.mean(axis=0)))):
            spread, g = zonotope_growth(Av, T, Gj, Gr, sZ)
            print(
                f"   {label}, {coords} coordinates: vertex spread {spread:.3f} of the centre; "
                + ", ".join(f"{v:.3g}" for v in g.values())
            )
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    here = Path(__file__).resolve().parents[1]
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else here / "tests/data/closed_tube_h_reset.npz",
         float(sys.argv[2]) if len(sys.argv) > 2 else 0.24)  # fmt: skip
