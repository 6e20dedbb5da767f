"""Compiled RK4 of the coupling model CM, eq. (1)-(3), over a batch of vehicles (numba).

The plant is the only loop computation whose cost is dominated by numpy's per-call
overhead: 20 evaluations of `fahv.model.dynamics.cm_rhs` per control step, each
some 60 small array operations. Here the very functions of
`fahv.model.dynamics` (no second copy of the model) are compiled with numba
(`register_jitable`) and integrated lane by lane in one compiled loop.

Numerics
    Every lane is integrated with the same scalar operations in the same order, so a
    run's result does not depend on its batch or its place in it. Compiled without
    fast-math (no reassociation, no fused multiply-add) and without Intel SVML (set
    off below before numba is imported), the arithmetic is IEEE 754 double as in
    numpy; sin and cos give numpy's bits, but `exp` (air density, eq. 3) is the C
    library's, which differs from numpy's vectorised exp on AVX-512 machines by at
    most one unit in the last place in about 5 % of arguments. That is the whole
    difference between this kernel and the numpy model (docs/reference/architecture.md states
    the resulting tolerance on closed-loop results).

Cache
    Compiled code is cached on disk (`cache=True`) in a folder named after the
    sha256 of this file, of `fahv.model.dynamics` and of the numba version, so a
    change of the model's source always recompiles (numba's own cache would only
    watch this file).
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path

os.environ.setdefault("NUMBA_DISABLE_INTEL_SVML", "1")

import numba  # noqa: E402  (after the SVML switch)
import numpy as np  # noqa: E402
from numba.extending import register_jitable  # noqa: E402

from fahv.model import dynamics  # noqa: E402
from fahv.model.vehicle import VehicleParams  # noqa: E402


def _cache_dir() -> Path:
    src = b"".join(Path(m.__file__).read_bytes() for m in (dynamics,)) + Path(__file__).read_bytes()
    key = hashlib.sha256(src + numba.__version__.encode()).hexdigest()[:16]
    base = os.environ.get("NUMBA_CACHE_DIR") or os.environ.get("XDG_CACHE_HOME")
    base = Path(base) if base else Path.home() / ".cache"
    return base / "fahv" / f"numba-{key}"


numba.config.CACHE_DIR = str(_cache_dir())

#: The model functions the kernel calls, compiled from their own source.
for _f in dynamics.JITABLE:
    register_jitable(_f)

#: Record layout of one vehicle's parameters (fields of VehicleParams, float64).
PARAMS_DTYPE = np.dtype([(f, np.float64) for f in VehicleParams.__dataclass_fields__])


def params_records(params) -> np.ndarray:
    """Structured array (B,) of `PARAMS_DTYPE` from B VehicleParams.

    Raises
    ------
    ValueError
        If a parameter is not a finite number.
    """
    rows = [tuple(float(getattr(p, f)) for f in PARAMS_DTYPE.names) for p in params]
    rec = np.array(rows, dtype=PARAMS_DTYPE)
    for f in PARAMS_DTYPE.names:
        if not np.all(np.isfinite(rec[f])):
            raise ValueError(f"vehicle parameter '{f}' must be finite")
    return rec


def perturbed_records(params: VehicleParams, uncertainty: dict, signs) -> np.ndarray:
    """Records (B,) of B vehicles of the parameter box: p (1 + s_bp rel_p) (sec. 5.1).

    The vectorised form of `fahv.plant.uncertainty.perturb` over many vehicles,
    with the same arithmetic (the same bits).

    Parameters
    ----------
    params : VehicleParams
        The nominal vehicle's parameters.
    uncertainty : dict[str, float]
        Relative half-widths rel_p of the box, by parameter name (P entries).
    signs : (B, P) array_like
        Fractions s_bp in [-1, 1], columns in the order of `uncertainty`.

    Returns
    -------
    (B,) ndarray of PARAMS_DTYPE

    Raises
    ------
    ValueError
        If a name is not a parameter, `signs` is not (B, P), or a fraction is NaN or
        outside [-1, 1].
    """
    names = list(uncertainty)
    signs = np.asarray(signs, float)
    if signs.ndim != 2 or signs.shape[1] != len(names):
        raise ValueError(f"uncertainty: signs must be (B, {len(names)}), got {signs.shape}")
    if not np.all(np.abs(signs) <= 1.0):
        raise ValueError("uncertainty: every sign/fraction must be in [-1, 1] (NaN refused)")
    out = np.repeat(params_records([params]), len(signs))
    for j, name in enumerate(names):
        if name not in PARAMS_DTYPE.names:
            raise ValueError(f"uncertainty: unknown parameter '{name}'")
        out[name] = out[name] * (1.0 + signs[:, j] * float(uncertainty[name]))
    return out


@numba.njit(cache=True)
def rk4_cm(X, U, P, Ts, n_sub):  # pragma: no cover - compiled
    """Integrate the CM over Ts for B vehicles, inputs held (ZOH), n_sub RK4 steps each.

    Parameters
    ----------
    X : (B, 9) float64 ndarray
        States [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s].
    U : (B, 2) float64 ndarray
        Inputs [Phi, delta_e rad] (already saturated).
    P : (B,) ndarray of PARAMS_DTYPE
        Parameters of each vehicle.
    Ts : float
        Interval [s].
    n_sub : int
        RK4 steps per interval (dt = Ts / n_sub).

    Returns
    -------
    (B, 9) float64 ndarray
        States at the end of the interval (a new array).
    """
    B = X.shape[0]
    out = np.empty_like(X)
    dt = Ts / n_sub
    xs = np.empty(9)  # the stages' states, written in place (no array per stage)
    for b in range(B):
        vp = P[b]
        u = U[b]
        x = X[b].copy()
        for _ in range(n_sub):
            k1 = dynamics.cm_rhs(x, u, vp)
            _stage(x, 0.5 * dt, k1, xs)
            k2 = dynamics.cm_rhs(xs, u, vp)
            _stage(x, 0.5 * dt, k2, xs)
            k3 = dynamics.cm_rhs(xs, u, vp)
            _stage(x, dt, k3, xs)
            k4 = dynamics.cm_rhs(xs, u, vp)
            _rk4_sum(x, dt / 6.0, k1, k2, k3, k4)
        out[b] = x
    return out


@numba.njit(cache=True)
def _stage(x, c, k, out):  # pragma: no cover - compiled
    """Write x + c k into `out`, element by element (numpy's `x + c * k`, the same bits)."""
    for i in range(x.size):
        out[i] = x[i] + c * k[i]


@numba.njit(cache=True)
def _rk4_sum(x, c, k1, k2, k3, k4):  # pragma: no cover - compiled
    """Add c (k1 + 2 k2 + 2 k3 + k4) to x in place, in numpy's order of operations."""
    for i in range(x.size):
        x[i] = x[i] + c * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i])


