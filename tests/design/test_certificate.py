"""The tube certificate against its own assumptions (fahv.design.certificate)."""

import dataclasses
import itertools
from pathlib import Path

import numpy as np
import pytest

from fahv.design.certificate import (
    CertificateDomain,
    bound_disturbance,
    disturbance_at,
    nominal_half_widths,
    onset_levels,
    parameter_directions,
    worst_level,
)
from fahv.design.disturbance import DEFAULT_DEV_BOX
from fahv.design.feasibility import fault_vertices
from fahv.errors import DesignError
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import TrimMap
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY

DATA = Path(__file__).resolve().parents[1] / "data"


def test_worst_level_is_exact_on_a_small_system():
    """The trust-region maximum equals a dense brute force (from below, to 1e-3)."""
    rng = np.random.default_rng(3)
    n, m, R = 3, 1, 2
    A = rng.normal(0, 0.4, (R, n, n))
    B = rng.normal(0, 1, (R, n, m))
    F = rng.normal(0, 0.2, (m, n))
    G = rng.normal(0, 1, (n, n))
    N = G @ G.T + np.eye(n)
    w = np.array([0.1, 0.3, 0.2])
    level, _ = worst_level(A, B, F, N, w)
    L = np.linalg.cholesky(N)
    u = rng.normal(size=(200_000, n))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    E = u @ L.T  # boundary of Z
    brute = 0.0
    Ninv = np.linalg.inv(N)
    for i, s in itertools.product(range(R), itertools.product((-1, 1), repeat=n)):
        Y = E @ (A[i] + B[i] @ F).T + np.array(s) * w
        brute = max(brute, np.max(np.einsum("ki,ij,kj->k", Y, Ninv, Y)))
    assert brute <= level * (1 + 1e-12)
    assert level <= brute * (1 + 1e-3)


def test_onset_levels_follow_the_certificate_recursion():
    """Without a pulse and with the budget sum mu w^2 = 1 - lam the level stays at 1; a
    pulse raises it by exactly the recursion's terms."""
    lam, mu, w = 0.99, np.array([2.0, 3.0]), np.array([0.04, 0.03])
    budget = float(mu @ w**2)
    w_full = w * np.sqrt((1 - lam) / budget)
    L = onset_levels(lam, mu, w_full, np.zeros(2), 0.04, 500)
    assert np.allclose(L, 1.0, atol=1e-12)
    L = onset_levels(lam, mu, w, np.array([0.1, 0.0]), 0.5, 3, level0=0.0)
    assert L[1] == pytest.approx(mu @ (w + [0.1, 0]) ** 2, rel=1e-14)
    assert L[2] == pytest.approx(lam * L[1] + mu @ (w + [0.05, 0]) ** 2, rel=1e-14)


@pytest.fixture(scope="module")
def model(design):
    a = design.arrays
    veh = load_vehicle()
    tp = build_tp_model(veh, "cm", 4, 5, 21, 21)
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    return veh, tp, tm


def _samples(dom, n, seed):
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


def _trim_domain(h, V, u_r):
    """A quarter of the nominal MPC's ranges and inputs +/-(0.05, 2 deg) around the trim at
    (h, V), the whole sec. 5.1 box, rho_f 0.7 and 1 (the domain of the bound's tests)."""
    nominal, notes = nominal_half_widths(
        {"reschedule": [100.0, 50.0], "dtheta_max": [300.0, 150.0], "att_max": 0.35},
        DEFAULT_DEV_BOX,
    )
    return CertificateDomain(
        np.array([[h, V]]), 0.25 * nominal, 0.25 * nominal, u_r - [0.05, np.radians(2.0)],
        u_r + [0.05, np.radians(2.0)], dict(PAPER_UNCERTAINTY), (0.7, 1.0), 0.02, 5, notes,
    )  # fmt: skip


