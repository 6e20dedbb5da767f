"""The tracking QP's state-dependent vectors, for B runs at once: linear cost and row bounds.

The rows of the condensed QP (`fahv.control.mpc.qp_layout`, built at a scheduling by
`fahv.control.mpc.tracking.TrackingMPC`) are fixed until the next scheduling; at
each re-plan only the linear cost f and the rows' bounds (bl, bu) move with the nominal's
deviation z0 from the scheduling trim, the steady input u_base, the command and the
disturbance estimate's shift x_d. A campaign batch re-plans all its runs at the same
step: `QPVectors` holds the parts of every run's QP that those vectors read, stacked
along a leading axis of B runs (copied at each run's scheduling, `put`), and `compute`
evaluates them for all runs in one pass of numpy calls, instead of about forty calls per
run. A single QP is a batch of one (`QPVectors.of`, `TrackingMPC.solve`).

A run's vectors do not depend on its batch, bit for bit: every product is a stacked
`np.matmul` of a run's (rows, n) matrix with its (n,) vector, which numpy evaluates
slice by slice with the same BLAS call as the run's own `matrix @ vector`; everything
else is element-wise.
"""

from __future__ import annotations

import numpy as np

#: Per-run parts of a scheduled QP that the vectors read (attribute names of
#: `TrackingMPC`); the range, own-trim and rate rows' parts where the settings have them.
PARTS = ("theta_s", "x_r_s", "Fz", "U_z", "Uf_z", "Tb_z", "Att_z", "u_lo", "u_hi",
         "_lo_b", "_hi_b", "_lo_b_rec", "_hi_b_rec")  # fmt: skip
#: The QP's "no bound": a bound at or beyond it reads as none.
QP_NO_BOUND = 1e30


def stacked_mv(M: np.ndarray, v: np.ndarray) -> np.ndarray:
    """M[b] @ v[b] for every run b, each product the BLAS call of the run alone.

    Parameters
    ----------
    M : (B, r, n) ndarray
    v : (B, n) ndarray

    Returns
    -------
    (B, r) ndarray
        Bit for bit each run's `M[b] @ v[b]` (a stacked `np.matmul`, evaluated slice by
        slice; `np.einsum` would sum in another order).
    """
    return np.matmul(M, v[:, :, None])[:, :, 0]