@numba.njit(cache=True)
def _servo_rhs(a, uc, AP, held):  # pragma: no cover - compiled
    """Rates of the actuator states a (4,) [Phi, Phi_dot, delta_e, delta_e_dot]."""
    ad = np.empty(4)
    for j in range(2):
        zeta, wn = AP[j, 0], AP[j, 1]
        ad[2 * j] = a[2 * j + 1]
        ad[2 * j + 1] = wn * wn * (uc[j] - a[2 * j]) - 2.0 * zeta * wn * a[2 * j + 1]
    if held:
        ad[2] = 0.0
        ad[3] = 0.0
    return ad


@numba.njit(cache=True)
def _position(a, AP):  # pragma: no cover - compiled
    """Positions (2,) [Phi, delta_e rad] the airframe sees: a's, clipped to the limits."""
    u = np.empty(2)
    for j in range(2):
        u[j] = min(max(a[2 * j], AP[j, 4]), AP[j, 5])
    return u


@numba.njit(cache=True)
def _limit(a, a_prev, AP, dt):  # pragma: no cover - compiled
    """The limits after one RK4 step, in place (JSBSim's rate limit and clipto, no wind-up)."""
    for j in range(2):
        incr, decr, lo, hi = AP[j, 2], AP[j, 3], AP[j, 4], AP[j, 5]
        r = min(max(a[2 * j + 1], -decr), incr)
        p = min(max(a[2 * j], a_prev[2 * j] - decr * dt), a_prev[2 * j] + incr * dt)
        p = min(max(p, lo), hi)
        if (p >= hi and r > 0.0) or (p <= lo and r < 0.0):
            r = 0.0
        a[2 * j], a[2 * j + 1] = p, r


