"""The one-step bounds of W (fahv.bounds.one_step_bound), checked independently.

The integral form on the stored eight-state tube sets (their vertex data rebuilt here,
tests/design/conftest.py), and the Taylor form of the vertex tube around a trim.
"""

from dataclasses import replace

import numpy as np
import pytest

from fahv.bounds.disturbance import STATE_DEVIATIONS
from fahv.bounds.domain import (
    CertificateDomain,
    SchedulingBox,
    box_shortfall,
    joint_shape,
    nominal_half_widths,
    product_supports,
)
from fahv.bounds.one_step_bound import (
    altitude_bound,
    bound_disturbance,
    disturbance_at,
    product_bound,
)
from fahv.bounds.plant_step import jacobians
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import TrimMap
from fahv.model.vehicle import load_vehicle
from fahv.plant.rk4 import params_records, perturbed_records, rk4_cm
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.synthesis.rpi_level import worst_level
from fahv.tube.tube_set import TubeSet

TS, N_SUB = 0.02, 5


def test_stored_tube_set_is_rpi_at_every_vertex(tube_set):
    """Exact worst one-step level of the stored tube over its vertices (64 box corners x
    2^k parameter-direction corners x rho_f at both ends: 4096 for k = 5, 16384 for
    k = 7; the eight states after h) and the corners of W_8: at most 1 (printed with its
    margin)."""
    d, *_, nv = tube_set
    A, B = nv.vertices()
    assert A.shape[0] == 64 * 2 ** int(d["k"]) * 2
    level, _ = worst_level(A[:, 1:, 1:], B[:, 1:, :], d["F"], d["N"], d["W"])
    print(f"worst one-step level {level:.6f} over {A.shape[0]} vertices, margin {1 - level:.2e}")
    assert level <= 1.0


def _interp_weights(box, s):
    """Multilinear weights (L, 64) of points s (L, 6) on the box corners (product order)."""
    t = (s - box.lo) / (box.hi - box.lo)
    w = np.ones((len(s), 1))
    for i in range(6):
        w = (w[:, :, None] * np.stack([1.0 - t[:, i], t[:, i]], axis=1)[:, None, :]).reshape(
            len(s), -1
        )
    return w


def _coordinates(tm, X, U):
    """Scheduling-box coordinates (L, 6) of states X (L, 9) and applied inputs U (L, 2),
    and the deviations (L, 5) of q and the flexible states from the trim."""
    x_r, u_r = tm.at(X[:, 0], X[:, 1])
    x_r, u_r = np.asarray(x_r, float), np.asarray(u_r, float)
    s = np.column_stack([X[:, :2], X[:, 2:4] - x_r[:, 2:4], U - u_r])
    return s, X[:, 4:9] - x_r[:, 4:9]


#: Gauss-Legendre nodes and weights on [0, 1] of the integral form's mean Jacobian.
GAUSS = ((0.5 - 0.5 / np.sqrt(3.0), 0.5), (0.5 + 0.5 / np.sqrt(3.0), 0.5))


def test_the_disturbance_along_the_nominal_lies_inside_W_8(tube_set, request):
    """100 000 true one-step errors along the nominal lie inside W_8: at nominal points in
    the nominal box (its corners first, then inside, with q and the flexible states of the
    nominal within their half-widths), for every corner of the sec. 5.1 box at both rho_f
    ends and then random corners and interior vehicles, e = (e_h, e_8) with |e_h| <= H and
    e_8 on the boundary of Z_8 and inside, w = f_p(z + e, v + P F e) - f_p(z, v) -
    J_theta [e; P F e] with J_theta the mean of its values at the two Gauss nodes of the
    segment (z + s e, v + s P F e), whose points must lie in the scheduling box; at each
    node J_theta is in the vertices' hull: the multilinear weights of the point and the
    carried coefficient of the vehicle's own deviation J_p - J_0 there (which must lie in
    the vertices' range). The earlier record of the same box (k = 5) is sampled 20 000
    times, every vehicle corner at both rho_f ends among them."""
    own = request.node.callspec.params["tube_set"] == "cm_certified"
    _check_true_errors(*tube_set, chunks=10 if own else 2)


