"""Trim (equilibrium) of the longitudinal models over the flight envelope.

For level flight at (h, V): gamma = theta - alpha = 0, q = 0, eta_dot = 0 and
x_dot = 0 (sec. 3.1, "let x_s_dot = l_i(x_s, u_s) = 0"). The rigid rows give three
equations (V_dot = alpha_dot = q_dot = 0) in (alpha, delta_e, Phi); the flexible rows
then give eta_i = N_i / omega_i^2. In the paper's CM the flexible states do not enter
L, D, T, M, and at rest eta_ddot = 0, so CM and DM have the same trim (M = 0).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from fahv.errors import TrimError
from fahv.model.blas import one_blas_thread
from fahv.model.dynamics import dm_rhs, forces, make_model
from fahv.model.jacobian import jacobian_complex_step
from fahv.model.vehicle import ALPHA, IQ, Vehicle, VehicleParams
from fahv.model.vehicle import V as IV

#: Residual tolerance of a trim, in scaled units (state derivative / state scale).
TRIM_TOL = 1e-8


@dataclass(frozen=True)
class TrimPoint:
    """Equilibrium of eq. (5) at (h, V).

    Attributes
    ----------
    h, V : float
        Altitude [ft] and speed [ft/s].
    alpha, delta_e : float
        Angle of attack and elevator [rad] (theta = alpha, q = 0).
    Phi : float
        Fuel-to-air ratio [-].
    eta_1, eta_2 : float
        Flexible coordinates at rest (eta_dot = 0).
    residual : float
        max |f(x_r, u_r)_i / scale_i| over all states of the model trimmed.

    Examples
    --------
    >>> tp = TrimPoint(85500.0, 7900.0, 0.03, 0.2, 0.3, 1.9, 0.9, 0.0)
    >>> tp.x_r.tolist()  # theta = alpha, q = 0, eta_dot = 0
    [85500.0, 7900.0, 0.03, 0.03, 0.0, 1.9, 0.0, 0.9, 0.0]
    >>> tp.u_r.tolist(), tp.x_r_ecm.shape
    ([0.3, 0.2], (11,))
    """

    h: float
    V: float
    alpha: float
    delta_e: float
    Phi: float
    eta_1: float
    eta_2: float
    residual: float

    @property
    def x_r(self) -> np.ndarray:
        """Trim state of CM/DM, shape (9,), eq. (5)."""
        return np.array(
            [self.h, self.V, self.alpha, self.alpha, 0.0, self.eta_1, 0.0, self.eta_2, 0.0]
        )

    @property
    def x_r_ecm(self) -> np.ndarray:
        """Trim state of ECM, shape (11,), eq. (41): q' = 0, x_q = 0."""
        return np.concatenate([self.x_r, [0.0, 0.0]])

    @property
    def u_r(self) -> np.ndarray:
        """Trim input [Phi, delta_e rad], shape (2,), eq. (5)."""
        return np.array([self.Phi, self.delta_e])


def _rigid_residual(z, h, V, vp: VehicleParams, zs):
    alpha, de, Phi = z * zs
    x = np.array([h, V, alpha, alpha, 0.0, 0.0, 0.0, 0.0, 0.0], dtype=np.result_type(z, float))
    f = dm_rhs(x, np.array([Phi, de]), vp)
    # rows V_dot [ft/s^2], alpha_dot [rad/s], q_dot [rad/s^2] scaled to ~1 for 1 deg
    return np.array([f[IV] / 10.0, f[ALPHA] / 0.0174533, f[IQ] / 0.0174533])


