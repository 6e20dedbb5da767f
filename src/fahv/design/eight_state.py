"""The tube on the eight states after h, with the altitude error bounded by a reset.

Along the nominal (:mod:`fahv.design.along_nominal`, integral form (2)), the W-Z
iteration at the size the onset of a loss needs diverges in the h row: the kinematic
integrator h_dot = V sin(theta - alpha) is held by the tube only through theta and q,
and its disturbance grows with the box. This module takes h out of the tube's RPI
condition. The tube (F_8, Z_8 = {e_8' N_8^-1 e_8 <= 1}) is designed on the other eight
states e_8 = (V, alpha, theta, q, eta_1, eta_1_dot, eta_2, eta_2_dot) with the
ancillary gain blind to e_h, and the altitude error is bounded by the nominal MPC's
reset of its h to the measured altitude at every re-plan (``mpc.h_reset``, M fast steps
apart), which makes e_h = 0 there:

    |e_h| <= H = M (step + w_h),                                                (1)
    step = max over the vertices of max over Z_8 of |a_h,8 e_8 + b_h F_8 e_8|,

with w_h the h row's own disturbance over the product set {|e_h| <= H} x Z_8 (solved
to its fixed point: w_h grows with H, weakly). The altitude error then enters the
other rows as a disturbance, max over the vertices of |A_8h| H, added to their bound.
Each support is exact for the product set (:func:`product_bound`): the parameter
residual of every vehicle at every box corner for rho_f at both ends, and the
interpolation remainder (elementwise bounds times the product set's supports).

:func:`close_pair` iterates W_8 <- max(W_8, grow x bound) with the tube LMI (24) re-solved
over the vertices until the bound lies inside W_8, checks that the scheduling box holds
the nominal's box grown by the product set's supports (the integral form's segment
condition), and re-checks the exact worst one-step level over the vertices and the
corners of W_8 (:func:`fahv.design.certificate.worst_level`).

What the pair assumes besides the vertices' own assumptions (stated by
:data:`ASSUMPTIONS`): the nominal resets its altitude every ``moves`` fast steps; the
nominal stays inside the certified range (the scheduling box less the tube,
:func:`certified_range`); the disturbance estimate has converged (the
onset of a loss is not in W_8).
"""

from __future__ import annotations

import itertools
from collections.abc import Callable
from dataclasses import dataclass, field, replace

import numpy as np

from fahv.control.base import ATTITUDE_BOUND_DEG
from fahv.control.nominal_mpc import elevator_share
from fahv.design.along_nominal import (
    BOX_COORDINATES,
    NominalVertices,
    SchedulingBox,
    nominal_vertices,
    onset_jumps,
)
from fahv.design.certificate import (
    NotchLoop,
    notch_gain,
    notch_loop,
    notch_tube,
    vertex_levels,
    worst_level,
)
from fahv.errors import DesignError
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.synthesis.feedback import design_tube, invariant_ellipsoid