def _samples(chunk, rng, n, names, corners, rho_min, nominal, S_corners):
    """Parameter fractions, rho_f and box points of one chunk of the sampling check."""
    if chunk == 0:  # every vehicle corner at both rho_f ends, at box corners (cycled)
        frac = np.vstack([corners, corners, rng.uniform(-1, 1, (n - 2048, len(names)))])
        rho = np.r_[np.full(1024, rho_min), np.ones(1024), rng.choice([rho_min, 1.0], n - 2048)]
        inside = nominal.lo + rng.random((n - 2048, 6)) * (nominal.hi - nominal.lo)
        return frac, rho, np.vstack([S_corners[np.arange(2048) % 64], inside])
    at_corner = rng.random(n) < 0.5
    frac = np.where(at_corner[:, None], rng.choice([-1.0, 1.0], (n, len(names))),
                    rng.uniform(-1, 1, (n, len(names))))  # fmt: skip
    rho = rng.choice([rho_min, 1.0], n)
    s = nominal.lo + rng.random((n, 6)) * (nominal.hi - nominal.lo)
    edge = rng.random(n) < 0.25
    s[edge] = S_corners[rng.integers(0, 64, edge.sum())]
    return frac, rho, s


def _check_true_errors(d, veh, tm, box, scale, nv, chunks: int = 10):
    """The sampling check of :func:`test_the_disturbance_along_the_nominal_lies_inside_W_8`:
    e = (e_h, e_8) with |e_h| <= H and e_8 in Z_8, F blind to e_h; rows 1-8 of w (with
    J_theta's h column times e_h, which W_8 holds) lie inside W_8, and one step's change
    of e_h is at most H / moves. For a tube set of the adjustable law (``tau`` in ``d``)
    the input deviation is tau' P F e, a third of the samples at tau' = tau, a third at 1,
    the rest uniform between."""
    W, N, rho_min = d["W"], d["N"], float(d["rho_min"])
    F = np.hstack([np.zeros((2, 1)), d["F"]])  # the tube on the eight states after h
    tau = float(d.get("tau", 1.0))
    nominal = SchedulingBox(d["nominal_lo"], d["nominal_hi"], d["nominal_other_half"])
    rs, cs = d["w_design"], d["col_scale"]
    unscale = rs[:, None] / cs[None, :]
    G = nv.dirs / unscale[None]  # scaled, orthonormal
    names = list(PAPER_UNCERTAINTY)
    corners = np.array(list(np.ndindex(*(2,) * len(names))), float) * 2 - 1
    L_N = np.linalg.cholesky(N)
    r0 = params_records([veh.params])
    rng = np.random.default_rng(11)
    worst, n_done, tol, h_step = np.zeros(9), 0, 1e-6 * (nv.c_hi - nv.c_lo), 0.0
    excess = np.full(nv.c_lo.size, -np.inf)
    S_corners = nominal.corners()
    for chunk in range(chunks):  # the first: every corner of the box at both rho_f ends
        n = 10_000
        frac, rho, s = _samples(chunk, rng, n, names, corners, rho_min, nominal, S_corners)
        recs = perturbed_records(veh.params, PAPER_UNCERTAINTY, frac)
        X, U = nominal.points(tm, s)
        X[:, 4:9] += rng.uniform(-1, 1, (n, 5)) * nominal.other_half
        m = N.shape[0]
        u = rng.normal(size=(n, m))
        u /= np.linalg.norm(u, axis=1, keepdims=True)
        u[n // 2 :] *= rng.random((n - n // 2, 1)) ** (1 / m)  # inside Z_8
        e_h = float(d["H"]) * np.where(rng.random(n) < 0.5, rng.choice([-1.0, 1.0], n),
                                       rng.uniform(-1.0, 1.0, n))  # fmt: skip
        e = np.column_stack([e_h, u @ L_N.T])
        du = (e @ F.T) * np.stack([np.ones(n), rho], axis=1)  # P F e
        if tau < 1.0:  # the adjustable law's gain tau' F: at both ends and between them
            g = rng.uniform(tau, 1.0, n)
            g[0::3], g[1::3] = tau, 1.0
            du *= g[:, None]
        J_th = np.zeros((n, 9, 11))
        for sigma, weight in GAUSS:  # J_theta at each node of the segment
            Xs, Us = X + sigma * e, U + sigma * du
            ss, other = _coordinates(tm, Xs, Us)
            tol_s = 1e-9 * (box.hi - box.lo)
            assert np.all(ss >= box.lo - tol_s) and np.all(ss <= box.hi + tol_s), (
                "the segment leaves the scheduling box"
            )
            assert np.all(np.abs(other) <= box.other_half * (1 + 1e-9)), (
                "the segment's q or flexible states leave the box's half-widths"
            )
            Jp = jacobians(Xs, Us, recs, TS, N_SUB, scale)
            J0 = jacobians(Xs, Us, np.repeat(r0, n), TS, N_SUB, scale)
            J_int = np.einsum("lc,cij->lij", _interp_weights(box, ss), nv.J0)
            coef = np.einsum("lij,kij->lk", (Jp - J0) / rs[None, :, None] * cs, G)
            excess = np.maximum(excess, np.max(np.maximum(nv.c_lo - coef, coef - nv.c_hi), 0))
            assert np.all(coef >= nv.c_lo - tol) and np.all(coef <= nv.c_hi + tol), (
                "a vehicle's carried coefficient leaves the vertices' range"
            )
            J_th += weight * (J_int + np.einsum("lk,kij->lij", coef, nv.dirs))
        f1 = rk4_cm(np.ascontiguousarray(X + e), np.ascontiguousarray(U + du), recs, TS, N_SUB)
        f0 = rk4_cm(np.ascontiguousarray(X), np.ascontiguousarray(U), recs, TS, N_SUB)
        w = f1 - f0 - np.einsum("lij,lj->li", J_th, np.concatenate([e, du], axis=1))
        w[:, 1:] += J_th[:, 1:, 0] * e[:, :1]  # e_h's effect: W_8 holds it
        h_step = np.maximum(h_step, np.abs(f1[:, 0] - f0[:, 0] - e[:, 0]).max())
        worst = np.maximum(worst, np.abs(w).max(axis=0))
        n_done += n
    print(f"largest one-step change of e_h {h_step:.4f} ft, H / moves "
          f"{float(d['H']) / float(d['moves']):.4f} ft")  # fmt: skip
    assert h_step <= float(d["H"]) / float(d["moves"])
    ratio = worst[1:] / W
    print(f"{n_done} samples: max |w| / W_8 per row:", np.round(ratio, 3))
    print("largest coefficient beyond the vertices' range / its width (< 0: inside):",
          np.round(excess / (nv.c_hi - nv.c_lo), 5))  # fmt: skip
    assert n_done == 10_000 * chunks
    assert np.all(ratio <= 1.0), ratio
    # the samples reach into W_8, so the test is not vacuous: a tenth of W_8 in the largest
    # row and 2 % in every row (the certified design's W_8 keeps 34-71 % of design slack)
    assert ratio.max() >= 0.1 and ratio.min() >= 0.02, ratio


def test_the_adjustable_tube_set_reproduces_its_bound_and_holds_W_8(tube_set_tau):
    """The adjustable law's tube set (tau = 0.8): its vertex data rebuilt here (8192
    vertices, the gains tau' F_8 at 0.8 and 1) reproduce the design's altitude bound H and
    row bound (to 1e-6), inside W_8 with the V row's slack of 3.0 %; and 20 000 true
    one-step errors of the perturbed nonlinear CM, every box corner at both rho_f ends,
    e on the boundary of Z_8 and inside, gains tau' anywhere in [0.8, 1], lie inside W_8
    (the check of test_the_disturbance_along_the_nominal_lies_inside_W_8)."""
    d, *_, nv = tube_set_tau
    A, B = nv.vertices()
    assert A.shape[0] == 8192
    ab = altitude_bound(nv, A, B, d["F"], d["N"], int(d["moves"]))
    print(f"H {ab.H:.4f} ft (stored {float(d['H']):.4f}); bound / W_8 "
          + " ".join(f"{v:.3f}" for v in ab.bound / d["W"]))  # fmt: skip
    assert ab.H == pytest.approx(float(d["H"]), rel=1e-6)
    np.testing.assert_allclose(ab.bound, d["bound"], rtol=1e-6)
    assert 0.025 < (1.0 - ab.bound / d["W"]).min() < 0.035
    _check_true_errors(*tube_set_tau, chunks=2)  # a test record, not a shipped design


def test_the_altitude_bound_reproduces_the_stored_tube_set(tube_set):
    """The altitude bound H of the reset and the eight rows' bound of the stored tube set,
    from its own vertex data, are the ones stored when it closed (to 1e-6), inside W_8
    with the stored slack; the box holds nominal plus the product set, and a box without
    theta's reach is refused naming it."""
    d, *_, nv = tube_set
    A, B = nv.vertices()
    ab = altitude_bound(nv, A, B, d["F"], d["N"], int(d["moves"]))
    ratio = " ".join(f"{v:.3f}" for v in ab.bound / d["W"])
    print(f"H {ab.H:.4f} ft (stored {float(d['H']):.4f}), step {ab.step:.4f} ft, "
          f"w_h {ab.w_h:.4f} ft; bound / W_8 {ratio}")  # fmt: skip
    assert ab.H == pytest.approx(float(d["H"]), rel=1e-6)
    np.testing.assert_allclose(ab.bound, d["bound"], rtol=1e-6)
    assert np.all(ab.bound <= d["W"])
    # the V row's slack: 15 % on the k = 5 tube set, 34 % on the certified design's (k = 7)
    slack = {5: 0.15, 7: 0.339}[int(d["k"])]
    assert (1.0 - ab.bound / d["W"]).min() == pytest.approx(slack, abs=0.01)
    nominal = SchedulingBox(d["nominal_lo"], d["nominal_hi"], d["nominal_other_half"])
    assert box_shortfall(nv.box, nominal, d["F"], d["N"], ab.H) == {}
    s_lo, _ = product_supports(d["F"], d["N"], ab.H)
    hi = nv.box.hi.copy()
    hi[3] = nominal.hi[3] + 0.5 * s_lo[3]
    short = box_shortfall(SchedulingBox(nv.box.lo, hi, nv.box.other_half), nominal,
                          d["F"], d["N"], ab.H)  # fmt: skip
    assert list(short) == ["hi theta"]
    assert short["hi theta"] == pytest.approx(0.5 * s_lo[3], rel=1e-9)
    ts = TubeSet(d["F"], d["N"], d["W"], ab.H, float(d["lam"]), ab.bound, 1.0,
                 int(d["moves"]), ab.step, ab.w_h)  # fmt: skip
    assert ts.F.shape == (2, 9) and np.all(ts.F[:, 0] == 0.0)
    assert ts.N[0, 0] == pytest.approx(ab.H**2) and np.all(ts.N[0, 1:] == 0.0)
    # the elevator tightening: 2.87 deg (k = 5), 3.444 deg (the certified design's, the
    # jumps in Z_8)
    np.testing.assert_allclose(np.degrees(ts.tightening[1]), {5: 2.87, 7: 3.451}[int(d["k"])],
                               atol=0.005)  # fmt: skip


def test_a_loops_joint_shape_replaces_the_tube_sets_in_the_altitude_and_row_bounds(tube_set):
    """The bounds take the joint shape of (e_8, u - v) a loop keeps: given the tube set's
    own (F_8 Z_8, built as a loop with two filter states that do not reach the input)
    they are the tube set's to 1e-9; a shape four times as large doubles the step of (1)
    and every support of the product set; a malformed shape is refused naming it."""
    d, *_, nv = tube_set
    A, B = nv.vertices()
    F_8, N_8, moves = d["F"], d["N"], int(d["moves"])
    ab = altitude_bound(nv, A, B, F_8, N_8, moves)
    # [e_8; chi] with u - v = [F_8, 0] xi over E(blkdiag(N_8, I)): the tube set's set
    J = np.vstack([np.hstack([np.eye(8), np.zeros((8, 2))]), np.hstack([F_8, np.zeros((2, 2))])])
    P = np.block([[N_8, np.zeros((8, 2))], [np.zeros((2, 8)), np.eye(2)]])
    C = J @ P @ J.T
    np.testing.assert_allclose(C, joint_shape(F_8, N_8), rtol=1e-12, atol=0.0)
    same = altitude_bound(nv, A, B, F_8, N_8, moves, joint=C)
    assert same.H == pytest.approx(ab.H, rel=1e-9)
    np.testing.assert_allclose(same.bound, ab.bound, rtol=1e-9)
    big = altitude_bound(nv, A, B, F_8, N_8, moves, joint=4.0 * C)
    assert big.step == pytest.approx(2.0 * ab.step, rel=1e-12)
    s_lo, s_oth = product_supports(F_8, N_8, ab.H)
    b_lo, b_oth = product_supports(F_8, N_8, ab.H, 4.0 * C)
    np.testing.assert_allclose(b_lo[1:], 2.0 * s_lo[1:], rtol=1e-12)
    np.testing.assert_allclose(b_oth, 2.0 * s_oth, rtol=1e-12)
    assert np.all(big.bound > ab.bound)
    with pytest.raises(ValueError, match="joint shape"):
        product_supports(F_8, N_8, ab.H, C[:9, :9])


def test_the_adjustable_gain_is_covered_at_both_ends_of_its_segment(tube_set):
    """Eq. (48) in the eight-state bounds: with nv.tau = 0.8 the vertices are [A_i, B_i]
    and [A_i, 0.8 B_i]; the parameter part of the row bound is the larger of its values
    for the gains F_8 and 0.8 F_8, and no gain tau' F_8 on a grid of [0.8, 1] exceeds it
    (each support is convex in tau'), while the interpolation part keeps F_8 Z_8's
    supports; the altitude step over the doubled vertices covers every tau' too."""
    d, *_, nv = tube_set
    F_8, N_8, H, tau = d["F"], d["N"], float(d["H"]), 0.8
    nv_t = replace(nv, tau=tau)
    A, B = nv.vertices()
    At, Bt = nv_t.vertices()
    R = A.shape[0]
    assert At.shape[0] == 2 * R == nv_t.n_vertices and R == nv.n_vertices
    np.testing.assert_array_equal(At[R:], A)
    np.testing.assert_allclose(Bt[R:], tau * B, rtol=0.0, atol=0.0)
    par_t, interp_t = product_bound(nv_t, F_8, N_8, H)
    par_1, interp_1 = product_bound(nv, F_8, N_8, H)
    par_tau, _ = product_bound(nv, tau * F_8, N_8, H)
    np.testing.assert_allclose(par_t, np.maximum(par_1, par_tau), rtol=1e-12)
    np.testing.assert_allclose(interp_t, interp_1, rtol=1e-12)
    grid = [product_bound(nv, g * F_8, N_8, H)[0] for g in np.linspace(tau, 1.0, 9)]
    assert np.all(np.max(grid, axis=0) <= par_t * (1.0 + 1e-12))
    # on this tube set the whole gain binds in every row; a residual whose input part
    # cancels the gain's part of e (R_u F_8 = -R_e Pi, Pi = N_8 F_8' (F_8 N_8 F_8')^-1 F_8,
    # the projection orthogonal in Z_8's metric: the support falls with tau') makes the
    # smaller gain bind, and the bound follows it
    assert np.all(par_tau <= par_1)
    Rs = nv.residual.copy()
    Rs[..., 9:] = -Rs[..., 1:9] @ (N_8 @ F_8.T @ np.linalg.inv(F_8 @ N_8 @ F_8.T))
    nv_c, nv_ct = replace(nv, residual=Rs), replace(nv_t, residual=Rs)
    par_c1 = product_bound(nv_c, F_8, N_8, H)[0]
    par_ct = product_bound(nv_c, tau * F_8, N_8, H)[0]
    assert np.all(par_ct > par_c1)
    np.testing.assert_allclose(product_bound(nv_ct, F_8, N_8, H)[0], par_ct, rtol=1e-12)
    with pytest.raises(ValueError, match="joint shape covers its own gain"):
        product_bound(nv_t, F_8, N_8, H, joint_shape(F_8, N_8))
    c = np.concatenate([At[:, 0, 1:], Bt[:, 0]], axis=1)
    C = joint_shape(F_8, N_8)
    step_t = np.sqrt(np.einsum("ri,ij,rj->r", c, C, c)).max()
    cg = np.concatenate([A[:, 0, 1:], B[:, 0]], axis=1)
    for g in np.linspace(tau, 1.0, 9):
        Cg = joint_shape(g * F_8, N_8)
        assert np.sqrt(np.einsum("ri,ij,rj->r", cg, Cg, cg)).max() <= step_t * (1.0 + 1e-12)


# -- the Taylor form of the vertex tube, around the scheduling trim ------------------------
@pytest.fixture(scope="module")
def model(design):
    a = design.arrays
    veh = load_vehicle()
    tp = build_tp_model(veh, "cm", 4, 5, 21, 21)
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    return veh, tp, tm


def _domain_samples(dom, n, seed):
    """n points of the domain: the first 2 x 1024 at every parameter corner (rho_f at
    both ends, box corners of x and u cycled), the rest uniform in the boxes with the
    parameters at random corners or inside."""
    rng = np.random.default_rng(seed)
    corners = dom.corners()
    P = len(dom.uncertainty)
    a = np.concatenate([dom.x_half, 0.5 * (dom.u_hi - dom.u_lo)])
    signs = np.empty((n, P))
    signs[: len(corners)] = corners
    signs[len(corners) : 2 * len(corners)] = corners
    k = 2 * len(corners)
    signs[k:] = np.where(rng.random((n - k, P)) < 0.5, rng.choice([-1.0, 1.0], (n - k, P)),
                         rng.uniform(-1, 1, (n - k, P)))  # fmt: skip
    unit = rng.uniform(-1, 1, (n, a.size))
    unit[:k] = np.sign(unit[:k])  # box corners for the parameter corners
    return unit, a, signs


def test_disturbance_bound_holds_on_100000_independent_samples(model):
    """The deterministic bound of W over a domain contains the true one-step disturbance
    of the perturbed nonlinear CM at 100 000 points of that domain, every corner of the
    sec. 5.1 box and rho_f at both ends included (a quarter of the nominal MPC's ranges
    and inputs +/-(0.05, 2 deg) around the trim at the envelope's centre, rho_f 0.7, 1)."""
    veh, tp, tm = model
    h, V = 85500.0, 7900.0
    x_r, u_r = tm(h, V)
    nominal, notes = nominal_half_widths(
        {"reschedule": [100.0, 50.0], "dtheta_max": [300.0, 150.0], "att_max": 0.35},
        STATE_DEVIATIONS,
    )
    dom = CertificateDomain(
        np.array([[h, V]]), 0.25 * nominal, 0.25 * nominal, u_r - [0.05, np.radians(2.0)],
        u_r + [0.05, np.radians(2.0)], dict(PAPER_UNCERTAINTY), (0.7, 1.0), 0.02, 5, notes,
    )  # fmt: skip
    bnd = bound_disturbance(dom, veh, tp, tm)
    assert np.all(bnd.corner_max <= bnd.w_bound)
    n = 100_000
    unit, a, signs = _domain_samples(dom, n, seed=12)
    center = np.concatenate([np.zeros(9), 0.5 * (dom.u_lo + dom.u_hi) - u_r])
    worst = np.zeros(9)
    for rho, sl in ((0.7, slice(0, n, 2)), (1.0, slice(1, n, 2))):
        D = disturbance_at(dom, veh, tp, tm, (h, V), center + unit[sl] * a, signs[sl], rho)
        worst = np.maximum(worst, np.max(np.abs(D), axis=0))
    ratio = worst / bnd.w_bound
    print("sampled max / bound per row:", np.round(ratio, 3))
    assert np.all(ratio <= 1.0), ratio
    # and the bound is not vacuous: the samples reach a good part of it
    assert np.all(ratio >= 0.3), ratio


@pytest.mark.xfail(
    strict=True,
    reason="the vertex tube's W does not bound the disturbance over the design's own domain "
    "(12-176x per row, docs/theory/alternatives.md); strict: passes once it does",
)
def test_the_vertex_tube_W_bounds_the_disturbance_over_its_own_domain(design, model):
    """The true one-step disturbance sampled over the vertex design's own domain lies
    inside its sampled W."""
    veh, tp, tm = model
    a = design.arrays
    h, V = 85500.0, 7900.0
    x_r, u_r = tm(h, V)
    nominal, notes = nominal_half_widths(design.case["mpc"], STATE_DEVIATIONS)
    t = veh.limits.u_max - a["u_hi"]
    dom = CertificateDomain(
        np.array([[h, V]]), nominal + np.sqrt(np.diag(a["N"])), nominal, a["u_lo"] - t,
        a["u_hi"] + t, dict(PAPER_UNCERTAINTY), (0.7, 1.0), 0.02, 5, notes,
    )  # fmt: skip
    unit, half, signs = _domain_samples(dom, 20_000, seed=5)
    center = np.concatenate([np.zeros(9), 0.5 * (dom.u_lo + dom.u_hi) - u_r])
    D = disturbance_at(dom, veh, tp, tm, (h, V), center + unit * half, signs, 0.7)
    assert np.all(np.max(np.abs(D), axis=0) <= a["w_max"])
