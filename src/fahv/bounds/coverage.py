"""Coverage of an elevator loss over the parameter box: every faulty trim within the inputs.

A vehicle with elevator effectiveness rho_f holds its trim with delta_e,r / rho_f (eq. 15;
Phi unchanged). The tube covers a loss only if that faulty trim fits the tightened input
set (eq. 30) for every vehicle of the parameter box (sec. 5.1) anywhere in the envelope:
`loss_coverage` trims every corner of the parameter box over the trim grid
(`corner_trims`) and bounds the trim elevator between grid points.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field

import numpy as np

from fahv.errors import DesignError

#: Parameters of the parameter box (sec. 5.1) that do not enter a level-flight trim: with gamma = 0,
#: q = 0 and eta_dot = 0 the trim rows are T cos(alpha) = D, L + T sin(alpha) = m g and
#: M = 0 (eq. 1-2), in which I_yy does not appear (`tests/design/test_feasibility.py`
#: checks it numerically).
TRIM_FREE_PARAMETERS = ("I_yy",)


@dataclass(frozen=True)
class LossCoverage:
    """Largest elevator loss whose faulty trim fits the tightened inputs over the parameter box.

    A vehicle with elevator effectiveness rho_f holds its trim with delta_e,r / rho_f
    (eq. 15; Phi unchanged). `loss_coverage` computes it for every corner of the
    sec. 5.1 parameter box over the trim grid of the envelope.

    Attributes
    ----------
    loss : float
        Largest loss 1 - rho_f in [0, 1] covered for every corner anywhere in the
        envelope (grid values plus the remainder bound between grid points).
    loss_path : float
        The same at the design step's path points only (its start and end).
    delta_e_max : float
        Largest trim elevator [rad] over corners and grid points.
    remainder : float
        Bound [rad] on how much the trim elevator between grid points can exceed the
        grid values (`loss_coverage`, Notes).
    worst_corner : dict
        {parameter: sign in {-1, 0, +1}} of the corner that needs delta_e_max
        (0: parameters that do not enter the trim).
    worst_point : (float, float)
        (h ft, V ft/s) where it does.
    Phi_range : (float, float)
        Smallest and largest trim Phi over corners and grid.
    alpha_offset_max : float
        Largest |alpha_r,p - alpha_r| [rad] between a corner's trim and the nominal
        vehicle's at the same point (also the theta offset: theta = alpha at trim).
    corners : int
        Corners trimmed (2^P over the parameters that enter the trim).
    points : int
        Grid points (the envelope's edges included).
    monotone : (bool, bool)
        Whether the trim elevator is monotone in h and in V along every grid line of
        every corner (then its maximum lies on the envelope's corners).
    input_offset : (C, nh, nV, 2) ndarray
        Every corner's trim input minus the nominal vehicle's at the same grid point
        [Phi -, delta_e rad] (`trim_offsets`).
    """

    loss: float
    loss_path: float
    delta_e_max: float
    remainder: float
    worst_corner: dict
    worst_point: tuple
    Phi_range: tuple
    alpha_offset_max: float
    corners: int
    points: int
    monotone: tuple
    input_offset: np.ndarray = field(default=None, repr=False)

    def trim_offsets(self) -> tuple[np.ndarray, np.ndarray]:
        """Range of a parameter-box corner's trim input minus the nominal vehicle's at a point.

        What the plant applies at steady state, whatever its elevator loss or bias (a
        vehicle that lost effectiveness is commanded delta_e,r / rho_f and applies
        delta_e,r, eq. 15; a bias is taken off the command the same way).

        Returns
        -------
        lo, hi : (2,) ndarray
            Smallest and largest [Phi -, delta_e rad] over the corners and the trim grid;
            the elevator's widened by the remainder bound between grid points for the
            corner's trim and the nominal's (the same bound, taken for it too), Phi's at
            the grid points.
        """
        off = self.input_offset
        lo = np.array([off[..., 0].min(), off[..., 1].min() - 2.0 * self.remainder])
        hi = np.array([off[..., 0].max(), off[..., 1].max() + 2.0 * self.remainder])
        return lo, hi

    def failing(self, rho_f: float, u_hi_e: float) -> str:
        """'' if a loss 1 - rho_f is covered, else a sentence naming the corner and the point."""
        if 1.0 - rho_f <= self.loss + 1e-12:
            return ""
        corner = ", ".join(
            f"{k} {'+' if s > 0 else '-'}" for k, s in self.worst_corner.items() if s != 0
        )
        return (
            f"a loss of {100 * (1 - rho_f):.1f} % is not covered over the parameter box: the "
            f"corner ({corner}) at h = {self.worst_point[0]:.0f} ft, V = "
            f"{self.worst_point[1]:.1f} ft/s trims at delta_e = "
            f"{np.degrees(self.delta_e_max):.3f} deg (+{np.degrees(self.remainder):.3f} deg "
            f"between grid points) and needs "
            f"{np.degrees(self.delta_e_max + self.remainder) / rho_f:.3f} deg at rho_f = "
            f"{rho_f}, beyond the tightened limit {np.degrees(u_hi_e):.3f} deg; largest loss "
            f"covered over the parameter box and the envelope: {100 * self.loss:.1f} %"
        )

    def summary(self) -> dict:
        """JSON-able form (design summary)."""
        return {
            "loss": self.loss,
            "loss_path": self.loss_path,
            "delta_e_max_deg": float(np.degrees(self.delta_e_max)),
            "remainder_deg": float(np.degrees(self.remainder)),
            "worst_corner": self.worst_corner,
            "worst_point": list(self.worst_point),
            "Phi_range": list(self.Phi_range),
            "alpha_offset_max_deg": float(np.degrees(self.alpha_offset_max)),
            "corners": self.corners,
            "points": self.points,
            "monotone_h_V": list(self.monotone),
        }


def _corner_params(vp, names, signs, rel, reps: int):
    """Parameters with (C reps,) array fields: corner c repeated `reps` times (perturb's rule)."""
    return vp.replace(
        **{k: np.repeat(getattr(vp, k) * (1.0 + signs[:, j] * rel[k]), reps)
           for j, k in enumerate(names)}
    )  # fmt: skip


def corner_trims(vehicle, rel: dict, tm, signs: np.ndarray | None = None):
    """Trims of every corner of a parameter box at every point of a trim map's grid.

    Parameters
    ----------
    vehicle : fahv.model.vehicle.Vehicle
    rel : dict
        {parameter: relative bound} (e.g. the sec. 5.1 box times the design's scale).
    tm : fahv.model.trim.TrimMap
        Nominal trims on the grid (starting points; its grid spans the envelope).
    signs : (C, P) ndarray, optional
        Corners to trim (signs over the parameters of `rel` that enter the trim, in
        that order); every corner by default.

    Returns
    -------
    names : list of str
        The parameters that enter the trim (`rel` minus `TRIM_FREE_PARAMETERS`).
    signs : (C, P) ndarray
    z : (3, C, N_h, N_V) ndarray
        alpha [rad], delta_e [rad], Phi of each corner's trim at each grid point.

    Raises
    ------
    DesignError
        If a trim does not converge (names the corner and the point).
    """
    from fahv.model.trim import TRIM_TOL, trim_batch

    names = [k for k in rel if k not in TRIM_FREE_PARAMETERS]
    if signs is None:
        signs = np.array(list(itertools.product((-1.0, 1.0), repeat=len(names))))
    signs = np.atleast_2d(np.asarray(signs, float))
    C = signs.shape[0]
    nh, nv = len(tm.h_grid), len(tm.V_grid)
    vp = _corner_params(vehicle.params, names, signs, rel, nh * nv)
    hh, VV = np.meshgrid(tm.h_grid, tm.V_grid, indexing="ij")
    h = np.tile(hh.ravel(), C)
    V = np.tile(VV.ravel(), C)
    guess = np.stack(
        [tm.x_r[..., 2].ravel(), tm.u_r[..., 1].ravel(), tm.u_r[..., 0].ravel()]
    )  # (3, N_h N_V)
    z, res = trim_batch(vp, h, V, np.tile(guess, (1, C)))
    bad = ~(res < TRIM_TOL) | ~np.all(np.isfinite(z), axis=0)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        corner = dict(zip(names, signs[i // (nh * nv)].tolist(), strict=True))
        raise DesignError(
            f"no trim of the parameter corner {corner} at h = {h[i]:.0f} ft, V = {V[i]:.1f} "
            f"ft/s (scaled residual {res[i]:.2e})"
        )
    return names, signs, z.reshape(3, C, nh, nv)


def loss_coverage(vehicle, rel: dict, tm, u_lo, u_hi, path=()) -> LossCoverage:
    """Largest elevator loss whose faulty trim fits [u_lo, u_hi] for every corner, everywhere.

    Parameters
    ----------
    vehicle : fahv.model.vehicle.Vehicle
    rel : dict
        {parameter: relative bound} of the parameter box.
    tm : fahv.model.trim.TrimMap
        Trim map of the design; its grid (edges of the envelope included) is where
        the corners are trimmed.
    u_lo, u_hi : (2,) array_like
        Tightened absolute input limits [Phi, delta_e rad] (eq. 30).
    path : sequence of (h, V)
        The design step's path points (start and end), trimmed for every corner too.

    Returns
    -------
    LossCoverage

    Raises
    ------
    DesignError
        If a corner's trim does not converge, or the trim elevator is not positive
        (the faulty trim delta_e,r / rho_f is then not the binding side).

    Notes
    -----
    Corners: a level-flight trim does not depend on I_yy
    (`TRIM_FREE_PARAMETERS`), so the 2^10 = 1024 corners of the parameter box
    have 512 distinct trims; all are computed (vectorised Newton,
    `fahv.model.trim.trim_batch`).
    The worst case lies at a corner because at a fixed point every parameter enters
    the trim monotonically over the parameter box (checked by the test of this function on
    interior draws).

    Between grid points: for each corner, the trim elevator f(h, V) on a grid cell is at
    most the largest of its four corner values plus (dh^2 max|f_hh| + dV^2 max|f_VV|) / 8
    (the error bound of bilinear interpolation). The second derivatives are taken as
    twice the largest second difference of f on the grid (over all corners and lines):
    an assumption on their smoothness, checked by the test on a grid three times
    finer.
    """
    u_lo, u_hi = np.asarray(u_lo, float), np.asarray(u_hi, float)
    names, signs, z = corner_trims(vehicle, rel, tm)
    alpha, de, Phi = z
    if np.any(de <= 0.0):
        raise DesignError("a corner of the parameter box trims with delta_e <= 0: the "
                          "coverage assumes the elevator binds upward")  # fmt: skip
    dh = float(np.diff(tm.h_grid).max())
    dV = float(np.diff(tm.V_grid).max())
    f_hh = np.abs(np.diff(de, 2, axis=1)).max() / dh**2 if de.shape[1] > 2 else 0.0
    f_VV = np.abs(np.diff(de, 2, axis=2)).max() / dV**2 if de.shape[2] > 2 else 0.0
    remainder = (dh**2 * 2.0 * f_hh + dV**2 * 2.0 * f_VV) / 8.0
    dh_sign = np.sign(np.diff(de, axis=1))
    dV_sign = np.sign(np.diff(de, axis=2))
    monotone = (bool(np.all(dh_sign == dh_sign.flat[0])), bool(np.all(dV_sign == dV_sign.flat[0])))
    i = np.unravel_index(int(np.argmax(de)), de.shape)
    de_max = float(de[i])
    worst = {k: 0.0 for k in rel}
    worst.update(zip(names, signs[i[0]].tolist(), strict=True))
    loss = float(np.clip(1.0 - (de_max + remainder) / u_hi[1], 0.0, 1.0))
    if de.min() < u_lo[1] or Phi.min() < u_lo[0] or Phi.max() > u_hi[0]:
        loss = 0.0  # not even the healthy trim fits
    alpha_nom = tm.x_r[..., 2]
    return LossCoverage(
        loss=loss,
        loss_path=_path_loss(vehicle, rel, tm, names, signs, u_hi, path) if len(path) else loss,
        delta_e_max=de_max,
        remainder=float(remainder),
        worst_corner=worst,
        worst_point=(float(tm.h_grid[i[1]]), float(tm.V_grid[i[2]])),
        Phi_range=(float(Phi.min()), float(Phi.max())),
        alpha_offset_max=float(np.abs(alpha - alpha_nom[None]).max()),
        corners=int(signs.shape[0]),
        points=int(de.shape[1] * de.shape[2]),
        monotone=monotone,
        input_offset=np.stack([Phi - tm.u_r[None, ..., 0], de - tm.u_r[None, ..., 1]], axis=-1),
    )


def _path_loss(vehicle, rel, tm, names, signs, u_hi, path) -> float:
    """The largest loss covered at the design step's path points (every corner trimmed there)."""
    from fahv.model.trim import TRIM_TOL, trim_batch

    pts = np.asarray(path, float)
    xs, us = tm.at(pts[:, 0], pts[:, 1])
    C = signs.shape[0]
    vp = _corner_params(vehicle.params, names, signs, rel, len(pts))
    guess = np.tile(np.stack([xs[:, 2], us[:, 1], us[:, 0]]), (1, C))
    zp, res = trim_batch(vp, np.tile(pts[:, 0], C), np.tile(pts[:, 1], C), guess)
    if not np.all(res < TRIM_TOL):
        raise DesignError("no trim of a parameter corner at a point of the design step's path")
    return float(np.clip(1.0 - zp[1].max() / u_hi[1], 0.0, 1.0))