def trim(
    vehicle: Vehicle,
    h: float,
    V: float,
    model: str = "dm",
    guess: tuple[float, float, float] | None = None,
    notch=None,
) -> TrimPoint:
    """Trim the model at (h, V) for level flight.

    Parameters
    ----------
    vehicle : Vehicle
    h : float
        Altitude [ft], inside `vehicle.envelope`.
    V : float
        Speed [ft/s], inside `vehicle.envelope`.
    model : {"dm", "cm", "ecm"}
        Model whose full residual is checked (the equilibrium is the same).
    guess : (alpha rad, delta_e rad, Phi), optional
        Starting point of the Newton iteration.
    notch : NotchFilter, optional
        Needed for `model="ecm"`.

    Returns
    -------
    TrimPoint

    Raises
    ------
    EnvelopeError
        If (h, V) is outside the envelope (the message gives the envelope).
    TrimError
        If the solver does not converge, the residual exceeds `TRIM_TOL`
        (scaled), or the trim input violates the input limits.

    Examples
    --------
    The design point of `cm_certified` (alpha and delta_e in deg):

    >>> import math
    >>> from fahv.model.vehicle import load_vehicle
    >>> v = load_vehicle()
    >>> tp = trim(v, 85500.0, 7900.0, "cm")
    >>> [round(math.degrees(a), 4) for a in (tp.alpha, tp.delta_e)], round(float(tp.Phi), 4)
    ([1.5774, 12.3816], 0.2696)
    >>> tp.residual < TRIM_TOL
    True
    >>> trim(v, 90000.0, 7900.0)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
        ...
    fahv.errors.EnvelopeError: flight condition h = 90000.0 ft, V = 7900.0 ft/s lies outside ...
    """
    vehicle.envelope.check(h, V)
    vp = vehicle.params
    zs = np.array([0.0174533, 0.0174533, 0.05])
    z0 = np.array(guess if guess is not None else (0.028, 0.21, 0.27)) / zs

    def fun(z):
        return _rigid_residual(z, h, V, vp, zs)

    def jac(z):
        return jacobian_complex_step(fun, z)

    from scipy import optimize  # trim solves only (node start-up)

    sol = optimize.root(fun, z0, jac=jac, method="hybr", options={"xtol": 1e-14})
    z = sol.x
    for _ in range(3):  # Newton polish with the exact (complex-step) Jacobian
        z = z - np.linalg.solve(jac(z), fun(z))
    alpha, de, Phi = z * zs
    if not np.all(np.isfinite(z)):
        raise TrimError(f"trim at h = {h} ft, V = {V} ft/s did not converge ({sol.message})")
    _, _, _, _, N1, N2 = forces(np.array([h, V, alpha]), np.array([Phi, de]), vp)
    eta_1, eta_2 = N1 / vp.omega_1**2, N2 / vp.omega_2**2
    tp = TrimPoint(h, V, alpha, de, Phi, eta_1, eta_2, 0.0)
    mdl = make_model(model, vehicle, notch)
    x_r = tp.x_r_ecm if model == "ecm" else tp.x_r
    scale = mdl.state_scale(vehicle, notch)
    resid = float(np.max(np.abs(mdl.f(x_r, tp.u_r) / scale)))
    tp = TrimPoint(h, V, alpha, de, Phi, eta_1, eta_2, resid)
    if not resid < TRIM_TOL:
        raise TrimError(
            f"no trim at h = {h} ft, V = {V} ft/s: scaled residual {resid:.3e} "
            f"exceeds {TRIM_TOL:.0e} ({sol.message})"
        )
    lim = vehicle.limits
    if not (lim.Phi_min <= Phi <= lim.Phi_max):
        raise TrimError(
            f"trim at h = {h} ft, V = {V} ft/s needs Phi = {Phi:.4f}, outside "
            f"the limits [{lim.Phi_min}, {lim.Phi_max}]"
        )
    if not (lim.delta_e_min <= de <= lim.delta_e_max):
        raise TrimError(
            f"trim at h = {h} ft, V = {V} ft/s needs delta_e = "
            f"{np.degrees(de):.3f} deg, outside the limits "
            f"[{np.degrees(lim.delta_e_min):.1f}, "
            f"{np.degrees(lim.delta_e_max):.1f}] deg"
        )
    return tp


def _level_residual(z, h, V, vp, zs):
    """Scaled rigid residual of level flight at (h, V) for L points: (3, L), as `trim`."""
    alpha, de, Phi = z[0] * zs[0], z[1] * zs[1], z[2] * zs[2]
    L, D, T, M, _, _ = forces((h, V, alpha), (Phi, de), vp)
    V_dot = (T * np.cos(alpha) - D) / vp.m
    alpha_dot = (-T * np.sin(alpha) - L) / (vp.m * V) + vp.g / V
    q_dot = M / vp.I_yy
    return np.stack([V_dot / 10.0, alpha_dot / 0.0174533, q_dot / 0.0174533])