def test_disturbance_bound_holds_on_100000_independent_samples(model):
    """The deterministic bound of W over a domain contains the true one-step disturbance
    of the perturbed nonlinear CM at 100 000 points of that domain, every corner of the
    sec. 5.1 box and rho_f at both ends included (issue: an independent test)."""
    veh, tp, tm = model
    h, V = 85500.0, 7900.0
    x_r, u_r = tm(h, V)
    dom = _trim_domain(h, V, u_r)
    bnd = bound_disturbance(dom, veh, tp, tm)
    assert np.all(bnd.corner_max <= bnd.w_bound)
    n = 100_000
    unit, a, signs = _samples(dom, n, seed=12)
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


def test_parameter_directions_carry_the_box_and_the_bound_stays_sound(model):
    """The parameter box's Jacobian deviation is dominated by one direction (I_yy, which
    scales the pitch row); with it in the tube's vertices the bound of the rest drops in
    the rigid-body rows and still contains the true disturbance at every parameter
    corner (both rho_f ends, box corners and interior points of the state/input box)."""
    veh, tp, tm = model
    h, V = 85500.0, 7900.0
    x_r, u_r = tm(h, V)
    dirs = parameter_directions(veh, tm, [[h, V]], dict(PAPER_UNCERTAINTY), 0.02, 5,
                                tp.state_scale, tp.input_scale, 1)  # fmt: skip
    sv = dirs.singular_values
    print("RMS singular values of the corners' deviations:", np.round(sv[:4], 5))
    assert sv[0] > 5 * sv[1]
    # the first direction separates the corners by I_yy (the 2nd parameter of the box)
    corners = np.array(list(itertools.product((-1.0, 1.0), repeat=len(PAPER_UNCERTAINTY))))
    coef = np.einsum("cij,ij->c", dirs.corner_linear[0][:, :, :9], dirs.dA[0])
    assert abs(np.corrcoef(coef, corners[:, 1])[0, 1]) > 0.95
    A, B = tp.discretize(0.02).A, tp.discretize(0.02).B
    Av, Bv = dirs.vertices(A, B)
    assert Av.shape == (2 * A.shape[0], 9, 9) and Bv.shape == (2 * B.shape[0], 9, 2)
    dom = _trim_domain(h, V, u_r)
    plain = bound_disturbance(dom, veh, tp, tm)
    bnd = bound_disturbance(dom, veh, tp, tm, directions=dirs)
    print("bound with / without the direction per row:", np.round(bnd.w_bound / plain.w_bound, 3))
    assert np.all(bnd.w_bound[2:5] < 0.7 * plain.w_bound[2:5])  # alpha, theta, q
    n = 2 * 2048
    unit, a, _ = _samples(dom, n, seed=7)
    signs = np.concatenate([corners] * 4)
    center = np.concatenate([np.zeros(9), 0.5 * (dom.u_lo + dom.u_hi) - u_r])
    worst = np.zeros(9)
    for rho, sl in ((0.7, slice(0, n, 2)), (1.0, slice(1, n, 2))):
        D = disturbance_at(dom, veh, tp, tm, (h, V), center + unit[sl] * a, signs[sl], rho,
                           directions=dirs)  # fmt: skip
        worst = np.maximum(worst, np.max(np.abs(D), axis=0))
    ratio = worst / bnd.w_bound
    print("sampled max / bound per row (with the direction):", np.round(ratio, 3))
    assert np.all(ratio <= 1.0), ratio
    with pytest.raises(DesignError, match="do not cover"):  # a vehicle beyond the box
        disturbance_at(dom, veh, tp, tm, (h, V), center[None], 0.0 * corners[:1], 1.0,
                       directions=dataclasses.replace(dirs, c_lo=dirs.c_hi - 1e-12))  # fmt: skip