class QPVectors:
    """The parts of B runs' scheduled QPs that f, bl and bu read, stacked (module docstring).

    The settings and the shapes are those of `mpc`, shared by every run of a batch (one
    variant of one design); each run's tightened input limits are its own parts.

    Parameters
    ----------
    mpc : fahv.control.mpc.tracking.TrackingMPC
        A scheduled QP of the batch: its shapes and settings (shared by every run).
    B : int
        Runs.
    """

    def __init__(self, mpc, B: int) -> None:
        self.s, self.m, self.n = mpc.s, mpc.m, mpc.n
        self.layout, self.Du, self.theta_scale = mpc.layout, mpc.Du, mpc.theta_scale
        names = list(PARTS)
        if self.s.hv_box is not None:
            names.append("Hv_z")
        if self.s.x_box is not None:
            names += ["T_own", "Xb_z"]
        if self.s.has_rate_rows:
            names.append("Rate_z")
        self.names = tuple(names)
        self.parts = {k: np.empty((B, *np.shape(getattr(mpc, k)))) for k in self.names}
        if self.s.has_rate_rows:
            self._rate_scaled = np.tile(self.s.du_max / self.Du, self.s.N_p - 1)
        n, m = self.n, self.m
        self._no_lo_t = np.full((B, 2 * n), -QP_NO_BOUND)
        self._no_hi_u, self._no_lo_u = np.full((B, m), QP_NO_BOUND), np.full((B, m), -QP_NO_BOUND)

    @classmethod
    def of(cls, mpc) -> QPVectors:
        """A batch of one: the vectors of `mpc`'s own QP at its current scheduling."""
        one = cls(mpc, 1)
        one.put(0, mpc)
        return one

    def put(self, b: int, mpc) -> None:
        """Copy run b's scheduled parts into the stack.

        After its scheduling (`TrackingMPC.schedule`) or a change of its tightened input
        limits.
        """
        for k in self.names:
            self.parts[k][b] = getattr(mpc, k)

    def compute(self, z0, u_base, cmd, x_off, u_prev=None, recover=False, relax_steady=False):
        """Linear cost and row bounds of every run's QP, in the order of its rows.

        Parameters
        ----------
        z0 : (B, n) ndarray
            Nominal state minus the scheduling trim x_r.
        u_base : (B, 2) ndarray
            Steady input at the scheduling point, u_r + u_d (absolute) [Phi, delta_e rad].
        cmd : (B, 2) ndarray
            Command (h_c, V_c) [ft, ft/s].
        x_off : (B, n) ndarray
            Steady-state shift x_d of the disturbance estimate.
        u_prev : (B, 2) ndarray, optional
            Nominal input applied at the previous fast step (absolute); None: no rate row
            on the first move (the first plan of a run).
        recover, relax_steady : bool
            The recovery QPs (`fahv.control.mpc.tracking.TrackingMPC.solve`).

        Returns
        -------
        f : (B, ny) ndarray
            Linear cost (DAQP's 1/2 y' H y + f' y).
        bl, bu : (B, ny + rows) ndarray
            Bounds of y's simple bounds and of the rows of `A_c`.
        """
        P, s = self.parts, self.s
        e_theta = (P["theta_s"] - cmd) / self.theta_scale
        f = 2.0 * stacked_mv(P["Fz"], z0)
        f[:, self.layout.delta] += 2.0 * s.t_w * e_theta
        bl, bu = self._row_bounds(z0, u_base, x_off, recover, u_prev, relax_steady)
        return f, bl, bu

    def _row_bounds(self, z0, u_base, x_off, recover, u_prev, relax_steady):
        """Bounds (bl, bu) (B, ny + rows) of y and of the rows, in `_constraint_matrix`'s order."""
        P, s, m, B = self.parts, self.s, self.m, z0.shape[0]
        u_off = stacked_mv(P["U_z"], z0).reshape(B, s.N_p, m) + u_base[:, None]
        parts = [self._move_start_bounds(z0, u_base, u_off, x_off, recover, u_prev, relax_steady)]
        if s.hv_box is not None:  # widened to hold the start (the reset h may lie outside)
            hv = stacked_mv(P["Hv_z"], z0).reshape(B, -1, 2) + P["x_r_s"][:, None, :2]
            h0 = z0[:, :2] + P["x_r_s"][:, :2]
            hv_lo, hv_hi = np.minimum(s.hv_box[0], h0), np.maximum(s.hv_box[1], h0)
            parts.append(((hv_lo[:, None] - hv).reshape(B, -1),
                          (hv_hi[:, None] - hv).reshape(B, -1)))  # fmt: skip
        if s.x_box is not None:  # from the trim at the nominal's own (h, V), with x_d
            xd = x_off[:, 2:9]
            start = z0[:, 2:9] - stacked_mv(P["T_own"], np.ascontiguousarray(z0[:, 0:2])) + xd
            xb_lo, xb_hi = np.minimum(s.x_box[0], start), np.maximum(s.x_box[1], start)
            xb = stacked_mv(P["Xb_z"], z0).reshape(B, -1, 7) + xd[:, None]
            parts.append(((xb_lo[:, None] - xb).reshape(B, -1),
                          (xb_hi[:, None] - xb).reshape(B, -1)))  # fmt: skip
        if s.has_rate_rows:
            rz = stacked_mv(P["Rate_z"], z0)
            parts.append((-self._rate_scaled - rz, self._rate_scaled - rz))
        uf_off = stacked_mv(P["Uf_z"], z0).reshape(B, -1, m) + u_base[:, None]
        parts.append((((P["u_lo"][:, None] - uf_off) / self.Du).reshape(B, -1),
                      ((P["u_hi"][:, None] - uf_off) / self.Du).reshape(B, -1)))  # fmt: skip
        if s.u_box is not None:  # the manoeuvre part K zeta + c = u_off - u_base + Du (row y)
            for off in (u_off - u_base[:, None], uf_off - u_base[:, None]):
                parts.append((((s.u_box[0] - off) / self.Du).reshape(B, -1),
                              ((s.u_box[1] - off) / self.Du).reshape(B, -1)))  # fmt: skip
        bl = np.concatenate([p[0] for p in parts], axis=1)
        return bl, np.concatenate([p[1] for p in parts], axis=1)

    def _move_start_bounds(self, z0, u_base, u_off, x_off, recover, u_prev, relax_steady):
        """Bounds (bl, bu) of y and of the move-start, terminal, steady and attitude rows.

        `u_off` (B, N_p, m) is the move-start inputs at y = 0; the other arguments as
        `compute`. Per-move rows come as (B, N_p, m) and (B, n_att, 2) blocks broadcast
        against their (m,) / (2,) bounds (the same element-wise operations as tiling
        the bounds).
        """
        P, s, m, B = self.parts, self.s, self.m, z0.shape[0]
        lo_b, hi_b = (P["_lo_b_rec"], P["_hi_b_rec"]) if recover else (P["_lo_b"], P["_hi_b"])
        lo_u = ((P["u_lo"][:, None] - u_off) / self.Du).reshape(B, -1)
        hi_u = ((P["u_hi"][:, None] - u_off) / self.Du).reshape(B, -1)
        if s.has_rate_rows and u_prev is not None:  # u_0 within du_max of the input before
            c0 = (u_off[:, 0] - u_prev) / self.Du
            du = s.du_max / self.Du
            lo_u[:, :m] = np.maximum(lo_u[:, :m], -du - c0)
            hi_u[:, :m] = np.minimum(hi_u[:, :m], du - c0)
        tz = stacked_mv(P["Tb_z"], z0)
        att = stacked_mv(P["Att_z"], z0).reshape(B, -1, 2)
        a_max = np.minimum(np.broadcast_to(s.att_max, (2,)), 1e3)
        off = x_off[:, 2:4]
        att_lo, att_hi = np.minimum(-a_max - off, 0.0), np.maximum(a_max - off, 0.0)
        s_hi = self._no_hi_u if relax_steady else (P["u_hi"] - u_base) / self.Du
        s_lo = self._no_lo_u if relax_steady else (P["u_lo"] - u_base) / self.Du
        bu = np.concatenate(
            [hi_b, hi_u, -tz, tz, s_hi, self._no_hi_u, (att_hi[:, None] - att).reshape(B, -1)],
            axis=1,
        )  # fmt: skip
        bl = np.concatenate(
            [lo_b, lo_u, self._no_lo_t, self._no_lo_u, s_lo,
             (att_lo[:, None] - att).reshape(B, -1)],
            axis=1,
        )  # fmt: skip
        return bl, bu
