"""Which QP solver for the nominal MPC: the QPs of a Case 1 run, solved by each candidate.

Run: .venv/bin/python benchmarks/bench_qp_solvers.py [--steps 15000] [--repeat 3]
         [--scenario FILE] [--smoke]

Records every QP the nominal MPC of `tube_mpc` hands to its solver during a run (in
process; by default Case 1 on the paper's design, offline_design/scenarios/case1_paper.yaml;
`--scenario` another, e.g. case1_implementable.yaml, whose QPs have the certificate's
state-range rows),
then solves the same sequence with each installed candidate, in order, the way the MPC
would use it: a solver keeps its factorisation/workspace while H and the constraint
matrix are unchanged (they change only when the MPC is rescheduled) and gets the vectors
updated and the previous solution as warm start where its API allows.
Prints per solver: median, p99 and max time per QP (best of `--repeat` passes), QPs
it did not solve, the worst constraint violation and the worst objective gap to DAQP.

Candidates: DAQP (dual active set) on every row (the project's), DAQP on a working set
of rows grown from the violated ones (constraint generation: class DAQPWorkingRows), OSQP
(ADMM), Clarabel (interior point, no warm start), PIQP (proximal interior point),
ProxSuite ProxQP (augmented Lagrangian).
PIQP and ProxSuite are not project dependencies; the table says so when missing
(`pip install piqp proxsuite` to compare them).

`--smoke` records 100 steps (4 QPs) and makes one pass, in seconds: CI's check that the
benchmark still runs (its figures mean nothing).
"""

import argparse
import io
import time

import numpy as np
import scipy.sparse as sp

from fahv.certificate.verified import load_or_design
from fahv.control.mpc import tracking
from fahv.loop.simulate import simulate

BIG = 1e29  # |bound| >= BIG: no bound (DAQP's convention in the MPC)
#: --smoke: the steps recorded (the nominal MPC solves a QP every 25 steps).
SMOKE_STEPS = 100


def record(steps: int, scenario: str) -> list[tuple]:
    """QPs (H, f, A_c, bu, bl) of a `tube_mpc` run of `scenario`, in the order solved.

    Every QP the nominal MPC hands to its solver (`TrackingMPC.solve_qp`, whole: every
    row of the constraint matrix).
    """
    qps = []
    solve_qp = tracking.TrackingMPC.solve_qp

    def recording(mpc, f, bl, bu):
        qps.append((mpc.H, f.copy(), mpc.A_c, bu.copy(), bl.copy()))
        return solve_qp(mpc, f, bl, bu)

    tracking.TrackingMPC.solve_qp = recording
    try:
        _, design, _ = load_or_design(scenario, log=io.StringIO().write,
                                      variants=["tube_mpc"], allow_uncertified=True)  # fmt: skip
        simulate(design, "tube_mpc", duration=steps * design.case["Ts"])
    finally:
        tracking.TrackingMPC.solve_qp = solve_qp
    return qps


def _split(H, A, bu, bl):
    """General form: G = [I; A] (nc, ny), lower/upper with +/-inf for absent bounds."""
    ny = H.shape[0]
    G = np.vstack([np.eye(ny), A])
    lo = np.where(bl <= -BIG, -np.inf, bl)
    hi = np.where(bu >= BIG, np.inf, bu)
    return G, lo, hi


class DAQP:
    """DAQP (dual active set) on every row: its workspace kept while H and A are the same."""

    name = "DAQP on every row (workspace kept)"

    def __init__(self):
        import daqp

        self.daqp, self.model, self.y = daqp, None, None

    def solve(self, H, f, A, bu, bl, same):
        if not same or self.model is None:
            self.model = self.daqp.Model()
            self.model.settings = {"iter_limit": 2000}
            if self.model.setup(H, f, A, bu, bl, primal_start=self.y)[0] < 0:
                self.model = None
                return None
        else:
            self.model.update(f=f, bupper=bu, blower=bl)
        y, _, flag, _ = self.model.solve()
        if flag not in (1, 2):
            self.model = None
            return None
        self.y = np.asarray(y)
        return self.y