def test_closed_tube_holding_the_trim_is_true(model):
    """The first closed pair (W, Z) (scripts/closure_study.py, holding the trim at the
    envelope centre and two opposite corners, the parameter box along 3 directions in the
    320 vertices, rho_f in [0.76, 1]): the exact worst one-step level over its vertices
    and the corners of its W is at most 1, and the true one-step disturbance of the
    perturbed nonlinear CM at 102 000 points of its domain (Z's box, the inputs of F Z
    around each trim; at each schedule every parameter corner at both rho_f ends, at box
    corners of state and input, the rest inside with the parameters at corners or inside
    the box) lies inside W, the carried part of each vehicle inside the vertices' range."""
    veh, tp, tm = model
    d = np.load(DATA / "closed_tube_hold_trim.npz")
    W, F, N = d["W"], d["F"], d["N"]
    sched = d["schedules"]
    assert sched.shape == (3, 2)
    dirs = parameter_directions(veh, tm, sched, dict(PAPER_UNCERTAINTY), 0.02, 5,
                                tp.state_scale, tp.input_scale, int(d["k"]),
                                row_scale=d["w_design"])  # fmt: skip
    disc = tp.discretize(0.02)
    Af, Bf = fault_vertices(*dirs.vertices(disc.A, disc.B), float(d["rho_min"]))
    level, _ = worst_level(Af, Bf, F, N, W)
    print(f"worst one-step level {level:.6f} over {Af.shape[0]} vertices, margin {1 - level:.2e}")
    assert Af.shape[0] == 320
    assert level <= 1.0
    t = np.sqrt(np.einsum("ij,jk,ik->i", F, N, F))
    du = np.array([float(d["dphi"]), np.radians(float(d["ddelta_e_deg"]))]) + t
    z = np.sqrt(np.diag(N))
    worst = np.zeros(9)
    n = 34_000  # per schedule: 102 000 in all
    for si, (h, V) in enumerate(sched):
        u_r = tm(h, V)[1]
        dom = CertificateDomain(np.array([[h, V]]), d["nominal"] + z, d["nominal"], u_r - du,
                                u_r + du, dict(PAPER_UNCERTAINTY), (float(d["rho_min"]), 1.0),
                                0.02, 5)  # fmt: skip
        unit, a, signs = _samples(dom, n, seed=21 + si)
        for rho, sl in ((float(d["rho_min"]), slice(0, n, 2)), (1.0, slice(1, n, 2))):
            D = disturbance_at(dom, veh, tp, tm, (h, V), unit[sl] * a, signs[sl], rho,
                               directions=dirs)  # fmt: skip
            worst = np.maximum(worst, np.max(np.abs(D), axis=0))
    ratio = worst / W
    print("sampled max / W per row:", np.round(ratio, 3))
    assert np.all(ratio <= 1.0), ratio
    assert np.all(ratio >= 0.2), ratio  # the samples reach W: it is not vacuous


@pytest.mark.xfail(
    strict=True,
    reason="certificate not closed (measured: the disturbance over the design's own domain "
    "exceeds W by 12-176x per row, docs/control_design.md); strict: passes once it is",
)
def test_design_W_bounds_the_disturbance_over_its_own_domain(design, model):
    """The true one-step disturbance sampled over the design's own domain lies inside W."""
    veh, tp, tm = model
    a = design.arrays
    h, V = 85500.0, 7900.0
    x_r, u_r = tm(h, V)
    nominal, notes = nominal_half_widths(design.case["mpc"], DEFAULT_DEV_BOX)
    t = veh.limits.u_max - a["u_hi"]
    dom = CertificateDomain(
        np.array([[h, V]]), nominal + np.sqrt(np.diag(a["N"])), nominal, a["u_lo"] - t,
        a["u_hi"] + t, dict(PAPER_UNCERTAINTY), (0.7, 1.0), 0.02, 5, notes,
    )  # fmt: skip
    unit, half, signs = _samples(dom, 20_000, seed=5)
    center = np.concatenate([np.zeros(9), 0.5 * (dom.u_lo + dom.u_hi) - u_r])
    D = disturbance_at(dom, veh, tp, tm, (h, V), center + unit * half, signs, 0.7)
    assert np.all(np.max(np.abs(D), axis=0) <= a["w_max"])


def test_design_tube_is_rpi_for_its_W_exactly(design):
    """The exact worst one-step level of the design's tube over its 40 vertices, the
    corners of W and all of Z is at most 1 (printed with its margin)."""
    a = design.arrays
    Af, Bf = fault_vertices(a["A"], a["B"], design.case["tube"]["rho_min"])
    level, _ = worst_level(Af, Bf, a["F"], a["N"], a["w_max"])
    print(f"worst one-step level {level:.6f}, margin {1 - level:.2e}")
    assert level <= 1.0