def trim_batch(
    params: VehicleParams, h, V, guess: np.ndarray, iterations: int = 30
) -> tuple[np.ndarray, np.ndarray]:
    """Level-flight trims of L vehicles at L points at once (vectorised Newton, eq. 5).

    The rigid equations of `trim` (V_dot = alpha_dot = q_dot = 0 at theta = alpha,
    q = 0) solved by Newton's method with the exact complex-step Jacobian, every point
    at once. For trims of many perturbed vehicles (the corners of the sec. 5.1 box)
    over a grid: about 1e5 trims per second.

    Parameters
    ----------
    params : VehicleParams
        Parameters whose fields are floats or (L,) arrays (one vehicle per point,
        e.g. `dataclasses.replace(vp, m=m_array)`).
    h, V : (L,) array_like
        Altitude [ft] and speed [ft/s] of each point.
    guess : (3, L) array_like
        Starting points (alpha rad, delta_e rad, Phi), e.g. the nominal trims.
    iterations : int
        Largest number of Newton steps.

    Returns
    -------
    z : (3, L) ndarray
        (alpha rad, delta_e rad, Phi) of each trim.
    residual : (L,) ndarray
        Scaled rigid residual of each, max |(V_dot / 10 ft/s^2, alpha_dot / 1 deg/s,
        q_dot / 1 deg/s^2)| (the rows `trim` solves).

    Raises
    ------
    ValueError
        If the shapes do not agree.

    Examples
    --------
    The nominal vehicle and one 10 % heavier at the design point, from the nominal trim:

    >>> import dataclasses, math
    >>> from fahv.model.vehicle import load_vehicle
    >>> v = load_vehicle()
    >>> tp = trim(v, 85500.0, 7900.0)
    >>> vp = dataclasses.replace(v.params, m=np.array([300.0, 330.0]))
    >>> guess = np.array([[tp.alpha, tp.delta_e, tp.Phi]] * 2).T
    >>> z, residual = trim_batch(vp, [85500.0] * 2, [7900.0] * 2, guess)
    >>> [round(math.degrees(a), 4) for a in z[0]]  # alpha [deg]
    [1.5774, 1.8176]
    >>> bool(abs(z[0, 0] - tp.alpha) < 1e-10), bool(residual.max() < 1e-10)
    (True, True)
    """
    h, V = np.asarray(h, float), np.asarray(V, float)
    zs = np.array([0.0174533, 0.0174533, 0.05])
    z = np.array(guess, float) / zs[:, None]
    if z.ndim != 2 or z.shape[0] != 3 or h.shape != (z.shape[1],) or V.shape != h.shape:
        raise ValueError(f"trim_batch: guess {z.shape}, h {h.shape}, V {V.shape} do not agree")
    step = 1e-30
    for _ in range(iterations):
        f = _level_residual(z, h, V, params, zs)
        J = np.empty((z.shape[1], 3, 3))
        for j in range(3):
            zc = z.astype(complex)
            zc[j] += 1j * step
            J[:, :, j] = (_level_residual(zc, h, V, params, zs).imag / step).T
        dz = np.linalg.solve(J, f.T[:, :, None])[..., 0].T
        z = z - dz
        if np.max(np.abs(dz)) < 1e-12:
            break
    f = _level_residual(z, h, V, params, zs)
    return z * zs[:, None], np.max(np.abs(f), axis=0)


def trim_grid(vehicle: Vehicle, h_grid, V_grid, model: str = "dm", notch=None):
    """Trim over a grid, each point started from its neighbour's solution.

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle trimmed.
    h_grid : (N_h,) array_like
        Altitudes [ft], inside the envelope.
    V_grid : (N_V,) array_like
        Speeds [ft/s], inside the envelope.
    model : {"dm", "cm", "ecm"}
        Model whose full residual is checked (`trim`).
    notch : NotchFilter, optional
        Needed for `model="ecm"`.

    Returns
    -------
    list of list of TrimPoint
        `[[TrimPoint for V in V_grid] for h in h_grid]`.

    Raises
    ------
    EnvelopeError, TrimError
        As `trim`.
    """
    rows = []
    for h in h_grid:
        row, guess = [], None
        for V in V_grid:
            tp = trim(vehicle, float(h), float(V), model, guess, notch)
            guess = (tp.alpha, tp.delta_e, tp.Phi)
            row.append(tp)
        rows.append(row)
    return rows