class DAQPWorkingRows:
    """DAQP on a working set of rows grown from the violated ones (constraint generation).

    The first QP on every row, its active rows the set; each later QP solved on the set,
    every row evaluated at the solution, the (at most ADD_AT_ONCE) most violated rows or
    rows within 1e-7 of a bound added, solved again (new set-up), until no row outside
    is violated: then it is the full QP's optimum. The set is carried across schedulings.
    """

    name = "DAQP on working rows (grown)"
    ADD_AT_ONCE = 5

    def __init__(self):
        self.daqp = DAQP()
        self.rows, self.model_rows = None, None  # the set; the rows DAQP's workspace has

    def solve(self, H, f, A, bu, bl, same):
        ny = H.shape[0]
        if self.rows is None:
            y = self.daqp.solve(H, f, A, bu, bl, False)
            if y is not None:
                self.rows = np.flatnonzero(_near(A @ y, bl[ny:], bu[ny:]))
            return y
        while True:
            sel = np.concatenate([np.arange(ny), ny + self.rows])
            kept = same and self.model_rows is self.rows
            y = self.daqp.solve(H, f, A[self.rows], bu[sel], bl[sel], kept)
            self.model_rows = self.rows
            if y is None:
                return None
            r = A @ y
            near = _near(r, bl[ny:], bu[ny:])
            near[self.rows] = False
            new = np.flatnonzero(near)
            if new.size == 0:
                return y
            excess = np.maximum(r[new] - bu[ny + new], bl[ny + new] - r[new])
            new = new[np.argsort(-excess, kind="stable")[: self.ADD_AT_ONCE]]
            self.rows = np.union1d(self.rows, new)


def _near(r, lo, hi, margin=1e-7):
    """Rows whose value r is beyond or within `margin` (relative) of a bound."""
    with np.errstate(invalid="ignore"):
        return ((hi < BIG) & (r > hi - margin * (1 + np.abs(hi)))) | (
            (lo > -BIG) & (r < lo + margin * (1 + np.abs(lo))))


class OSQP:
    """OSQP (ADMM): set up per scheduling, vectors updated and warm-started after."""

    name = "OSQP (ADMM, warm)"

    def __init__(self):
        import osqp

        self.osqp, self.m = osqp, None

    def solve(self, H, f, A, bu, bl, same):
        G, lo, hi = _split(H, A, bu, bl)
        if not same or self.m is None:
            self.m = self.osqp.OSQP()
            self.m.setup(sp.triu(sp.csc_matrix(H), format="csc"), f, sp.csc_matrix(G), lo, hi,
                         verbose=False, eps_abs=1e-7, eps_rel=1e-7, polishing=False,
                         max_iter=20000)  # fmt: skip
        else:
            self.m.update(q=f, l=lo, u=hi)
        r = self.m.solve()
        return r.x if r.info.status_val in (1, 2) else None


class Clarabel:
    """Clarabel (interior point): the bounds as a nonnegative cone, no warm start."""

    name = "Clarabel (interior point)"

    def __init__(self):
        import clarabel

        self.c = clarabel

    def solve(self, H, f, A, bu, bl, same):
        G, lo, hi = _split(H, A, bu, bl)
        up, dn = np.isfinite(hi), np.isfinite(lo)
        Gc = sp.csc_matrix(np.vstack([G[up], -G[dn]]))
        b = np.concatenate([hi[up], -lo[dn]])
        st = self.c.DefaultSettings()
        st.verbose = False
        s = self.c.DefaultSolver(
            sp.triu(sp.csc_matrix(H), format="csc"), f, Gc, b, [self.c.NonnegativeConeT(b.size)], st
        )
        r = s.solve()
        return np.asarray(r.x) if str(r.status) in ("Solved", "AlmostSolved") else None


class PIQP:
    """PIQP (proximal interior point, dense): set up per scheduling, vectors updated."""

    name = "PIQP (proximal interior point)"

    def __init__(self):
        import piqp

        self.piqp, self.s = piqp, None

    def solve(self, H, f, A, bu, bl, same):
        ny = H.shape[0]
        lo_y, hi_y = _split(H, A, bu, bl)[1:]
        if not same or self.s is None:
            self.s = self.piqp.DenseSolver()
            self.s.settings.verbose = False
            self.s.setup(np.asfortranarray(H), f, None, None, np.asfortranarray(A),
                         lo_y[ny:], hi_y[ny:], lo_y[:ny], hi_y[:ny])  # fmt: skip
        else:
            self.s.update(c=f, h_l=lo_y[ny:], h_u=hi_y[ny:], x_l=lo_y[:ny], x_u=hi_y[:ny])
        st = self.s.solve()
        return np.asarray(self.s.result.x) if st == self.piqp.PIQP_SOLVED else None