@numba.njit(cache=True)
def rk4_cm_act(X, A, U, P, AP, held, Ts, n_sub):  # pragma: no cover - compiled
    """Integrate the CM with second-order actuators over Ts for B vehicles (ZOH commands).

    The 9 airframe states and the 4 actuator states are one RK4 state; the airframe
    sees the actuator positions clipped to their limits. After each RK4 step of
    dt = Ts / n_sub, per actuator (JSBSim `FGActuator`: rate limit, then clipto):

    1. rate state r <- clip(r, -rate_limit_decr, rate_limit_incr);
    2. position p <- clip(p, p_prev - rate_limit_decr dt, p_prev + rate_limit_incr dt),
       p_prev the position before the step (the rate limit on the position itself);
    3. p <- clip(p, min, max) (clipto);
    4. no wind-up: r <- 0 if p is at a limit and r points beyond it.

    Parameters
    ----------
    X : (B, 9) float64 ndarray
        Airframe states [ft, ft/s, rad, rad, rad/s, -, 1/s, -, 1/s].
    A : (B, 4) float64 ndarray
        Actuator states [Phi, Phi_dot 1/s, delta_e rad, delta_e_dot rad/s].
    U : (B, 2) float64 ndarray
        Commands [Phi, delta_e rad] (already saturated).
    P : (B,) ndarray of PARAMS_DTYPE
        Parameters of each vehicle.
    AP : (B, 2, 6) float64 ndarray
        Servos of each vehicle, of Phi and of delta_e: [zeta, omega_n rad/s,
        rate_limit_incr, rate_limit_decr (input unit/s, inf: none), min, max]
        (`fahv.model.actuators.kernel_parameters`; a campaign disperses them per run).
    held : (B,) bool ndarray
        The elevator actuator is held (fault `stuck`): its position and rate frozen.
    Ts : float
        Interval [s].
    n_sub : int
        RK4 steps per interval (dt = Ts / n_sub).

    Returns
    -------
    tuple of ndarray
        Airframe states (B, 9) and actuator states (B, 4) at the end of the interval,
        and each servo's peak |rate| within it (B, 2) [input unit/s]: the largest |rate
        state| after the limits of any of the n_sub RK4 steps (what a servo's rate
        limit bounds; the step-to-step difference of its position is an average).
    """
    B = X.shape[0]
    out = np.empty_like(X)
    out_a = np.empty_like(A)
    peak = np.zeros((B, 2))
    dt = Ts / n_sub
    xs = np.empty(9)  # the stages' airframe states, written in place
    for b in range(B):
        vp = P[b]
        uc = U[b]
        h = held[b]
        ap = AP[b]
        x = X[b].copy()
        a = A[b].copy()
        if h:
            a[3] = 0.0
        for _ in range(n_sub):
            k1 = dynamics.cm_rhs(x, _position(a, ap), vp)
            j1 = _servo_rhs(a, uc, ap, h)
            a2 = a + 0.5 * dt * j1
            _stage(x, 0.5 * dt, k1, xs)
            k2 = dynamics.cm_rhs(xs, _position(a2, ap), vp)
            j2 = _servo_rhs(a2, uc, ap, h)
            a3 = a + 0.5 * dt * j2
            _stage(x, 0.5 * dt, k2, xs)
            k3 = dynamics.cm_rhs(xs, _position(a3, ap), vp)
            j3 = _servo_rhs(a3, uc, ap, h)
            a4 = a + dt * j3
            _stage(x, dt, k3, xs)
            k4 = dynamics.cm_rhs(xs, _position(a4, ap), vp)
            j4 = _servo_rhs(a4, uc, ap, h)
            _rk4_sum(x, dt / 6.0, k1, k2, k3, k4)
            a_prev = a
            a = a + dt / 6.0 * (j1 + 2.0 * j2 + 2.0 * j3 + j4)
            _limit(a, a_prev, ap, dt)
            for j in range(2):
                peak[b, j] = max(peak[b, j], abs(a[2 * j + 1]))
        out[b] = x
        out_a[b] = a
    return out, out_a, peak


def compile_kernels(P: np.ndarray, servos: np.ndarray | None = None) -> None:
    """Compile `rk4_cm` (and `rk4_cm_act` with `servos`) now, or load them from disk.

    Numba compiles a kernel at its first call; in a loop node that call would fall in a
    step its peers' watchdogs time (a cold compile takes seconds: on a fresh clone with
    three graphs starting at once it outlasted the 10 s watchdog). Every object that
    integrates with these kernels (the plant, the nominal CM, the Kalman filter's
    predictor) calls this when it is built. One zero-length step of one vehicle, with
    the argument types every later call passes (C-contiguous float64 states and inputs,
    records of `PARAMS_DTYPE`, a float Ts and an int n_sub), so no step adds a
    specialisation. Changes nothing.

    Parameters
    ----------
    P : (B,) ndarray of PARAMS_DTYPE
        Parameter records (the first one is used).
    servos : (2, 6) or (B, 2, 6) ndarray, optional
        Servo data of `rk4_cm_act` (`fahv.model.actuators.kernel_parameters`; the
        first vehicle's is used).
    """
    X, U, P1 = np.ones((1, 9)), np.zeros((1, 2)), np.ascontiguousarray(P[:1])
    rk4_cm(X, U, P1, 0.0, 1)
    if servos is not None:
        AP = np.ascontiguousarray(np.reshape(servos, (-1, 2, 6))[:1], dtype=np.float64)
        rk4_cm_act(X, np.zeros((1, 4)), U, P1, AP, np.zeros(1, bool), 0.0, 1)


def servo_lanes(servos: np.ndarray, n_runs: int) -> np.ndarray:
    """Servo data (2, 6) repeated for `n_runs` vehicles: the (B, 2, 6) of `rk4_cm_act`.

    Raises
    ------
    ValueError
        If `servos` is not of shape (2, 6) or (n_runs, 2, 6).
    """
    AP = np.asarray(servos, dtype=np.float64)
    if AP.shape not in ((2, 6), (n_runs, 2, 6)):
        raise ValueError(f"servo data of shape {AP.shape}, expected (2, 6) or ({n_runs}, 2, 6)")
    return np.ascontiguousarray(np.broadcast_to(AP, (n_runs, 2, 6)))