@dataclass(frozen=True)
class TrimMap:
    """Trim map x_r(p), u_r(p) over the envelope, eq. (5), interpolated between trims.

    Attributes
    ----------
    h_grid : (N_h,) ndarray
        Altitudes [ft] of the trim grid (ascending, at least 4).
    V_grid : (N_V,) ndarray
        Speeds [ft/s] (ascending, at least 4).
    x_r : (N_h, N_V, n) ndarray
        Trim states (n = 9 for DM/CM, 11 for ECM).
    u_r : (N_h, N_V, 2) ndarray
        Trim inputs [Phi, delta_e rad].

    Notes
    -----
    Bicubic interpolating splines (`scipy.interpolate.RectBivariateSpline`) of each
    component, evaluated together as one `scipy.interpolate.NdBSpline`.
    (h, V) is clipped to the grid, which covers the envelope.
    """

    h_grid: np.ndarray
    V_grid: np.ndarray
    x_r: np.ndarray
    u_r: np.ndarray

    def __post_init__(self) -> None:
        nh, nv = len(self.h_grid), len(self.V_grid)
        if nh < 4 or nv < 4:
            raise ValueError(f"trim map needs at least a 4 x 4 grid, got {nh} x {nv}")
        if self.x_r.shape[:2] != (nh, nv) or self.u_r.shape != (nh, nv, 2):
            raise ValueError(
                f"trim map arrays x_r {self.x_r.shape} / u_r {self.u_r.shape} do not match "
                f"the grid {nh} x {nv}"
            )
        vals = np.concatenate([self.x_r, self.u_r], axis=2)
        if not np.all(np.isfinite(vals)):
            raise ValueError("trim map contains non-finite values")
        from scipy import interpolate  # here: nodes without a trim map skip its 0.4 s import

        splines = [
            interpolate.RectBivariateSpline(self.h_grid, self.V_grid, vals[:, :, j])
            for j in range(vals.shape[2])
        ]
        # One vector-valued tensor-product B-spline with the fitted coefficients of all
        # components: the same function, evaluated in one call (about 10x faster).
        tx, ty = splines[0].get_knots()
        coef = np.stack(
            [sp.get_coeffs().reshape(len(tx) - 4, len(ty) - 4) for sp in splines], axis=-1
        )
        object.__setattr__(self, "_spline", interpolate.NdBSpline((tx, ty), coef, 3))

    @property
    def n_x(self) -> int:
        """State dimension of the map."""
        return self.x_r.shape[2]

    def at(self, h, V) -> tuple[np.ndarray, np.ndarray]:
        """(x_r (B, n), u_r (B, 2)) at B points, clipped to the grid.

        Parameters
        ----------
        h : float or (B,) array_like
            Altitudes [ft].
        V : float or (B,) array_like
            Speeds [ft/s].

        Returns
        -------
        x_r : (B, n) ndarray
            Trim states (state units).
        u_r : (B, 2) ndarray
            Trim inputs [Phi -, delta_e rad].
        """
        h = np.minimum(
            np.maximum(np.atleast_1d(np.asarray(h, float)), self.h_grid[0]), self.h_grid[-1]
        )
        V = np.minimum(
            np.maximum(np.atleast_1d(np.asarray(V, float)), self.V_grid[0]), self.V_grid[-1]
        )
        v = self._spline(np.stack([h, V], axis=1))
        n = self.n_x
        return v[:, :n], v[:, n:]

    def __call__(self, h: float, V: float) -> tuple[np.ndarray, np.ndarray]:
        """(x_r (n,), u_r (2,)) at one point (h [ft], V [ft/s]): `at` of one point."""
        x, u = self.at(h, V)
        return x[0], u[0]


@one_blas_thread
def trim_map(vehicle: Vehicle, n_h: int = 13, n_V: int = 13, model: str = "cm", notch=None):
    """Trim the model on an n_h x n_V grid over the envelope and build a `TrimMap`.

    `model="ecm"` (with `notch`) gives the 11-state trim x_r' of eq. (41).

    Parameters
    ----------
    vehicle : Vehicle
        The vehicle trimmed; its envelope is the grid's extent.
    n_h : int
        Grid points in h (at least 4), uniform over the envelope, ends included.
    n_V : int
        Grid points in V (at least 4).
    model : {"dm", "cm", "ecm"}
        Model trimmed (`trim`).
    notch : NotchFilter, optional
        Needed for `model="ecm"`.

    Returns
    -------
    TrimMap
        The bicubic map over the grid.

    Raises
    ------
    EnvelopeError, TrimError
        As `trim`.
    ValueError
        If `n_h` or `n_V` is below 4 (`TrimMap`).

    Examples
    --------
    >>> import math
    >>> from fahv.model.vehicle import load_vehicle
    >>> tm = trim_map(load_vehicle(), n_h=4, n_V=4)
    >>> x_r, u_r = tm(85500.0, 7900.0)  # between grid points: the trim's 12.3816 deg
    >>> x_r.shape, round(math.degrees(u_r[1]), 4)
    ((9,), 12.3816)
    """
    env = vehicle.envelope
    hg = np.linspace(env.h_min, env.h_max, n_h)
    Vg = np.linspace(env.V_min, env.V_max, n_V)
    rows = trim_grid(vehicle, hg, Vg, model, notch)
    x = np.array([[tp.x_r_ecm if model == "ecm" else tp.x_r for tp in row] for row in rows])
    u = np.array([[tp.u_r for tp in row] for row in rows])
    return TrimMap(hg, Vg, x, u)