class ProxQP:
    """ProxSuite ProxQP (dense, box constraints): warm start from the previous result."""

    name = "ProxSuite ProxQP (dense, warm)"

    def __init__(self):
        from proxsuite import proxqp

        self.px, self.qp = proxqp, None

    def solve(self, H, f, A, bu, bl, same):
        ny, nc = H.shape[0], A.shape[0]
        lo = np.maximum(bl, -1e20)
        hi = np.minimum(bu, 1e20)
        if not same or self.qp is None:
            self.qp = self.px.dense.QP(ny, 0, nc, True)
            self.qp.settings.eps_abs = 1e-7
            self.qp.settings.verbose = False
            self.qp.init(H, f, None, None, A, lo[ny:], hi[ny:], lo[:ny], hi[:ny])
        else:
            self.qp.settings.initial_guess = self.px.InitialGuess.WARM_START_WITH_PREVIOUS_RESULT
            self.qp.update(g=f, l=lo[ny:], u=hi[ny:], l_box=lo[:ny], u_box=hi[:ny])
        self.qp.solve()
        ok = self.qp.results.info.status == self.px.QPSolverOutput.PROXQP_SOLVED
        return np.asarray(self.qp.results.x) if ok else None


def run(cls, qps):
    """Times [s], solutions (None: not solved) of one pass over the sequence.

    Every candidate class has `solve(H (ny, ny), f (ny,), A (nc, ny), bu, bl (ny + nc,),
    same)` -> y (ny,) or None, with DAQP's conventions (the first ny bounds are simple
    bounds on y, |bound| >= 1e29 none); `same`: H and A are those of the previous QP.
    """
    solver = cls()
    times, ys, prev = [], [], None
    for H, f, A, bu, bl in qps:
        same = prev is not None and prev[0] is H and prev[1] is A
        t0 = time.perf_counter()
        y = solver.solve(H, f, A, bu, bl, same)
        times.append(time.perf_counter() - t0)
        ys.append(y)
        prev = (H, A)
    return np.array(times), ys


def quality(qp, y, y_ref):
    """Worst bound violation and objective gap (relative) of y against DAQP's y_ref."""
    H, f, A, bu, bl = qp
    Ay = np.concatenate([y, A @ y])
    viol = np.max(np.maximum(np.where(bl > -BIG, bl - Ay, 0), np.where(bu < BIG, Ay - bu, 0)))

    def obj(v):
        return 0.5 * v @ H @ v + f @ v

    gap = (obj(y) - obj(y_ref)) / (1.0 + abs(obj(y_ref)))
    return max(viol, 0.0), gap


def main() -> None:
    """Record the QPs, run every candidate, print the table."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=15000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--scenario", default="offline_design/scenarios/case1_paper.yaml",
                    help="the run whose QPs are recorded (its tube_mpc variant)")
    ap.add_argument("--smoke", action="store_true",
                    help=f"{SMOKE_STEPS} steps, one pass (CI: it still runs)")  # fmt: skip
    args = ap.parse_args()
    if args.smoke:
        args.steps, args.repeat = SMOKE_STEPS, 1
        print(f"smoke: {SMOKE_STEPS} steps, one pass (the figures mean nothing)")
    qps = record(args.steps, args.scenario)
    n_sched = len({id(q[0]) for q in qps})
    ny, nc = qps[0][0].shape[0], qps[0][2].shape[0]
    print(f"{len(qps)} QPs recorded over {args.steps} steps ({n_sched} distinct H), "
          f"{ny} variables, {nc} constraint rows + bounds")  # fmt: skip
    _, ref = run(DAQP, qps)
    print(f"{'solver':38s} {'median':>9s} {'p99':>9s} {'max':>9s} {'unsolved':>9s} "
          f"{'max viol':>9s} {'obj gap':>9s}")  # fmt: skip
    for cls in (DAQP, DAQPWorkingRows, OSQP, Clarabel, PIQP, ProxQP):
        try:
            best = None
            for _ in range(args.repeat):
                t, ys = run(cls, qps)
                best = t if best is None else np.minimum(best, t)
        except ImportError as exc:
            print(f"{cls.name:38s} not installed ({exc.name})")
            continue
        ms = best * 1e3
        bad = sum(y is None for y in ys)
        q = [quality(qp, y, r) for qp, y, r in zip(qps, ys, ref, strict=True)
             if y is not None and r is not None]  # fmt: skip
        viol = max((v for v, _ in q), default=np.nan)
        gap = max((abs(g) for _, g in q), default=np.nan)
        print(f"{cls.name:38s} {np.median(ms):7.3f}ms {np.percentile(ms, 99):7.3f}ms "
              f"{ms.max():7.3f}ms {bad:9d} {viol:9.1e} {gap:9.1e}")  # fmt: skip


if __name__ == "__main__":
    main()