def test_worst_level_bounds_the_nearly_hard_case_tightly():
    """The trust-region maximum when M'c is almost orthogonal to the top eigenvector
    (the case that a primal fill along that eigenvector once overstated by 4e-3): an
    upper bound of the brute-force maximum over 2 000 001 points of the circle, within
    1e-9 of it."""
    from fahv.design.certificate import _max_on_ball

    M = np.diag([0.9974, 0.9961])
    c = np.array([[2.5e-11, 0.0139], [0.0, 0.0139], [0.3, 0.2]])
    t = np.linspace(0.0, 2.0 * np.pi, 2_000_001)
    U = np.stack([np.cos(t), np.sin(t)], axis=1)
    brute = np.array([np.max(np.sum((U @ M.T + cl) ** 2, axis=1)) for cl in c])
    got = _max_on_ball(M, c)
    assert np.all(got >= brute - 1e-12), (got, brute)
    np.testing.assert_allclose(got, brute, rtol=0, atol=1e-9)


@pytest.mark.parametrize(
    "a, w, factor",
    [(0.5, 0.25, 2.0), (0.9, 1.0, 0.1), (0.999, 1.0, 0.001), (1.2, 0.1, 0.0)],
)
def test_rpi_margin_is_the_exact_factor_below_half_too(a, w, factor):
    """e+ = a e + g w on Z = [-1, 1]: RPI iff |a| + g w <= 1, so g = (1 - a) / w; a loop
    that expands Z without a disturbance gives 0. (The bisection once started at 0.5 and
    reported 0.5 for any smaller factor.)"""
    from fahv.design.certificate import rpi_margin

    A, B, F, N = np.array([[[a]]]), np.zeros((1, 1, 1)), np.zeros((1, 1)), np.eye(1)
    g = rpi_margin(A, B, F, N, np.array([w]))
    assert g == pytest.approx(factor, abs=4.0 * 2.0**-30 + 1e-9)


def test_gain_vertices_certify_every_adjustable_gain_and_the_incomplete_set():
    """Eq. (47)-(48) on e+ = a e + b tau' F e + w, Z = [-z, z]: the tube LMI over
    ``gain_vertices`` (tau = 0.5) makes Z RPI for W under every gain tau' F, tau' in
    [0.5, 1] (checked by brute force on a grid of tau', with the exact scalar condition
    |a + b tau' F| z + w <= z), and tau Z RPI for g W with g >= tau, where the exact factor
    is g = tau z (1 - |a + b tau F|) / w."""
    from fahv.design.certificate import rpi_margin, worst_level
    from fahv.design.feasibility import gain_vertices
    from fahv.synthesis.feedback import design_tube, verify_tube

    a, b, w, tau = 1.05, 1.0, 0.01, 0.5
    A, B = np.array([[[a]]]), np.array([[[b]]])
    At, Bt = gain_vertices(A, B, tau)
    assert At.shape == (2, 1, 1) and Bt[1, 0, 0] == tau * b
    one = np.ones(1)
    tube = design_tube(At, Bt, np.array([w]), one, one, np.array([1.0]))
    verify_tube(At, Bt, tube, one, one)
    F, z = tube.F[0, 0], float(np.sqrt(tube.N[0, 0]))
    for t in np.linspace(tau, 1.0, 51):
        assert abs(a + b * t * F) * z + w <= z * (1 + 1e-9), t
    level = worst_level(At, Bt, tube.F, tube.N, np.array([w]))[0]
    assert level <= 1.0
    g = rpi_margin(A, B, tube.F, tube.N, np.array([w]), tau)
    g_exact = tau * z * (1.0 - abs(a + b * tau * F)) / w
    assert g == pytest.approx(g_exact, abs=4.0 * 2.0**-30 + 1e-9)
    assert g >= tau * (1 - 1e-9)
    assert gain_vertices(A, B, 1.0)[0] is A
    with pytest.raises(ValueError, match="tube.tau = 0"):
        gain_vertices(A, B, 0.0)