#: The states of the tube, after h (the design's state order without its first entry).
EIGHT_STATES = ("V", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")

#: Contraction factors tried for the onset bound's steady set (:func:`steady_set`): the
#: smallest ellipsoid RPI for the bound at one factor may not exist at another (on
#: case1.yaml's pair of 16384 vertices: none at 0.995, 0.419 Z_8 at one of the others; docs).
STEADY_LAMS = (0.995, 0.993, 0.998)

#: What a pair of :func:`close_pair` assumes beyond the vertices' own assumptions.
ASSUMPTIONS = (
    "the nominal resets its altitude to the measured one every `moves` fast steps "
    "(mpc.h_reset, M = moves), so |e_h| <= H between resets",
    "the ancillary gain is blind to e_h: u = v + F_8 e_8",
    "the nominal stays inside the certified range (the scheduling box less the tube: "
    "certified_range); the QP's rows keep its h, V, attitude (from the set point's trim) and "
    "inputs in the nominal box, and its alpha, theta, q and flexible states in the certified "
    "range from the trim at its own (h, V) (mpc.x_box; the trim's slope linearised at the "
    "scheduling point, the remainder measured per run: metrics nominal_*, the campaign "
    "report's range line)",
    "the disturbance estimate has converged: the onset of a loss and the estimate's lag "
    "are not in W_8 (bounded separately as a transient of the pair: the onset lines)",
)


@dataclass(frozen=True)
class EightStatePair:
    """A closed eight-state pair and its altitude bound.

    Attributes
    ----------
    F8 : (2, 8) ndarray
        Ancillary gain on e_8 [(-, rad) per state unit].
    N8 : (8, 8) ndarray
        Shape of Z_8 = {e_8' N8^-1 e_8 <= 1} (state units squared).
    W8 : (8,) ndarray
        Half-widths of W_8 (state units per period Ts).
    H : float
        Altitude error bound (1) [ft].
    lam : float
        Contraction factor of the tube LMI (24).
    bound : (8,) ndarray
        The disturbance bound over the product set, per row (<= W8 when closed).
    level : float
        Exact worst one-step level over the vertices and the corners of W_8 (<= 1).
    moves : int
        Fast steps between the nominal's altitude resets (M).
    step : float
        Largest one-step change of e_h by the tube's own dynamics [ft].
    w_h : float
        The h row's disturbance over the product set [ft].
    onset : OnsetBound, optional
        The onset of a loss as a transient of the pair (:func:`onset_bound`).
    notch_loops : tuple of NotchLoop
        The tube variants that feed q through a notch, their loops certified in their
        own states at the pair's vertices (:func:`fahv.design.certificate.notch_tube`).
    notch_gains : dict
        ``{variant: (2, 8) ndarray}``: the gains designed for those loops and certified
        (``eight_state.notch_gain: designed``, :func:`fahv.design.certificate.notch_gain`);
        such a variant runs its own gain in place of F_8.
    """

    F8: np.ndarray
    N8: np.ndarray
    W8: np.ndarray
    H: float
    lam: float
    bound: np.ndarray
    level: float
    moves: int
    step: float
    w_h: float
    onset: OnsetBound | None = None
    notch_loops: tuple[NotchLoop, ...] = ()
    notch_gains: dict = field(default_factory=dict)

    @property
    def F(self) -> np.ndarray:
        """(2, 9) ancillary gain on the nine states, zero on e_h."""
        return np.hstack([np.zeros((2, 1)), self.F8])

    @property
    def N(self) -> np.ndarray:
        """(9, 9) diag(H^2, N_8), the tube shape the nodes take.

        Its ellipsoid holds the product set's e_8 part and its h support is H; the
        node's tube level with it is a bound, not the product set's level.
        """
        N = np.zeros((9, 9))
        N[0, 0], N[1:, 1:] = self.H**2, self.N8
        return N

    @property
    def tightening(self) -> np.ndarray:
        """(2,) support of F_8 Z_8 per input [-, rad]: the tightening of eq. (30)."""
        return np.sqrt(np.einsum("ij,jk,ik->i", self.F8, self.N8, self.F8))

    @property
    def slack(self) -> np.ndarray:
        """(8,) 1 - bound / W_8 per row (>= 0 when closed)."""
        return 1.0 - self.bound / self.W8

    def summary(self, nominal: SchedulingBox, box: SchedulingBox) -> dict:
        """JSON-ready record of the pair for the design summary (``certificate``).

        Units as the attributes; the boxes in their coordinates (:data:`BOX_COORDINATES`);
        ``certified_range`` is :func:`certified_range` of the scheduling box.
        """
        cert = certified_range(box, self.F8, self.N8, self.H)
        return {
            "form": "eight_state",
            "states": list(EIGHT_STATES),
            "W_8": self.W8.tolist(),
            "bound": self.bound.tolist(),
            "slack": self.slack.tolist(),
            "level": self.level,
            "level_margin": 1.0 - self.level,
            "lam": self.lam,
            "H_ft": self.H,
            "moves": self.moves,
            "h_step_ft": self.step,
            "w_h_ft": self.w_h,
            "tightening": self.tightening.tolist(),
            "nominal_box": {
                "lo": nominal.lo.tolist(),
                "hi": nominal.hi.tolist(),
                "other_half": nominal.other_half.tolist(),
            },  # fmt: skip
            "scheduling_box": {
                "lo": box.lo.tolist(),
                "hi": box.hi.tolist(),
                "other_half": box.other_half.tolist(),
            },  # fmt: skip
            "certified_range": {
                "lo": cert.lo.tolist(),
                "hi": cert.hi.tolist(),
                "other_half": cert.other_half.tolist(),
            },  # fmt: skip
            "assumptions": list(ASSUMPTIONS),
            "onset": None if self.onset is None else self.onset.summary(),
            "notch_in_loop": [loop.summary() for loop in self.notch_loops],
        }


def pair_shape(F8, N8) -> np.ndarray:
    """Joint shape (10, 10) of (e_8, u - v) over Z_8 under u - v = F_8 e_8: [I; F_8] N_8 [I; F_8]'.

    The set {(e_8, F_8 e_8) : e_8 in Z_8} is the degenerate ellipsoid of this shape: the
    support of r'(e_8, u - v) over it is sqrt(r' C r). A loop whose input deviation is
    not F_8 e_8 (the tube loop through the notch filter, u - v = K xi over an ellipsoid
    E(P) of xi = [e_8; chi]) has its own joint shape, [[I, 0], K] P [[I, 0], K]' (the
    ``joint`` argument of :func:`product_supports`, :func:`product_bound`,
    :func:`altitude_bound`).

    Parameters
    ----------
    F8 : (2, 8) array_like
    N8 : (8, 8) array_like

    Returns
    -------
    (10, 10) ndarray
        Rows and columns V ... eta_2_dot, then Phi [-] and delta_e [rad].

    Raises
    ------
    ValueError
        If the shapes are not (2, 8) and (8, 8).
    """
    F8, N8 = np.asarray(F8, float), np.asarray(N8, float)
    if F8.shape != (2, 8) or N8.shape != (8, 8):
        raise ValueError(f"pair_shape: F8 {F8.shape}, N8 {N8.shape}; expected (2, 8), (8, 8)")
    J = np.vstack([np.eye(8), F8])
    return J @ N8 @ J.T


def _joint(F8, N8, joint) -> np.ndarray:
    """The joint shape of the pair, or ``joint`` checked as a (10, 10) finite matrix."""
    if joint is None:
        return pair_shape(F8, N8)
    C = np.asarray(joint, float)
    if C.shape != (10, 10) or not np.all(np.isfinite(C)):
        raise ValueError(f"joint shape must be (10, 10) finite values, got {C.shape}")
    return 0.5 * (C + C.T)


def product_supports(F8, N8, H: float, joint=None) -> tuple[np.ndarray, np.ndarray]:
    """Supports of the product set {|e_h| <= H} x Z_8 in the scheduling box's coordinates.

    Parameters
    ----------
    F8 : (2, 8) array_like
    N8 : (8, 8) array_like
    H : float
        Altitude error bound [ft].
    joint : (10, 10) array_like, optional
        Joint shape of (e_8, u - v) in place of the pair's (:func:`pair_shape`).

    Returns
    -------
    s_lo : (6,) ndarray
        h [ft], V [ft/s], alpha, theta [rad], then the input deviation in Phi [-] and
        delta_e [rad] (F_8 Z_8 for the pair).
    s_oth : (5,) ndarray
        q [rad/s] and the flexible states.

    Raises
    ------
    ValueError
        On a malformed ``joint`` or pair.
    """
    s = np.sqrt(np.maximum(np.diag(_joint(F8, N8, joint)), 0.0))
    return np.concatenate([[H], s[:3], s[8:]]), s[3:8]


def product_bound(
    nv: NominalVertices, F8, N8, H: float, joint=None
) -> tuple[np.ndarray, np.ndarray]:
    """Parameter and interpolation parts (9,), (9,) of the disturbance over the product set.

    The parameter part is, per row, the largest support over {|e_h| <= H} x Z_8 of each
    vehicle's residual (the part of its Jacobian deviation the vertices do not carry)
    applied to [e; P F e], P = diag(1, rho_f), at every box corner, for rho_f at both
    ends of [rho_min, 1] (exact for the product set: |r_h| H plus the ellipsoid's
    support). The interpolation part is the elementwise remainder bound times the
    product set's supports in e and F e. With ``joint`` the set of (e_8, u - v) is the
    ellipsoid of that shape in place of {(e_8, F_8 e_8) : e_8 in Z_8}. Without it and
    with ``nv.tau`` < 1 (the adjustable law, eq. 48), u - v = tau' F_8 e_8 for any
    tau' in [tau, 1]: the parameter part is the larger of its values at the two ends
    (each support is convex in tau'), and F_8 Z_8 holds every tau' F_8 Z_8.

    Parameters
    ----------
    nv : NominalVertices
        Vertex data over the scheduling box (:func:`fahv.design.along_nominal.nominal_vertices`).
    F8, N8, H
        The pair and its altitude bound, as in :func:`product_supports`.

    Returns
    -------
    parameters, interpolation : (9,) ndarray
        In state units per period, rows h ... eta_2_dot.

    Raises
    ------
    ValueError
        On a malformed ``joint`` or pair, or a ``joint`` with ``nv.tau`` < 1.
    """
    C = _joint(F8, N8, joint)
    if joint is not None and nv.tau < 1.0:
        raise ValueError(
            f"product_bound: a loop's joint shape covers its own gain, not the adjustable "
            f"law's tau' in [{nv.tau:g}, 1]"
        )
    # the adjustable law's gains tau' F, tau' in [nv.tau, 1]: each support is the square
    # root of a convex quadratic in tau', so its largest value is at an end of the segment
    shapes = [C] if nv.tau == 1.0 else [C, _joint(nv.tau * F8, N8, None)]
    par = np.zeros(9)
    R = nv.residual  # (64, C, 9, 11) on (e_h, e_8, u - v)
    for rho, Cg in itertools.product((nv.rho_min, 1.0), shapes):
        S = np.r_[np.ones(9), rho]  # (e_8, u - v) -> (e_8, P (u - v)), P = diag(1, rho_f)
        sup = np.abs(R[..., 0]) * H + np.sqrt(
            np.einsum("scij,jk,scik->sci", R[..., 1:], S[:, None] * Cg * S[None, :], R[..., 1:])
        )
        par = np.maximum(par, sup.max(axis=(0, 1)))
    s_lo, s_oth = product_supports(F8, N8, H, C)  # (h, V, alpha, theta, F Z), (q, flexible)
    interp = nv.interp @ np.concatenate([s_lo[:4], s_oth, s_lo[4:]])
    return par, interp


@dataclass(frozen=True)
class AltitudeBound:
    """H of (1) and the disturbance bound of the eight rows it implies.

    Attributes
    ----------
    H : float
        [ft], the fixed point of H = moves (step + w_h(H)).
    step : float
        [ft] largest support over Z_8 of a_h,8 e_8 + b_h F_8 e_8 over the vertices.
    w_h : float
        [ft] the h row's disturbance at H.
    bound : (8,) ndarray
        Disturbance bound of rows V ... eta_2_dot over the product set, e_h's coupling
        max |A_8h| H included.
    """

    H: float
    step: float
    w_h: float
    bound: np.ndarray


def altitude_bound(nv: NominalVertices, A, B, F8, N8, moves: int, joint=None) -> AltitudeBound:
    """Solve (1) for H and bound the eight rows' disturbance over the product set.

    Parameters
    ----------
    nv : NominalVertices
    A : (R, 9, 9) array_like
    B : (R, 9, 2) array_like
        The vertices (:meth:`NominalVertices.vertices`).
    F8 : (2, 8) array_like
    N8 : (8, 8) array_like
    moves : int
        Fast steps between the nominal's altitude resets.
    joint : (10, 10) array_like, optional
        Joint shape of (e_8, u - v) in place of the pair's (:func:`pair_shape`): the
        step of (1) is then the support of a_h,8 e_8 + b_h (u - v) over it.

    Returns
    -------
    AltitudeBound

    Raises
    ------
    DesignError
        If the iteration for H does not converge (the h row's own disturbance grows with
        H as fast as the reset allows).
    ValueError
        On a malformed ``joint`` or pair.
    """
    A, B = np.asarray(A, float), np.asarray(B, float)
    C = _joint(F8, N8, joint)
    c = np.concatenate([A[:, 0, 1:], B[:, 0]], axis=1)  # (R, 10) on (e_8, u - v)
    step = float(np.sqrt(np.einsum("ri,ij,rj->r", c, C, c)).max())
    H = moves * step
    for _ in range(100):
        par, interp = product_bound(nv, F8, N8, H, joint)  # joint None: the gains of nv.tau
        H_new = moves * (step + par[0] + interp[0])
        if abs(H_new - H) <= 1e-12 * H_new:
            break
        H = H_new
    else:
        raise DesignError(f"eight-state tube: the altitude bound H does not converge ({H:.4g} ft)")
    bound = par[1:] + interp[1:] + np.abs(A[:, 1:, 0]).max(axis=0) * H_new
    return AltitudeBound(float(H_new), step, float(par[0] + interp[0]), bound)


def pulse_peak(a: float, j0: float, parts, steps: int = 100_000) -> float:
    """Peak of d_k+1 = a d_k + p_k, d_0 = 0: the error's largest norm after a jump.

    p_0 = j0 is the jump's first step; after it p_k = sum_i j_i (1 - gamma_i)^k, the parts
    of the jump each removed by the estimate at its own gain per step. d bounds the norm
    of the part of the error the jump drives when every vertex's closed loop contracts
    the norm by at most a. The sequence rises to its peak and then falls (p_k falls).
    The norm recursion of the onset bound (:func:`onset_bound`; docs/control_design.md,
    "The onset as a transient of the eight-state pair"). For one part (j, gamma) with
    j0 = j, the peak per unit jump is max_k (a^k - b^k) / (a - b), b = 1 - gamma.

    Parameters
    ----------
    a : float
        Contraction of the closed loop in the norm, in [0, 1).
    j0 : float
        Norm of the first step's jump (>= 0).
    parts : sequence of (float, float)
        (j_i, gamma_i): norm of a part of the jump (>= 0) and its estimator gain per
        step, in (0, 1].
    steps : int
        Steps searched for the peak.

    Returns
    -------
    float
        The peak (>= j0).

    Raises
    ------
    ValueError
        If a, a norm or a gain is out of range.
    """
    parts = [(float(j), float(g)) for j, g in parts]
    if not 0.0 <= a < 1.0 or j0 < 0.0 or any(j < 0.0 or not 0.0 < g <= 1.0 for j, g in parts):
        raise ValueError(f"pulse_peak: need 0 <= a < 1, norms >= 0, gains in (0, 1]: got "
                         f"{a}, {j0}, {parts}")  # fmt: skip
    d, peak = float(j0), float(j0)
    decay = [1.0 - g for _, g in parts]
    for k in range(1, steps):
        d = a * d + sum(j * dk**k for (j, _), dk in zip(parts, decay, strict=True))
        if d < peak:
            break
        peak = d
    return peak


@dataclass(frozen=True)
class OnsetBound:
    """The onset of an elevator loss as a transient of a closed pair (:func:`onset_bound`).

    Attributes
    ----------
    loss : float
        The design's loss 1 - rho_min.
    gamma : float
        The case's estimator gain per step (Ts / est_tau).
    gamma_e : float
        Its gain along the elevator column (Ts / est_tau_elevator; 0: none, gamma in every
        direction).
    contraction : float
        a: largest factor by which a vertex's closed loop A_8 + B_8 F_8 maps Z_8's norm.
    steady : float
        c: the level the error holds at with the disturbance inside the bound (the largest
        bound / W_8, at the altitude bound grown by the onset): c Z_8 is RPI for c W_8.
    steady_shaped : float
        c_w: the same for an ellipsoid shaped for the bound itself (:func:`steady_set`):
        the Z_8 radius of the smallest ellipsoid RPI for the bound's own box at every
        vertex, exactly re-checked (inf if none is found). The level the bound starts
        from is min(c, c_w) (:attr:`level0`).
    jump : float
        j: the largest Z_8 norm of J_8 / rho_f at the design loss over the scheduling box
        and every corner of the parameter box.
    jump_elevator, jump_rest : float
        With gamma_e: the largest Z_8 norms of the jump's share along the estimate's
        elevator direction and of the rest, over the samples and the directions (0
        without gamma_e).
    interior_ratio : float
        The interior samples' largest norm over the corners' (<= 1: the corners hold it).
    peak : float
        min(c, c_w) + the jump's pulse peak (:func:`pulse_peak`): the level bound at the
        design loss with the case's estimate (certified when <= 1).
    certified_loss, certified_loss_one_step : float
        The largest loss whose level bound is <= 1 with the case's estimate, and with an
        estimate that knows the whole loss one step after it acts (min(c, c_w) + j <= 1:
        the ceiling of any analysis that keeps e in Z_8 from that steady set).
    jump_h : float
        [ft] largest |J_h| / rho_f at the design loss (e_h's share, added to H).
    jump_share : tuple of 8 floats
        The jump of largest Z_8 norm, state by state (V, alpha, theta, q, eta_1,
        eta_1_dot, eta_2, eta_2_dot) as a signed multiple of Z_8's support in that state:
        which states make the norm.
    jump_rigid : float
        The largest Z_8 norm of the jumps with q and the bending modes left out: what the
        requirement states V, alpha and theta receive.
    jump_rigid_q : float
        The same with only the bending modes left out (V, alpha, theta and q).
    witness : OnsetWitness or None
        The lower bound at the design's loss (:func:`onset_witness`; None: not computed).
    ceiling : float
        With ``witness``: the smallest loss found whose lower bound exceeds 1, bisected
        between ``certified_loss`` and the design's loss (an upper bound of what any
        analysis on the pair's assumptions can certify); the design's loss when its own
        lower bound is at most 1; nan without ``witness``.
    """

    loss: float
    gamma: float
    gamma_e: float
    contraction: float
    steady: float
    steady_shaped: float
    jump: float
    jump_elevator: float
    jump_rest: float
    interior_ratio: float
    peak: float
    certified_loss: float
    certified_loss_one_step: float
    jump_h: float
    jump_share: tuple[float, ...]
    jump_rigid: float
    jump_rigid_q: float
    witness: OnsetWitness | None = None
    ceiling: float = float("nan")

    @property
    def level0(self) -> float:
        """The steady level the bound starts from, min(c, c_w)."""
        return min(self.steady, self.steady_shaped)

    def summary(self) -> dict:
        """JSON-ready record (the attributes; ``jump_share`` as a list)."""
        out = {k: [float(x) for x in v] if isinstance(v, tuple) else float(v)
               for k, v in self.__dict__.items() if k != "witness"}  # fmt: skip
        if self.witness is not None:
            out["witness"] = {k: float(v) if isinstance(v, float) else int(v)
                              for k, v in self.witness.__dict__.items()}  # fmt: skip
        return out

    def lines(self) -> list[str]:
        """The design log's lines of the bound."""
        ok = self.peak <= 1.0
        gains = f"estimate gain {self.gamma:.3f} per step"
        if self.gamma_e > 0.0:
            gains += (
                f", {self.gamma_e:.3f} along the elevator column (the jump's share along it "
                f"{self.jump_elevator:.3f}, the rest {self.jump_rest:.3f} x Z_8)"
            )
        return [
            f"onset of a {100 * self.loss:.1f} % loss (item 3; from the error at its steady "
            f"level {self.level0:.3f} (c Z_8, c = {self.steady:.3f}; the ellipsoid RPI for the "
            f"bound itself lies in {self.steady_shaped:.3f} Z_8), {gains}): first jump "
            f"{self.jump:.3f} x Z_8 at the scheduling box's worst point (interior samples "
            f"{self.interior_ratio:.3f} of the corners'), closed-loop contraction "
            f"{self.contraction:.5f} per step, level bound {self.peak:.3f} "
            + ("<= 1  OK" if ok else "> 1: NOT certified"),
            f"largest loss whose onset keeps e in Z_8: {100 * self.certified_loss:.2f} % with "
            f"the case's estimate, {100 * self.certified_loss_one_step:.2f} % with an estimate "
            "that knows the whole loss one step after it acts (the first step alone, which no "
            "estimate can remove)",
            "the first jump state by state, x Z_8's support: "
            + ", ".join(f"{n} {v:+.3f}" for n, v in zip(EIGHT_STATES, self.jump_share, strict=True))
            + f"; its Z_8 norm without the bending modes {self.jump_rigid_q:.3f}, without q and "
            f"them (V, alpha, theta alone) {self.jump_rigid:.3f}",
        ] + ([] if self.witness is None else [self.witness_line()])

    def witness_line(self) -> str:
        """The design log's line of the lower bound (requires ``witness``)."""
        w = self.witness
        refuted = w.level_any_column > 1.0
        return (
            f"onset lower bound (one vertex held, w inside the bound for {w.pre_steps} steps, "
            f"a jump sample, the estimate's most favourable elevator direction; re-simulated): "
            f"level {w.level:.3f} at the {100 * self.loss:.1f} % loss, {w.step} steps after "
            f"the onset (its onset part {w.pulse:.3f}; whichever column the estimate uses, "
            f"{w.level_any_column:.3f}) "
            + ("> 1: no analysis on the pair's assumptions certifies this loss; the smallest "
               f"loss so refuted {100 * self.ceiling:.2f} % (certified "
               f"{100 * self.certified_loss:.2f} %)" if refuted else
               "<= 1: not refuted")
        )  # fmt: skip


def steady_set(Acl8, N8, F8, bound, lam: float) -> tuple[float, np.ndarray | None]:
    """The error's steady set shaped for the disturbance bound itself (the onset bound's c_w).

    Before an onset the error is driven by a disturbance inside the pair's bound (per row,
    ``bound`` <= W_8) from e = 0. c Z_8 (c = the largest bound / W_8) is RPI for it, but
    the bound's rows are far from uniform (V 0.85-0.88 of W_8, the others 0.28-0.55), so
    a smaller set is: the smallest ellipsoid E(P) RPI for the box ``bound`` at every
    closed-loop vertex with its projection in s Z_8, s minimised
    (:func:`fahv.synthesis.feedback.invariant_ellipsoid`, the analysis form of LMI (24),
    constraint generation over the vertices). Accepted only on the exact re-check, the
    worst one-step level over every vertex and every corner of the box at most 1
    (:func:`fahv.design.certificate.vertex_levels`); s is then the largest eigenvalue of
    N_8^-1/2 P N_8^-1/2, square-rooted.

    Parameters
    ----------
    Acl8 : (R, 8, 8) ndarray
        Closed-loop vertices A_8 + B_8 F_8.
    N8 : (8, 8) ndarray
        Z_8's shape.
    F8 : (2, 8) ndarray
        The tube gain (its supports over E(P) are kept within F_8 Z_8's).
    bound : (8,) array_like
        The disturbance bound per row (state units per period).
    lam : float
        Contraction factor of the S-procedure, in (0, 1).

    Returns
    -------
    c_w : float
        s (inf if no ellipsoid is found or the exact re-check fails).
    P : (8, 8) ndarray or None
        The ellipsoid's shape.
    """
    Acl8, N8, F8 = (np.asarray(v, float) for v in (Acl8, N8, F8))
    bound = np.asarray(bound, float)
    tightening = np.sqrt(np.einsum("ij,jk,ik->i", F8, N8, F8))
    ell = invariant_ellipsoid(Acl8, bound, np.sqrt(np.diag(N8)), N8, F8, tightening,
                              lambda P: vertex_levels(Acl8, P, bound), lam)  # fmt: skip
    if ell is None or float(vertex_levels(Acl8, ell.P, bound).max()) > 1.0:
        return float("inf"), None
    L = np.linalg.cholesky(N8)
    s = np.sqrt(np.linalg.eigvalsh(np.linalg.solve(L, np.linalg.solve(L, ell.P).T)).max())
    return float(s), ell.P


@dataclass(frozen=True)
class OnsetWitness:
    """An onset scenario inside a pair's own assumptions that leaves Z_8 (or comes closest).

    A lower bound of what any analysis of the onset on the pair's assumptions can
    certify (:func:`onset_witness`): one closed-loop vertex held throughout, a
    disturbance sequence inside the bound's box, one nonlinear jump sample and the
    estimate's most favourable elevator direction. ``level`` is the Z_8 norm of the
    error that sequence reaches, re-simulated step by step.

    Attributes
    ----------
    level : float
        The Z_8 norm the scenario reaches with the estimate's most favourable column,
        re-simulated.
    vertex, sample, direction : int
        Indices of the vertex, the jump sample and the estimate's direction (-1: none).
    step : int
        Steps after the onset at which the level is reached (0: the onset's own step).
    pre_steps : int
        Steps of the disturbance sequence before that.
    pulse : float
        The Z_8 norm the onset's part alone reaches at that step (the rest is the
        disturbance sequence's).
    level_any_column : float
        The level a scenario of the search reaches whichever column the estimate projects
        on (the smallest over the columns of z' e at each column's peak, <= ``level``):
        > 1 shows that no certificate on these assumptions keeps e in Z_8.
    """

    level: float
    vertex: int
    sample: int
    direction: int
    step: int
    pre_steps: int
    pulse: float
    level_any_column: float


def onset_witness(Acl8, N8, bound, J, gamma: float, *, gamma_e: float | None = None,
                  directions=None, projection_scale=None, top: int = 6, steps: int = 60,
                  pre_steps: int = 3000, candidates: int = 50) -> OnsetWitness:  # fmt: skip
    """The worst onset of a loss the pair's own assumptions allow, found explicitly.

    The onset bound (:func:`onset_bound`) is an upper bound; this is the matching lower
    bound. Its model is the bound's own: e = e_w + e_p along any vertex sequence, e_w
    driven by w in the box ``bound``, e_p from 0 by the jump J at the onset's step and
    then by what the estimate has not yet removed, p_k = (1 - gamma_e)^k J_b +
    (1 - gamma)^k J_r (J_b = the share of J along the estimate's elevator direction b,
    J_r the rest; p_k = (1 - gamma)^k J without gamma_e). Held at one vertex A, e_p is
    computed exactly for each of the ``top`` jumps of largest Z_8 norm and every
    direction b, for ``steps`` steps; at its largest Z_8 norm, at step k with direction
    z = N_8^-1 e_p / ||e_p||, the disturbance w_(k-1-t) = sign(z' A^t) * bound for
    t < ``pre_steps`` (the last ``pre_steps`` steps up to k) adds sum_t |z' A^t| . bound
    to z' e. The direction b is taken as the most favourable (the smallest such level
    over the vertices searched): that level, ``level_any_column``, is reached whichever
    elevator column the estimate projects on. The winning scenario is re-simulated step
    by step from e = 0 (its norm ``level`` is at least z' e). Every ingredient (vertex,
    jump sample, w inside the box, the estimate's model) is one the certificate must
    cover, so ``level_any_column`` above 1 shows that no analysis on these assumptions
    keeps e in Z_8 at this loss.

    Parameters
    ----------
    Acl8 : (R, 8, 8) ndarray
        The pair's closed-loop vertices A_8 + B_8 F_8, each a candidate to hold.
    N8 : (8, 8) ndarray
        Z_8's shape: the level reported is the Z_8 norm sqrt(e' N8^-1 e).
    bound : (8,) array_like
        Half-widths of the disturbance box (state units per period).
    J : (S, 9) ndarray
        Jump samples J / rho_f, h first (state units per period), e.g. from
        :func:`fahv.design.along_nominal.onset_jumps`; the estimate's share is taken of
        all nine rows, as it computes it, and the error of the last eight.
    gamma : float
        The estimate's gain per step, in (0, 1].
    gamma_e, directions, projection_scale
        As :func:`onset_bound` (directions (D, 9), scale (9,)).
    top : int
        Jump samples tried (largest Z_8 norm first).
    steps : int
        Steps after the onset searched for the peak.
    pre_steps : int
        Length of the disturbance sequence.
    candidates : int
        Vertices (largest onset part first) given the disturbance sequence.

    Returns
    -------
    OnsetWitness

    Raises
    ------
    ValueError
        On inconsistent shapes or gains out of range.
    DesignError
        If the re-simulated level falls short of the constructed one (a defect).
    """
    Acl8, N8, J = (np.asarray(v, float) for v in (Acl8, N8, J))
    bound = np.asarray(bound, float)
    R = Acl8.shape[0]
    if Acl8.shape[1:] != (8, 8) or N8.shape != (8, 8) or bound.shape != (8,) \
            or J.ndim != 2 or J.shape[1] != 9 or not 0.0 < gamma <= 1.0:  # fmt: skip
        raise ValueError(f"onset_witness: shapes Acl8 {Acl8.shape}, N8 {N8.shape}, bound "
                         f"{bound.shape}, J {J.shape}; gamma {gamma}")  # fmt: skip
    J8 = J[:, 1:]
    if gamma_e is None:
        shares = np.zeros((1, len(J8), 8))  # no elevator part: p_k = (1 - gamma)^k J
        g_e = 1.0
    else:
        directions = np.atleast_2d(np.asarray(directions, float))
        scale = np.asarray(projection_scale, float)
        if not 0.0 < gamma_e <= 1.0 or directions.shape[1:] != (9,) or scale.shape != (9,):
            raise ValueError(f"onset_witness: gamma_e {gamma_e}, directions "
                             f"{directions.shape}, projection_scale {scale.shape}")  # fmt: skip
        shares = np.stack([elevator_share(J, b, scale)[:, None] * b[1:] for b in directions])
        g_e = float(gamma_e)
    Ninv = np.linalg.inv(N8)

    def norm(X):
        return np.sqrt(np.einsum("...i,ij,...j->...", X, Ninv, X))

    def pulse_run(s, Jb):  # e_p over steps at every vertex for the directions' shares Jb (D, 8)
        Jr = J8[s] - Jb
        e = np.broadcast_to(J8[s], (len(Jb), R, 8)).copy()
        best, e_best = norm(e), e.copy()
        k_best = np.zeros(best.shape, int)
        for k in range(1, steps):
            p = (1.0 - g_e) ** k * Jb + (1.0 - gamma) ** k * Jr
            e = np.einsum("rij,drj->dri", Acl8, e) + p[:, None, :]
            n = norm(e)
            up = n > best
            best, k_best = np.where(up, n, best), np.where(up, k, k_best)
            e_best[up] = e[up]
        return best, k_best, e_best

    AT = np.transpose(Acl8, (0, 2, 1))
    found = None
    for s in np.argsort(-norm(J8))[:top]:
        best, k_best, e_best = pulse_run(s, shares[:, s])
        levels = []
        for d in range(len(best)):  # the sequence's share for the best candidates
            cand = np.argsort(-best[d])[:candidates]
            z = np.einsum("ij,rj->ri", Ninv, e_best[d, cand]) / best[d, cand][:, None]
            v, reach = z.copy(), np.zeros(len(cand))
            for _ in range(pre_steps):
                reach += np.abs(v) @ bound
                v = np.einsum("rij,rj->ri", AT[cand], v)
            i = int(np.argmax(best[d, cand] + reach))
            levels.append((float(best[d, cand[i]] + reach[i]), int(cand[i])))
        d = int(np.argmin([lv for lv, _ in levels]))  # the estimate's most favourable b
        if found is None or levels[d][0] > found[0]:
            found = (levels[d][0], int(s), d, levels[d][1])
    level, s, d, r = found
    A = Acl8[r]
    Jb = shares[d, s]
    _, k_best, e_best = pulse_run(s, Jb[None])
    k = int(k_best[0, r])
    z = Ninv @ e_best[0, r] / norm(e_best[0, r])
    # re-simulate: w at the t-th step before the target is sign(z' A^t) * bound
    signs, v = [], z.copy()
    for _ in range(pre_steps):
        signs.append(np.sign(v))
        v = A.T @ v
    e = np.zeros(8)
    for t in range(pre_steps - 1, -1, -1):  # steps pre_steps - 1 ... 0 before the target
        e = A @ e + signs[t] * bound
        m = k - t  # this step's index after the onset (0: the onset's own step)
        if m == 0:
            e = e + J8[s]
        elif m > 0:
            e = e + (1.0 - g_e) ** m * Jb + (1.0 - gamma) ** m * (J8[s] - Jb)
    simulated = float(norm(e))
    if simulated < level * (1.0 - 1e-9) or not np.isfinite(simulated):
        raise DesignError(f"onset_witness: the re-simulated level {simulated:.6f} falls short "
                          f"of the constructed {level:.6f}")  # fmt: skip
    return OnsetWitness(simulated, r, s, d if gamma_e is not None else -1, k, pre_steps,
                        float(norm(e_best[0, r])), level)  # fmt: skip


def onset_bound(nv: NominalVertices, pair: EightStatePair, vehicle, trim_map,
                uncertainty: dict, gamma: float, Ts: float, n_sub: int, *,
                gamma_e: float | None = None, directions=None, projection_scale=None,
                interior: int = 1024, iterations: int = 6,
                steady_shaped: float | None = None, steady_lams=None,
                witness_iterations: int = 4) -> OnsetBound:  # fmt: skip
    """Bound the onset of an elevator loss as a transient of the pair (item 3).

    At the step a loss of 1 - rho_f starts, the plant moves by J = f_p(x, P u) - f_p(x, u)
    more than the nominal (with the estimate of the step before) expects
    (:func:`fahv.design.along_nominal.onset_jumps`); as the controller's command grows to
    delta_e / rho_f the residual grows on to J / rho_f. The estimate removes what it has
    seen at the rate gamma per step, so the estimate's error is a sum of such jumps, each
    decaying as (1 - gamma)^k. The error dynamics are linear along any sequence of the
    vertices (rho_f at both ends of [rho_min, 1] among them), so e = e_w + e_p: e_w,
    driven by the disturbance inside the bound from the error at the onset, stays in
    c Z_8 if it starts there (c Z_8 is RPI for c W_8); e_p, driven by the estimate's error
    from 0, has the Z_8 norm at most pulse_peak(a, j, [(j, gamma)]),
    j = max ||J_8 / rho_f||_Z_8 (the jumps arriving later only delay part of it). With a
    gain gamma_e along the elevator column b (:class:`fahv.control.nominal_mpc.
    DisturbanceEstimator`), the jump's share along b, P_b J, decays at gamma_e and the
    rest at gamma: pulse_peak(a, j, [(j_b, gamma_e), (j_r, gamma)]) with j_b, j_r the
    largest norms of P_b J and J - P_b J over the samples and the estimate's possible
    directions b. e stays in Z_8 if c + that peak <= 1. The altitude error takes
    |J_h| / rho_f per step on top of (1), at most 1 / gamma of it between resets; the
    bound of c is taken at that H. e_w also stays in the ellipsoid RPI for that bound
    itself, which lies in c_w Z_8 (:func:`steady_set`); the bound starts from
    min(c, c_w).

    The bound is an upper one. Its matching lower bound (:func:`onset_witness`) builds
    the worst onset the same model allows at one vertex held throughout, re-simulated: if
    its level exceeds 1 at the design's loss, no analysis on the pair's assumptions
    certifies that loss, and the smallest loss it so refutes is bisected (``ceiling``):
    the loss certifiable on this pair lies between ``certified_loss`` and it.

    Parameters
    ----------
    nv : NominalVertices
        The pair's vertex data over its scheduling box.
    pair : EightStatePair
        The closed pair (its loss is nv.rho_min).
    vehicle, trim_map
        The nominal vehicle and its trim map.
    uncertainty : dict[str, float]
        Relative half-widths of the parameter box.
    gamma : float
        The case's estimator gain per step, in (0, 1].
    Ts : float
        Control period [s].
    n_sub : int
        RK4 sub-steps per period.
    gamma_e : float, optional
        The estimate's gain along the elevator column, in (0, 1].
    directions : (D, 9) array_like, optional
        With gamma_e: the elevator columns the estimate may project on (the scheduled
        model's, e.g. its LPV vertices' B_i[:, 1]).
    projection_scale : (9,) array_like, optional
        With gamma_e: the state scale of the estimate's projection metric (its ``scale``).
    interior : int
        Interior samples of the jumps besides the corners.
    iterations : int
        Bisection steps for each certified loss.
    steady_shaped : float, optional
        c_w when already computed for this pair and bound (:func:`steady_set`, a
        minute or two over 4096 vertices); computed here by default.
    steady_lams : sequence of float, optional
        Contraction factors tried for that ellipsoid (the smallest c_w is kept; a minute
        or two each); default: the pair's lam alone.
    witness_iterations : int
        Bisection steps for the smallest loss the lower bound refutes
        (:func:`onset_witness` at the design's loss, then between the certified loss and
        it; half a minute each over 16384 vertices); 0: no lower bound.

    Returns
    -------
    OnsetBound

    Raises
    ------
    ValueError
        If a gain is not in (0, 1], or gamma_e comes without directions (D, 9) and a
        positive projection_scale (9,).
    DesignError
        If a plant step is not finite.
    """
    if not 0.0 < gamma <= 1.0:
        raise ValueError(f"onset_bound: gamma must be in (0, 1], got {gamma}")
    if gamma_e is not None:
        directions = np.atleast_2d(np.asarray(directions, float))
        scale = np.asarray(projection_scale, float)
        if not 0.0 < gamma_e <= 1.0 or directions.shape[1:] != (9,) or scale.shape != (9,) \
                or not np.all(scale > 0.0):  # fmt: skip
            raise ValueError(
                f"onset_bound: gamma_e in (0, 1] needs directions (D, 9) and a positive scale "
                f"(9,); got {gamma_e}, {directions.shape}, {scale.shape}"
            )
    A, B = nv.vertices()
    A8, B8 = A[:, 1:, 1:], B[:, 1:, :]
    L = np.linalg.cholesky(pair.N8)
    Acl8 = A8 + B8 @ pair.F8
    a = float(np.linalg.norm(np.linalg.solve(L, Acl8) @ L, 2, axis=(1, 2)).max())

    def z8(V):  # Z_8 norms of the e_8 parts of rows V (S, 9)
        return np.sqrt((np.linalg.solve(L, V[:, 1:].T) ** 2).sum(axis=0))

    def jumps(loss: float, full: bool = False):
        J, n_c = onset_jumps(nv.box, vehicle, trim_map, uncertainty, 1.0 - loss, Ts, n_sub,
                             interior)  # fmt: skip
        J = J / (1.0 - loss)
        norm, jb, jr = z8(J), 0.0, 0.0
        if gamma_e is not None:
            for b in directions:  # the share along b, as the estimate takes it
                PJ = elevator_share(J, b, scale)[:, None] * b
                jb, jr = max(jb, float(z8(PJ).max())), max(jr, float(z8(J - PJ).max()))
        out = norm, n_c, float(np.abs(J[:, 0]).max()), jb, jr
        return (*out, J) if full else out

    def peak(j, jb, jr, one_step=False):
        if one_step:
            return j
        parts = [(j, gamma)] if gamma_e is None else [(jb, gamma_e), (jr, gamma)]
        return pulse_peak(a, j, parts)

    loss = 1.0 - nv.rho_min
    norm, n_c, jump_h, jb, jr, J = jumps(loss, full=True)
    j = float(norm.max())
    share = tuple(float(v) for v in J[int(norm.argmax()), 1:] / np.sqrt(np.diag(pair.N8)))
    J_rigid = J.copy()
    J_rigid[:, 5:] = 0.0  # the bending modes (J's columns 5-8; column 0 is h)
    rigid_q = float(z8(J_rigid).max())
    J_rigid[:, 4] = 0.0  # and q
    rigid = float(z8(J_rigid).max())
    H = pair.H + jump_h / gamma
    par, interp = product_bound(nv, pair.F8, pair.N8, H)
    bound = par[1:] + interp[1:] + np.abs(A[:, 1:, 0]).max(axis=0) * H
    c = float((bound / pair.W8).max())
    if steady_shaped is None:
        steady_shaped = min(steady_set(Acl8, pair.N8, pair.F8, bound, lam)[0]
                            for lam in (steady_lams or (pair.lam,)))  # fmt: skip
    c_s = float(steady_shaped)
    c0 = min(c, c_s)  # the steady level the bound starts from

    def certified(one_step: bool) -> float:
        if c0 >= 1.0:
            return 0.0
        p = peak(j, jb, jr, one_step)
        if c0 + p <= 1.0:
            return loss
        lo, hi = 0.0, loss
        guess = 2.0 * loss * (1.0 - c0) / p  # twice the first-order loss: bracket

        def ok(x):
            n, _, _, xb, xr = jumps(x)
            return c0 + peak(float(n.max()), xb, xr, one_step) <= 1.0

        if guess < loss:
            lo, hi = (guess, loss) if ok(guess) else (0.0, guess)
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if ok(mid) else (lo, mid)
        return lo

    est = {} if gamma_e is None else {"gamma_e": gamma_e, "directions": directions,
                                       "projection_scale": scale}  # fmt: skip

    def witness(J_x):
        return onset_witness(Acl8, pair.N8, bound, J_x, gamma, **est)

    cert, cert_one_step = certified(False), certified(True)
    found = witness(J) if witness_iterations > 0 else None
    ceiling = float("nan") if found is None else loss
    if found is not None and found.level_any_column > 1.0:  # the smallest loss refuted
        lo, ceiling = cert, loss
        for _ in range(witness_iterations):
            mid = 0.5 * (lo + ceiling)
            lo, ceiling = (lo, mid) if witness(jumps(mid, full=True)[-1]).level_any_column > 1.0 \
                else (mid, ceiling)  # fmt: skip
    return OnsetBound(
        loss, gamma, 0.0 if gamma_e is None else float(gamma_e), a, c, c_s, j, jb, jr,
        float(norm[n_c:].max() / norm[:n_c].max()) if len(norm) > n_c else 0.0,
        c0 + peak(j, jb, jr), cert, cert_one_step, jump_h, share, rigid, rigid_q, found, ceiling,
    )  # fmt: skip


def box_shortfall(box: SchedulingBox, nominal: SchedulingBox, F8, N8, H: float) -> dict:
    """Where the scheduling box does not hold the nominal box grown by the product set.

    Returns a mapping from coordinate name ("lo alpha", "hi Phi", "q", ...) to how far
    [coordinate units] the box falls short there; empty when it holds it (the integral
    form's segment condition, :mod:`fahv.design.along_nominal` (2)).
    """
    s_lo, s_oth = product_supports(F8, N8, H)
    lo, hi, oth = box.margin_to(nominal)
    reach = np.r_[lo - s_lo, hi - s_lo, oth - s_oth]
    names = [f"{side} {c}" for side in ("lo", "hi") for c in BOX_COORDINATES]
    names += ["q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot"]
    return {n: float(-v) for n, v in zip(names, reach, strict=True) if v < 0}


def certified_range(box: SchedulingBox, F8, N8, H: float) -> SchedulingBox:
    """The nominal points the pair's certificate covers: the scheduling box less the tube.

    The vertices and W_8's bound hold for every segment from a nominal point to the plant
    inside the scheduling box (the integral form, :mod:`fahv.design.along_nominal` (2)),
    so the certificate needs the nominal inside the box shrunk by the product set's
    supports (H in h, Z_8's in the states, F_8 Z_8's in the inputs); the nominal box of
    the case is a part of it (:func:`box_shortfall` checks that).

    Parameters
    ----------
    box : SchedulingBox
        The scheduling box (coordinates :data:`BOX_COORDINATES`, then q and the
        flexible states as half-widths).
    F8, N8, H
        The pair and its altitude bound, as in :func:`product_supports`.

    Returns
    -------
    SchedulingBox
        The certified nominal range in the same coordinates.

    Raises
    ------
    ValueError
        If the tube does not fit inside the box in some coordinate (an empty range).
    """
    s_lo, s_oth = product_supports(F8, N8, H)
    lo, hi, oth = box.lo + s_lo, box.hi - s_lo, box.other_half - s_oth
    if np.any(lo > hi) or np.any(oth < 0.0):
        raise ValueError(
            "certified range: the tube does not fit inside the scheduling box (supports "
            f"{s_lo.tolist()}, {s_oth.tolist()})"
        )
    return SchedulingBox(lo, hi, oth)


def box_for(h_range, nominal: SchedulingBox, F8, N8, H: float, scale: float) -> SchedulingBox:
    """The scheduling box holding ``nominal`` plus 1.01 ``scale`` times the product set.

    Parameters
    ----------
    h_range : (2,) array_like
        The box's h range [ft] (the envelope).
    nominal : SchedulingBox
    F8, N8, H
        The pair whose product set's supports grow the box.
    scale : float
        Size of the tube the box is for, in units of the pair's.
    """
    s_lo, s_oth = product_supports(F8, N8, H)
    x = 1.01 * scale
    lo = np.r_[h_range[0], nominal.lo[1:] - x * s_lo[1:]]
    hi = np.r_[h_range[1], nominal.hi[1:] + x * s_lo[1:]]
    return SchedulingBox(lo, hi, nominal.other_half + x * s_oth)


def close_pair(
    nv: NominalVertices,
    nominal: SchedulingBox,
    W8,
    state_scale,
    input_scale,
    room,
    lam: float,
    moves: int,
    *,
    grow: float = 1.05,
    iterations: int = 6,
    w_ref=None,
    active: int = 96,
    state_max=None,
    contain=None,
    log: Callable[[str], None] = print,
) -> EightStatePair:
    """Iterate W_8 and Z_8 to a closed pair over the vertices ``nv`` (module docstring).

    Parameters
    ----------
    nv : NominalVertices
        Vertex data over the scheduling box (``hessians=False`` suffices).
    nominal : SchedulingBox
        The nominal's own box, which the scheduling box must hold grown by the tube.
    W8 : (8,) array_like
        Starting half-widths of W_8 (state units per period).
    state_scale : (9,) array_like
        Design state scaling (Dx); its eight entries after h scale the LMI.
    input_scale : (2,) array_like
        Design input scaling (Du).
    room : (2,) array_like
        Input room of each row (:func:`fahv.design.feasibility.input_room`).
    lam : float
        Contraction factor of the tube LMI (24).
    moves : int
        Fast steps between the nominal's altitude resets (M of ``mpc``).
    grow : float
        W_8 <- max(W_8, grow x bound) between iterations.
    iterations : int
    w_ref : (9,) array_like, optional
        Reference size of W for the LMI's scaling (:func:`fahv.synthesis.feedback.design_tube`);
        its eight entries after h are used.
    active : int
        Vertex blocks per round of constraint generation.
    state_max : (8,) array_like, optional
        Largest supports of Z_8 along e_8's axes (V, alpha, theta, ...; unscaled, inf: no
        bound), e.g. 0.5 deg less the box's trim offset in alpha and theta, so that the
        attitude requirement follows from the pair (docs/control_design.md, "Attitude by
        construction"); passed to :func:`fahv.synthesis.feedback.design_tube`.
    contain : (S, 8) array_like, optional
        Errors Z_8 must contain (``contain`` of :func:`fahv.synthesis.feedback.design_tube`),
        e.g. the onset's jumps over the level they may use.
    log : callable
        Receives one line per iteration.

    Returns
    -------
    EightStatePair
        Closed: bound <= W8 in every row, the box holds nominal + product set, exact
        one-step level <= 1.

    Raises
    ------
    DesignError
        If the tube LMI is infeasible, the tube outgrows the scheduling box (names the
        coordinates), the exact level exceeds 1, or the iterations run out (gives the
        last bound / W_8).
    """
    A, B = nv.vertices()
    A8, B8 = A[:, 1:, 1:], B[:, 1:, :]
    W8 = np.asarray(W8, float).copy()
    w_ref8 = None if w_ref is None else np.asarray(w_ref, float)[1:]
    ratio = np.full(8, np.inf)
    for it in range(iterations):
        tube = design_tube(A8, B8, W8, np.asarray(state_scale, float)[1:], input_scale, room,
                           (lam,), state_max=state_max, w_ref=w_ref8, active=active,
                           contain=contain)  # fmt: skip
        F8, N8 = tube.F, tube.N
        ab = altitude_bound(nv, A, B, F8, N8, moves)
        ratio = ab.bound / W8
        short = box_shortfall(nv.box, nominal, F8, N8, ab.H)
        log(
            f"eight-state tube, iteration {it}: tightening {tube.tightening[0]:.4f} / "
            f"{np.degrees(tube.tightening[1]):.3f} deg, alpha support "
            f"{np.degrees(np.sqrt(N8[1, 1])):.4f} deg, H = {ab.H:.2f} ft (step {ab.step:.3f} "
            f"ft, w_h {ab.w_h:.3f} ft); bound / W_8 (V ... eta_2_dot) "
            + " ".join(f"{r:.3f}" for r in ratio)
        )
        if short:
            raise DesignError(
                "eight-state tube: the scheduling box does not hold the nominal box grown by "
                "the tube (short by "
                + ", ".join(f"{n} {v:.3g}" for n, v in short.items())
                + "); grow the box or shrink the nominal's ranges"
            )
        if np.all(ratio <= 1.0):
            level, _ = worst_level(A8, B8, F8, N8, W8)
            if level > 1.0:
                raise DesignError(
                    f"eight-state tube: bound inside W_8 but the exact worst one-step level "
                    f"is {level:.6f} > 1 over {A8.shape[0]} vertices"
                )
            return EightStatePair(F8, N8, W8, ab.H, float(tube.lam), ab.bound, float(level),
                                  int(moves), ab.step, ab.w_h)  # fmt: skip
        W8 = np.maximum(W8, grow * ab.bound)
    raise DesignError(
        f"eight-state tube: not closed in {iterations} iterations (bound / W_8 "
        + " ".join(f"{r:.3f}" for r in ratio)
        + ")"
    )


def nominal_box(section: dict, envelope) -> tuple[SchedulingBox, SchedulingBox]:
    """The nominal box and the scheduling box of a case's ``eight_state`` section.

    Parameters
    ----------
    section : dict
        The validated ``eight_state`` section (:mod:`fahv.design.case`).
    envelope : fahv.model.vehicle.Envelope
        The flight envelope (h, V ranges).

    Returns
    -------
    nominal, box : SchedulingBox
        The nominal's ranges (h, V: the envelope shrunk by the margins; attitude, input
        deviations from the trim and q, flexible half-widths as given) and the scheduling
        box: the envelope in h, V, the nominal ranges grown by ``reach`` elsewhere.

    Raises
    ------
    DesignError
        If the margins leave no nominal h or V range inside the envelope.
    """
    deg = np.pi / 180.0
    att = section["attitude"] * deg
    hm, Vm = section["h_margin"], section["V_margin"]
    if hm >= 0.5 * (envelope.h_max - envelope.h_min) or Vm >= 0.5 * (
        envelope.V_max - envelope.V_min
    ):
        raise DesignError(
            f"eight_state.h_margin {hm} / V_margin {Vm} leave no nominal range in the envelope"
        )
    lo = np.array([envelope.h_min + hm, envelope.V_min + Vm, -att, -att,
                   section["Phi"][0], section["delta_e"][0] * deg])  # fmt: skip
    hi = np.array([envelope.h_max - hm, envelope.V_max - Vm, att, att,
                   section["Phi"][1], section["delta_e"][1] * deg])  # fmt: skip
    other = np.asarray(section["other"], float) * np.r_[deg, np.ones(4)]
    nominal = SchedulingBox(lo, hi, other)
    r = np.asarray(section["reach"], float) * np.r_[deg, deg, 1.0, deg, deg, np.ones(4)]
    box = SchedulingBox(
        np.r_[envelope.h_min, envelope.V_min, lo[2:] - r[:4]],
        np.r_[envelope.h_max, envelope.V_max, hi[2:] + r[:4]],
        other + r[4:],
    )
    return nominal, box


def design_pair(
    case: dict,
    vehicle,
    trim_map,
    scale,
    w_max,
    col_scale,
    rho_min: float,
    room,
    log: Callable[[str], None] = print,
    gamma: float | None = None,
    notches=None,
    stable_only=None,
    **estimate,
) -> tuple[EightStatePair, SchedulingBox, SchedulingBox]:
    """The eight-state tube of a case (``tube.form: eight_state``), closed and checked.

    Parameters
    ----------
    case : dict
        Validated case data (its ``eight_state``, ``uncertainty``, ``mpc.M``,
        ``mpc.att_max``, ``Ts``, ``plant_substeps``).
    vehicle : fahv.model.vehicle.Vehicle
        The nominal vehicle.
    trim_map : fahv.model.trim.TrimMap
    scale : (11,) array_like
        Design scaling (Dx, Du).
    w_max : (9,) array_like
        The sampled W (eq. 19): the row scale of the parameter directions and the unit of
        ``eight_state.w0``.
    col_scale : (11,) array_like
        Supports of e and F e over the vertex tube: the column scale of the directions.
    rho_min : float
        Smallest elevator effectiveness (eq. 15) the vertices cover.
    room : (2,) array_like
        Input room of each row with the faulty trim (the tube objective's weights).
    log : callable
    gamma : float, optional
        The case's estimator gain per step: the onset of the design loss is then bounded
        as a transient of the pair (:func:`onset_bound`, ``pair.onset``).
    notches : dict, optional
        ``{variant: NotchFilter}``: the tube variants that feed q through a notch; their
        loops are certified in their own states at the pair's vertices
        (:func:`fahv.design.certificate.notch_tube`, a few minutes each;
        ``pair.notch_loops``).
    stable_only : dict, optional
        ``{variant: NotchFilter}``: notch variants whose error filters the measured q
        alone; their loops with F_8 are checked for stability only
        (:func:`fahv.design.certificate.notch_loop`, also in ``pair.notch_loops``).
    **estimate
        ``gamma_e``, ``directions``, ``projection_scale`` of :func:`onset_bound` (the
        estimate's gain along the elevator column).

    Returns
    -------
    pair : EightStatePair
    nominal, box : SchedulingBox
        The nominal box and the scheduling box the pair is closed over.

    Raises
    ------
    DesignError
        If the boxes are malformed, a plant step leaves the model, or the pair does not
        close (:func:`close_pair`).
    """
    s = case["eight_state"]
    nominal, box = nominal_box(s, vehicle.envelope)
    unc = {k: v * case["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    nv = nominal_vertices(box, vehicle, trim_map, unc, rho_min, case["Ts"],
                          case["plant_substeps"], scale, s["k"], w_max, col_scale,
                          hessians=False)  # fmt: skip
    tau = float(case["tube"]["tau"])
    if tau < 1.0:  # the adjustable law's gains tau' F, tau' in [tau, 1] (eq. 48)
        nv = replace(nv, tau=tau)
    log(f"eight-state tube: {nv.n_vertices} vertices along the nominal (64 scheduling-box "
        f"corners x 2^{s['k']} parameter directions x rho_f in {{{rho_min:g}, 1}}"
        + (f" x the gains tau' F_8 at tau' = {tau:g} and 1 (eq. 48)" if tau < 1.0 else "")
        + f"), {sum(nv.n_vehicles)} vehicles for the residual")  # fmt: skip
    scale = np.asarray(scale, float)
    w_max = np.asarray(w_max, float)
    state_max = None
    if s["certify_attitude"]:  # supports in alpha, theta: the requirement less the rows
        state_max = np.full(8, np.inf)
        state_max[1:3] = np.radians(ATTITUDE_BOUND_DEG - case["mpc"]["att_max"])
        log(f"eight-state tube: supports in alpha and theta bounded to "
            f"{ATTITUDE_BOUND_DEG - case['mpc']['att_max']:.3f} deg (requirement "
            f"{ATTITUDE_BOUND_DEG} deg less the QP's rows mpc.att_max)")  # fmt: skip
    contain = None
    if s["onset_in_tube"] > 0.0:  # the onset's first jumps J / rho_f in kappa Z_8 (item 3)
        J, _ = onset_jumps(box, vehicle, trim_map, unc, rho_min, case["Ts"],
                           case["plant_substeps"], interior=1024)  # fmt: skip
        contain = J[:, 1:] / rho_min / s["onset_in_tube"]
        log(f"eight-state tube: the first jumps of a {100 * (1 - rho_min):.1f} % loss at "
            f"{len(J)} box points held in {s['onset_in_tube']:g} Z_8 (eight_state."
            f"onset_in_tube)")  # fmt: skip
    pair = close_pair(nv, nominal, s["w0"] * w_max[1:], scale[:9], scale[9:], room, s["lam"],
                      case["mpc"]["M"], grow=s["grow"], iterations=s["iterations"],
                      w_ref=w_max, state_max=state_max, contain=contain,
                      log=log)  # fmt: skip
    if gamma is not None:
        lams = tuple(dict.fromkeys((pair.lam, *STEADY_LAMS)))
        onset = onset_bound(nv, pair, vehicle, trim_map, unc, gamma, case["Ts"],
                            case["plant_substeps"], steady_lams=lams, **estimate)  # fmt: skip
        pair = replace(pair, onset=onset)
    if notches or stable_only:
        A, B = nv.vertices()
        A8, B8, iq = A[:, 1:, 1:], B[:, 1:, :], EIGHT_STATES.index("q")
        loops = tuple(notch_loop(A8, B8, pair.F8, nf, case["Ts"], iq, v)
                      for v, nf in (stable_only or {}).items())  # fmt: skip
        gains = {}
        for v, nf in (notches or {}).items():
            loop = notch_tube(A8, B8, pair.F8, pair.N8, pair.W8, nf, case["Ts"], iq, pair.lam, v)
            if s["notch_gain"] == "designed" and not loop.certified:
                log(f"{loop.line()}; a gain is designed for this loop (eight_state.notch_gain)")
                got = designed_notch_loop(
                    nv, A, B, pair, nf, case["Ts"], v, s["notch_continuation"], log
                )
                if got is not None:
                    loop, gains[v] = got
            loops += (loop,)
        pair = replace(pair, notch_loops=loops, notch_gains=gains)
    return pair, nominal, box


def designed_notch_loop(
    nv: NominalVertices,
    A,
    B,
    pair: EightStatePair,
    notch,
    Ts: float,
    variant: str,
    continuation=(),
    log: Callable[[str], None] = print,
):
    """A gain designed for the pair's loop through the notch, closed on W_8 (or None).

    The loop u - v = F e' through the notch (:func:`fahv.design.certificate.notch_gain`,
    from F_8, with the pair's Z_8 and tightening) keeps e_8 in Z_8 and the applied input
    within the tightening, but its input deviation is K xi, not F_8 e_8: W_8's bound over
    the product set is therefore recomputed for the loop's own joint set of (e_8, u - v)
    (:func:`altitude_bound` with ``joint``); the loop is closed if its altitude bound is
    at most the pair's H (the scheduling box holds that) and its bound lies inside W_8
    (``NotchLoop.w_ratio`` = (H / the pair's H, bound / W_8), every entry <= 1).

    Parameters
    ----------
    nv : NominalVertices
    A, B : (R, 9, 9), (R, 9, 2) ndarray
        The pair's vertices (``nv.vertices()``).
    pair : EightStatePair
    notch : fahv.model.notch.NotchFilter
    Ts : float
        Control period [s].
    variant : str
    continuation : sequence of float
        ``eight_state.notch_continuation``.
    log : callable

    Returns
    -------
    (NotchLoop, (2, 8) ndarray) or None
        The certified loop's re-check (``designed``, ``w_ratio``) and its gain; None if no
        gain was certified and closed at the case's eps_p (the variant keeps F_8).

    Raises
    ------
    DesignError
        As :func:`fahv.design.certificate.notch_gain`.
    """
    iq = EIGHT_STATES.index("q")
    got = notch_gain(A[:, 1:, 1:], B[:, 1:, :], pair.F8, pair.N8, pair.W8, notch, Ts, iq,
                     pair.lam, continuation, variant=variant, log=log)  # fmt: skip
    if got is None:
        return None
    ab = altitude_bound(nv, A, B, pair.F8, pair.N8, pair.moves, joint=got.joint(notch, Ts, iq))
    # h first: the scheduling box was checked to hold |e_h| <= H, the loop's H must not exceed it
    loop = replace(got.loop, w_ratio=tuple([ab.H / pair.H, *(ab.bound / pair.W8).tolist()]))
    log(f"variant {variant}: the designed gain's loop: H {ab.H:.3f} ft (the pair's "
        f"{pair.H:.3f} ft), W_8's bound over its own set / W_8 "
        + " ".join(f"{v:.3f}" for v in loop.w_ratio[1:])
        + "; the onset lines are F_8's loop's, none is computed for this gain")  # fmt: skip
    if not loop.certified:  # the variant keeps F_8 (and its own loop's verdict)
        log(f"{loop.line()}; the variant runs F_8")
        return None
    return loop, got.F


def pair_report(pair: EightStatePair, nominal: SchedulingBox, box: SchedulingBox) -> list[str]:
    """The certificate lines of a closed pair, each with its margin (for the design log)."""
    s_lo, s_oth = product_supports(pair.F8, pair.N8, pair.H)
    lo, hi, oth = box.margin_to(nominal)
    room = np.r_[np.minimum(lo, hi)[1:] / s_lo[1:], oth / s_oth]
    names = [*BOX_COORDINATES[1:], "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot"]
    worst = int(np.argmin(room))
    sz = np.sqrt(np.diag(pair.N8))
    return [
        "W_8 bounds the one-step disturbance over its domain (the nominal box, the product "
        "set |e_h| <= H x Z_8, every corner of the parameter box, rho_f in [rho_min, 1]): "
        "slack per row (V ... eta_2_dot) "
        + " ".join(f"{v:.3f}" for v in pair.slack)
        + f", smallest {pair.slack.min():.3f}  OK",
        f"closed: Z_8 RPI for W_8, exact worst one-step level {pair.level:.6f} <= 1 (margin "
        f"{1.0 - pair.level:.2e}), lam = {pair.lam}  OK",
        f"altitude: |e_h| <= H = {pair.H:.3f} ft by the reset every {pair.moves} steps (step "
        f"{pair.step:.4f} ft, w_h {pair.w_h:.4f} ft)",
        f"scheduling box holds the nominal box plus the tube: smallest reach "
        f"{room[worst]:.2f} x the tube's support ({names[worst]})  OK",
        *range_lines(certified_range(box, pair.F8, pair.N8, pair.H), nominal),
        f"Z_8 supports: V {sz[0]:.3f} ft/s, alpha {np.degrees(sz[1]):.4f} deg, theta "
        f"{np.degrees(sz[2]):.4f} deg, q {np.degrees(sz[3]):.4f} deg/s; tightening "
        f"{pair.tightening[0]:.4f} / {np.degrees(pair.tightening[1]):.3f} deg",
        "assumed, not certified: " + "; ".join(ASSUMPTIONS),
        *([] if pair.onset is None else pair.onset.lines()),
        *(loop.line() for loop in pair.notch_loops),
    ]


def range_lines(cert: SchedulingBox, nominal: SchedulingBox) -> list[str]:
    """The design log's line of the certified nominal range (:func:`certified_range`)."""
    deg = np.degrees
    o = cert.other_half
    return [
        f"the certificate covers a nominal anywhere in the scheduling box less the tube: h "
        f"{cert.lo[0]:.0f}..{cert.hi[0]:.0f} ft, V {cert.lo[1]:.2f}..{cert.hi[1]:.2f} ft/s, "
        f"alpha {deg(cert.lo[2]):+.3f}..{deg(cert.hi[2]):+.3f} deg and theta "
        f"{deg(cert.lo[3]):+.3f}..{deg(cert.hi[3]):+.3f} deg from the trim at its own (h, V), "
        f"applied Phi {cert.lo[4]:+.4f}..{cert.hi[4]:+.4f} and delta_e "
        f"{deg(cert.lo[5]):+.3f}..{deg(cert.hi[5]):+.3f} deg from the trim's, |q| <= "
        f"{deg(o[0]):.3f} deg/s, |eta_1|, |eta_1_dot|, |eta_2|, |eta_2_dot| <= {o[1]:.3f}, "
        f"{o[2]:.3f}, {o[3]:.3f}, {o[4]:.3f} from the trim's (the case's nominal box, "
        f"e.g. alpha +/-{deg(nominal.hi[2]):.3f} deg, is the part the QP's rows keep)"
    ]


def input_rows(trim_offsets, nominal: SchedulingBox) -> np.ndarray:
    """Rows of the QP on the manoeuvre part of the nominal input (``mpc.u_box``).

    The nominal box bounds the input the plant applies minus the nominal vehicle's trim
    (where the vertices' Jacobians are taken). At steady state the plant applies its own
    trim whatever its loss or bias (eq. 15), so what is left of the box after every box
    corner's trim offset is the room of the manoeuvre part K zeta + c; a loss only scales
    the applied part towards 0.

    Parameters
    ----------
    trim_offsets : tuple of (2,) ndarray
        (lo, hi) of the corners' trim inputs minus the nominal trim [Phi -, delta_e rad]
        (:meth:`fahv.design.feasibility.BoxCoverage.trim_offsets`).
    nominal : SchedulingBox
        The nominal box (its Phi and delta_e coordinates).

    Returns
    -------
    (2, 2) ndarray
        [[Phi lo, delta_e lo], [Phi hi, delta_e hi]] [-, rad], lo < 0 < hi.

    Raises
    ------
    DesignError
        If the box leaves no room on a side (names the offsets).
    """
    off_lo, off_hi = (np.asarray(v, float) for v in trim_offsets)
    room = np.array([nominal.lo[4:6] - off_lo, nominal.hi[4:6] - off_hi])
    if np.any(room[0] >= 0.0) or np.any(room[1] <= 0.0):
        raise DesignError(
            "eight_state.Phi / delta_e: the nominal box does not hold the trim input of "
            f"every box corner with room to manoeuvre (trims at Phi {off_lo[0]:+.4f}.."
            f"{off_hi[0]:+.4f}, delta_e {np.degrees(off_lo[1]):+.3f}.."
            f"{np.degrees(off_hi[1]):+.3f} deg from the nominal trim): widen the box"
        )
    return room


def state_rows(cert: SchedulingBox) -> np.ndarray:
    """Rows of the QP on the nominal's states besides h, V and the inputs (``mpc.x_box``).

    The certificate covers a nominal inside the certified range (:func:`certified_range`):
    its alpha and theta between the range's bounds and q and the bending modes within its
    half-widths, all from the nominal vehicle's trim at the nominal's own (h, V). The QP
    keeps its prediction there (:class:`fahv.control.nominal_mpc.MPCSettings`, ``x_box``),
    so the assumption holds by construction instead of being measured per run.

    Parameters
    ----------
    cert : SchedulingBox
        The certified range.

    Returns
    -------
    (2, 7) ndarray
        [lo, hi] of alpha, theta [rad], q [rad/s], eta_1, eta_1_dot [1/s], eta_2,
        eta_2_dot [1/s].

    Raises
    ------
    DesignError
        If the range does not hold the trim (lo < 0 < hi fails for a state).
    """
    box = np.array([np.r_[cert.lo[2:4], -cert.other_half], np.r_[cert.hi[2:4], cert.other_half]])
    if not (np.all(box[0] < 0.0) and np.all(box[1] > 0.0)):
        raise DesignError(
            f"certified range: it does not hold the trim in every state (lo {box[0].tolist()}, "
            f"hi {box[1].tolist()}): the tube fills the scheduling box"
        )
    return box
