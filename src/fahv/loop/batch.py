"""Batched in-process closed loop: many runs of one variant at once, numpy over a batch axis.

A Monte Carlo campaign runs the same designed case hundreds of times with other plant
parameters, faults, commands and initial trims (node parameter ``overrides``, as
:func:`fahv.loop.simulate.simulate` takes them). :func:`simulate_batch` runs B such
runs together: every quantity of the loop gets a batch axis and each numpy call
advances all B runs, so the Python overhead of one step is paid once per batch
instead of once per run.

Same numbers as :func:`~fahv.loop.simulate.simulate`, bit for bit
    Every run is first built exactly as ``simulate`` builds it (its node parameters
    validated by :func:`fahv.loop.cores.build_core`, which also gives the initial
    states), then the batched kernel repeats the operations of the cores in the same
    order: elementwise operations over the batch axis are the scalar operations
    (IEEE 754), the plant's RK4 of :func:`fahv.model.dynamics.cm_rhs` runs on a
    (9, B) state with per-run parameters as (B,) arrays, and every matrix product is
    a stacked ``np.matmul`` whose items are the very BLAS call the scalar code makes
    (a (B, n) operand is C-contiguous, the matrix broadcast). A run's result
    therefore does not depend on the batch it is in, nor on the batch size; the tests
    compare the two simulators with ``array_equal``.

What is batched, what is not
    Batched: the plant (RK4 of the CM), the notch filter, the ancillary law of the
    Tube-MPC laws, eq. (36)/(54) (``tube_mpc``, ``tube_mpc_paper`` and their notch
    variants; the 11-state ECM law of Case 2 included) and the built-in fault kinds.
    The nominal part, by mode of the nominal_trajectory node:

    - ``governor`` (the paper's law): batched whole (nominal LPV model, reference
      governor with its bisection, trim map);
    - ``mpc`` (the online nominal MPC of :mod:`fahv.control.nominal_mpc`): the fast
      steps (disturbance estimate, plan interpolation, nominal model, trim map) are
      batched; every M steps each run's own :class:`~fahv.control.nominal_mpc.TrackingNominal`
      re-plans (``_plan``: scheduling of the condensed QP and one DAQP solve), one run
      after the other -- a QP per run cannot share a numpy call. This mirror is used
      only while the source of ``TrackingNominal`` is the one it was checked against
      (:data:`MPC_SOURCE_HASH`); otherwise the generic path below;
    - anything else: each run's own nominal core, called per run inside the batch.

    Not batched at all, run one by one through ``simulate`` (the per-run fallback):
    any other control law -- the RMPC baseline solves its Kothare LMIs online with
    cvxpy, one SDP per run and re-solve. A batch whose runs do not share the design
    matrices is split into groups that do.

Divergence
    A run whose plant state becomes non-finite fails with the message ``simulate``
    raises (:class:`fahv.errors.RunError`, time of the step); the batch goes on, the
    failed run's lanes are reset to finite values and their results discarded.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import inspect
from collections.abc import Sequence

import numpy as np

from fahv.control.nominal_mpc import TrackingNominal
from fahv.control.reference import NominalTrajectory
from fahv.control.tube_mpc import PaperTubeMPCLaw
from fahv.errors import RunError
from fahv.loop.cores import build_core
from fahv.loop.graph import STATE_FIELDS, n_steps_of
from fahv.loop.params import controller_node, validate
from fahv.loop.simulate import RunResult, run_parameters, simulate
from fahv.model.dynamics import cm_rhs
from fahv.model.vehicle import DELTA_E, Q, load_vehicle
from fahv.plant.faults import Bias, Dropout, LossOfEffectiveness, NoFault, Stuck
from fahv.plant.integrator import Plant, rk4_step

#: Loop nodes built for every run (the controller node is added per variant).
_NODES = ("plant", "notch_filter", "nominal_trajectory", "fault_injector")  # plant first
#: Fault kinds applied over the batch axis (others: per run, through their injector).
_FAULT_CODES = {NoFault: 0, LossOfEffectiveness: 1, Bias: 2, Stuck: 3, Dropout: 4}


@dataclasses.dataclass
class _PlantSetup:
    """What the kernel needs of a run's plant node (the attributes of ``PlantCore``)."""

    plant: Plant
    Ts: float
    n_steps: int
    limits: object


def _plant(raw: dict, vehicles: dict) -> _PlantSetup:
    """The plant of one run as :class:`fahv.loop.cores.PlantCore` builds it.

    Same validation (:func:`fahv.loop.params.validate`) and the same
    :class:`fahv.plant.integrator.Plant`, but the vehicle file is read once per batch
    (``vehicles`` caches it by file name) instead of once per run.
    """
    p = validate("plant", raw)
    key = p["vehicle_file"] or ""
    if key not in vehicles:
        vehicles[key] = load_vehicle(key or None)
    veh = vehicles[key]
    params = dataclasses.replace(
        veh.params, **{k.split(".", 1)[1]: v for k, v in p.items() if k.startswith("params.")}
    )
    plant = Plant(params, veh.limits, p["x0"], p["Ts"], p["plant_substeps"])
    return _PlantSetup(plant, p["Ts"], n_steps_of(p), veh.limits)


def _cores(p: dict, vehicles: dict) -> dict:
    """The cores of one run (plant, notch_filter, nominal_trajectory, fault_injector, ctrl)."""
    out = {n: build_core(n, p[n]) for n in _NODES[1:]}
    out["plant"] = _plant(p["plant"], vehicles)
    out["controller"] = build_core(controller_node(p), p[controller_node(p)])
    return out


def _source_hash(*objs) -> str:
    """sha256 (16 hex) of the source code of classes or functions."""
    return hashlib.sha256("".join(inspect.getsource(o) for o in objs).encode()).hexdigest()[:16]


#: Source hash of :class:`~fahv.control.nominal_mpc.TrackingNominal` and its estimator
#: that :class:`_MPCLanes` mirrors. When the class changes, the mirror is not used
#: (the generic per-run nominal path is, same numbers, slower) until its fast-step
#: computation has been checked again against the class and this hash updated
#: (``tests/loop/test_batch.py`` fails meanwhile).
MPC_SOURCE_HASH = "14dab426dfb2350a"


@functools.cache
def mpc_source_hash() -> str:
    """Current source hash of the nominal MPC classes the batched mirror depends on."""
    from fahv.control.nominal_mpc import DisturbanceEstimator

    return _source_hash(TrackingNominal, DisturbanceEstimator)


def nominal_mode(cores: dict) -> str:
    """How the batched kernel runs a run's nominal part: governor, mpc or per_run."""
    src = cores["nominal_trajectory"].source
    if type(src) is NominalTrajectory:
        return "governor"
    mirrored = mpc_source_hash() == MPC_SOURCE_HASH
    if type(src) is TrackingNominal and src.measure is None and mirrored:
        return "mpc"
    return "per_run"


def not_batchable(cores: dict) -> str | None:
    """Why one run's cores cannot go through the batched kernel (None: they can).

    The kernel reproduces exactly the ancillary law of eq. (36)/(54)
    (:meth:`fahv.control.tube_mpc.PaperTubeMPCLaw.step`, also the step of
    ``tube_mpc``); any other law runs through the per-run fallback.
    """
    law = cores["controller"].law
    if not isinstance(law, PaperTubeMPCLaw) or type(law).step is not PaperTubeMPCLaw.step:
        return f"control law '{law.name}' ({type(law).__name__}) has no batched kernel"
    return None


def _signature(c: dict) -> bytes:
    """Bytes of everything the batched kernel shares between the runs of a batch."""
    pl, nt, no, ct = c["plant"], c["notch_filter"], c["nominal_trajectory"], c["controller"]
    src, law = no.source, ct.law
    mode = nominal_mode(c)
    parts = [
        repr((pl.Ts, pl.n_steps, pl.plant.n_sub, pl.limits, nt.enabled, law.tube.tau, mode)),
        repr(type(law).__name__),
    ]
    arrays = [law.tube.F, law.tube.N_inv]
    if mode == "governor":
        parts.append(repr(src.level_max))
        arrays += [src.K, src.P, src.lpv.A, src.lpv.B, src.lpv.h_grid, src.lpv.V_grid]
        arrays += [src.lpv.W_h, src.lpv.W_V, src.trim_map.h_grid, src.trim_map.V_grid]
        arrays += [src.trim_map.x_r, src.trim_map.u_r]
    elif mode == "mpc":
        mpc = src.mpc
        parts.append(repr((mpc.s.M, src.est is None, src.n_plant, src.Ts)))
        parts.append(repr(None if src.est is None else src.est.gamma))
        arrays += [mpc.K, mpc.L, mpc.Du, mpc.theta_scale, mpc.trim_map.h_grid]
        arrays += [mpc.trim_map.V_grid, mpc.trim_map.x_r, mpc.trim_map.u_r]
    if nt.enabled:
        f = nt.filter
        arrays += [f._Ad, f._Bd, f.C_q, np.array([f.D_q])]
    return b"".join(p.encode() for p in parts) + b"".join(
        np.ascontiguousarray(a).tobytes() + repr(a.shape).encode() for a in arrays
    )


def simulate_batch(
    design,
    variant: str | None = None,
    overrides: Sequence[dict | None] = (None,),
    duration: float | None = None,
    fallback: bool = True,
) -> list[RunResult | Exception]:
    """Run B runs of one variant of a designed case, batched where the law allows.

    Parameters
    ----------
    design : fahv.design.Design
    variant : str, optional
        One of the case's variants; its first by default.
    overrides : sequence of dict or None
        Per run, node parameter overrides ``{node: {name: value}}`` (as
        :func:`~fahv.loop.simulate.simulate` takes them); B = its length.
    duration : float, optional
        Simulated time of every run [s]; the case's by default.
    fallback : bool
        Runs that cannot be batched (see the module notes) run one by one through
        ``simulate`` (True) or fail with the reason (False, for tests).

    Returns
    -------
    list
        Per run, in order: its :class:`~fahv.loop.simulate.RunResult` (identical to
        ``simulate(design, variant, duration, overrides=...)``), or the exception
        that run raised (:class:`~fahv.errors.RunError` for a non-finite state,
        :class:`~fahv.errors.ParameterError` naming the node and key of a bad
        override, ...). One failing run never stops the others.
    """
    case = design.case
    variant = case["variants"][0] if variant is None else variant
    n = len(overrides)
    results: list = [None] * n
    built: dict[int, dict] = {}
    groups: dict[bytes, list[int]] = {}
    single: list[int] = []
    vehicles: dict = {}
    for i, ov in enumerate(overrides):
        try:
            cores = _cores(run_parameters(design, variant, duration, ov), vehicles)
        except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
            results[i] = exc
            continue
        reason = not_batchable(cores)
        if reason is not None:
            if not fallback:
                results[i] = RunError(f"run cannot be batched: {reason}")
            else:
                single.append(i)
            continue
        built[i] = cores
        groups.setdefault(_signature(cores), []).append(i)
    info = {"variant": variant, "case": case["name"], "fault": case["fault"]}  # as simulate
    for idx in groups.values():
        for i, res in zip(idx, _run_kernel([built[i] for i in idx], info), strict=True):
            results[i] = res
    for i in single:
        try:
            results[i] = simulate(design, variant, duration, overrides=overrides[i])
        except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
            results[i] = exc
    return results


def _stack_params(cores: list[dict]):
    """VehicleParams whose fields differ between runs become (B,) arrays (others floats)."""
    ps = [c["plant"].plant.params for c in cores]
    changes = {}
    for f in dataclasses.fields(ps[0]):
        vals = [getattr(p, f.name) for p in ps]
        if any(v != vals[0] for v in vals):
            changes[f.name] = np.array(vals, dtype=float)
    return dataclasses.replace(ps[0], **changes)


def _quad(x: np.ndarray, M: np.ndarray) -> np.ndarray:
    """x_b' M x_b (B,) for x (B, n): the scalar ``x @ M @ x`` of every run, same BLAS calls."""
    return (np.matmul(x[:, None, :], M) @ x[:, :, None])[:, 0, 0]


def _mv(M: np.ndarray, x: np.ndarray) -> np.ndarray:
    """M @ x_b (B, m) for x (B, n): the scalar ``M @ x`` of every run (stacked gemv)."""
    return np.matmul(M, x[:, :, None])[..., 0]


def _govern(gov, G0, G1, dh, dV, XR, UR, x_pred):
    """Reference governor of :meth:`NominalTrajectory.advance` for every run at once.

    Per run: the full step (s = 1) if x_n stays in E(Q), else the bisection on s in
    [0, 1] (30 halvings, as the scalar code), the best admissible s kept; s = 0 when
    the command does not move. Returns s (B,), x_r (B, n), u_r (B, 2), x_n (B, n).
    """
    tm, P, level_max, n = gov
    B = G0.size
    s_best = np.zeros(B)
    xr_b, ur_b, xn_b = XR.copy(), UR.copy(), x_pred.copy()

    def candidate(s, rows):
        hh = np.minimum(np.maximum(G0[rows] + s * dh[rows], tm.h_grid[0]), tm.h_grid[-1])
        vv = np.minimum(np.maximum(G1[rows] + s * dV[rows], tm.V_grid[0]), tm.V_grid[-1])
        v = tm._spline(np.stack([hh, vv], axis=1))
        xr, ur = v[:, :n], v[:, n:]
        xn = x_pred[rows] - (xr - XR[rows])
        return xr, ur, xn, _quad(np.ascontiguousarray(xn), P) <= level_max

    rows = np.flatnonzero((dh != 0.0) | (dV != 0.0))
    if rows.size:
        xr, ur, xn, ok = candidate(1.0, rows)
        acc = rows[ok]
        s_best[acc], xr_b[acc], ur_b[acc], xn_b[acc] = 1.0, xr[ok], ur[ok], xn[ok]
        rows = rows[~ok]
    if rows.size:
        lo, hi = np.zeros(rows.size), np.ones(rows.size)
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            xr, ur, xn, ok = candidate(mid, rows)
            acc = rows[ok]
            s_best[acc], xr_b[acc], ur_b[acc], xn_b[acc] = mid[ok], xr[ok], ur[ok], xn[ok]
            lo = np.where(ok, mid, lo)
            hi = np.where(ok, hi, mid)
    return s_best, xr_b, ur_b, xn_b


class _GovernorLanes:
    """Nominal part of the paper's law for B runs: :class:`NominalTrajectory`, batched."""

    def __init__(self, cores: list[dict], command) -> None:
        srcs = [c["nominal_trajectory"].source for c in cores]
        s0 = srcs[0]
        self.command, self.Ts = command, s0.Ts
        self.lpv, self.K, n = s0.lpv, s0.K, s0.lpv.A.shape[1]
        R = s0.lpv.A.shape[0]
        self.A2 = np.ascontiguousarray(s0.lpv.A.reshape(R, -1))
        self.B2 = np.ascontiguousarray(s0.lpv.B.reshape(R, -1))
        self.shape = (R, n, s0.lpv.B.shape[2])
        self.gov = (s0.trim_map, s0.P, s0.level_max, n)
        self.G0 = np.array([s.g[0] for s in srcs], dtype=float)
        self.G1 = np.array([s.g[1] for s in srcs], dtype=float)
        self.XN = np.stack([s.x_n for s in srcs])
        self.XR = np.stack([s.x_r for s in srcs])
        self.UR = np.stack([s.u_r for s in srcs])

    def step(self, k: int, XT, U_prev, alive):
        """Outputs of step k (h_g, V_g, x_r, u_r, x_n, u_n), then advance; no failures."""
        G0, G1, XN, XR, UR = self.G0, self.G1, self.XN, self.XR, self.UR
        out = (G0, G1, XR, UR, XN, _mv(self.K, XN))
        lpv, (R, n, m), B = self.lpv, self.shape, G0.size
        wh = np.stack(
            [np.interp(G0, lpv.h_grid, lpv.W_h[:, a]) for a in range(lpv.W_h.shape[1])], 1
        )
        wv = np.stack(
            [np.interp(G1, lpv.V_grid, lpv.W_V[:, b]) for b in range(lpv.W_V.shape[1])], 1
        )
        w = (wh[:, :, None] * wv[:, None, :]).reshape(B, R)
        A = np.matmul(w[:, None, :], self.A2)[:, 0, :].reshape(B, n, n)
        Bm = np.matmul(w[:, None, :], self.B2)[:, 0, :].reshape(B, n, m)
        x_pred = (
            np.matmul(A, XN[:, :, None])[..., 0]
            + np.matmul(Bm, _mv(self.K, XN)[:, :, None])[..., 0]
        )
        ch, cV = self.command((k + 1) * self.Ts)
        dh, dV = ch - G0, cV - G1
        s_best, self.XR, self.UR, self.XN = _govern(self.gov, G0, G1, dh, dV, XR, UR, x_pred)
        self.G0, self.G1 = G0 + s_best * dh, G1 + s_best * dV
        return out, []


class _PerRunLanes:
    """Any nominal source: each run's own nominal core, called per run (exact by construction)."""

    def __init__(self, cores: list[dict], Ts: float) -> None:
        self.cores = [c["nominal_trajectory"] for c in cores]
        self.Ts = Ts
        self.last = None

    def step(self, k: int, XT, U_prev, alive):
        """Outputs of step k from each run's ``NominalCore.on_state``; failures per run."""
        t = k * self.Ts
        rows, failed = [], []
        for b, core in enumerate(self.cores):
            if not alive[b]:
                rows.append(None)
                continue
            state = {"k": k, "t": t, **dict(zip(STATE_FIELDS, map(float, XT[b]), strict=True))}
            prev = None
            if k > 0:
                prev = {"k": k - 1, "t": (k - 1) * self.Ts, "phi": float(U_prev[b, 0]),
                        "delta_e": float(U_prev[b, 1])}  # fmt: skip
            try:
                rows.append(core.on_state(state, prev))
            except Exception as exc:  # noqa: BLE001 - the run fails as in simulate
                failed.append((b, exc))
                rows.append(None)
        fill = next((r for r in rows if r is not None), None)
        if fill is None:
            fill = self.last
        self.last = fill
        rows = [fill if r is None else r for r in rows]
        out = (
            np.array([r["h_g"] for r in rows], dtype=float),
            np.array([r["v_g"] for r in rows], dtype=float),
            np.stack([np.asarray(r["x_r"], float) for r in rows]),
            np.stack([np.asarray(r["u_r"], float) for r in rows]),
            np.stack([np.asarray(r["x_n"], float) for r in rows]),
            np.stack([np.asarray(r["u_n"], float) for r in rows]),
        )
        return out, failed


class _MPCLanes:
    """Nominal MPC of ``tube_mpc`` for B runs: fast steps batched, re-plans per run.

    Mirrors :meth:`fahv.control.nominal_mpc.TrackingNominal.step` operation by
    operation (estimator update, plan interpolation, output, nominal model) over the
    batch axis; every M steps each run's own object re-plans (``_plan``) with its
    state written back first, and the scheduled matrices are read again after.
    """

    def __init__(self, cores: list[dict]) -> None:
        self.srcs = [c["nominal_trajectory"].source for c in cores]
        s0 = self.srcs[0]
        mpc = s0.mpc
        self.M, self.p, self.Ts = mpc.s.M, s0.n_plant, s0.Ts
        self.K, self.L, self.Du, self.scale = mpc.K, mpc.L, mpc.Du, mpc.theta_scale
        self.n = mpc.n
        self.has_est = s0.est is not None
        self.gamma = s0.est.gamma if self.has_est else 0.0
        B = len(self.srcs)
        self.XN = np.stack([s.X_n for s in self.srcs])
        self.D = np.stack([s.est.d if self.has_est else np.zeros(self.p) for s in self.srcs])
        self.prev = np.zeros((B, self.p))
        self.has_prev = np.array([s.prev is not None for s in self.srcs])
        for b, s in enumerate(self.srcs):
            if s.prev is not None:
                self.prev[b] = s.prev
        self.k = s0.k
        self._read()

    def _read(self, rows=None) -> None:
        """Scheduled matrices, set point and plan of the runs ``rows`` (all by default)."""
        srcs = self.srcs
        if rows is None:
            rows = range(len(srcs))
            m0 = srcs[0].mpc
            B = len(srcs)
            self.XRS = np.empty((B, m0.x_r_s.size))
            self.URS = np.empty((B, 2))
            self.THS = np.empty((B, 2))
            self.GX = np.empty((B,) + m0.Gx.shape)
            self.GU = np.empty((B,) + m0.Gu.shape)
            self.A = np.empty((B,) + m0.A.shape)
            self.Bm = np.empty((B,) + m0.B.shape)
            self.TH = np.empty((B, 2))
            self.PLAN0 = np.empty((B, 2))
            self.TRX = np.empty((B, self.n))
            self.TRU = np.empty((B, 2))
            self.HX = np.empty((B, self.n, self.p))
            self.HU = np.empty((B, 2, self.p))
            if self.has_est:
                self.EA = np.empty((B, self.p, self.p))
                self.EB = np.empty((B, self.p, 2))
        for b in rows:
            s = srcs[b]
            mpc = s.mpc
            self.XRS[b], self.URS[b], self.THS[b] = mpc.x_r_s, mpc.u_r_s, mpc.theta_s
            self.GX[b], self.GU[b], self.A[b], self.Bm[b] = mpc.Gx, mpc.Gu, mpc.A, mpc.B
            self.TH[b], self.PLAN0[b] = s.theta, s.plan[0]
            self.HX[b], self.HU[b] = s.Hx_p, s.Hu_p
            self.TRX[b], self.TRU[b] = s.trim_theta
            if self.has_est:
                EA, EB = s.est._AB
                self.EA[b], self.EB[b] = EA, EB

    def step(self, k: int, XT, U_prev, alive):
        """Outputs of step k (TrackingNominal.step of every run), then advance."""
        p = self.p
        failed = []
        if self.has_est:  # _estimate (x_meas and, from step 1 on, u_prev given)
            dx = XT[:, :p] - self.XRS[:, :p]
            if k > 0:
                upd = self.has_prev
                dx_prev = np.ascontiguousarray(self.prev - self.XRS[:, :p])
                du_prev = np.ascontiguousarray(U_prev - self.URS)
                r = (dx - np.matmul(self.EA, dx_prev[:, :, None])[..., 0]) - np.matmul(
                    self.EB, du_prev[:, :, None]
                )[..., 0]
                d_new = self.D + self.gamma * (r - self.D)
                self.D = np.where(upd[:, None], d_new, self.D)
            self.prev = XT[:, :p].copy()
            self.has_prev[:] = True
        if self.k % self.M == 0:  # re-plan: each run's own object, its state written back
            for b, s in enumerate(self.srcs):
                if not alive[b]:
                    continue
                s.X_n = self.XN[b].copy()
                s.k = self.k
                if self.has_est:
                    s.est.d = self.D[b].copy()
                try:
                    s._plan()
                except Exception as exc:  # noqa: BLE001 - the run fails as in simulate
                    failed.append((b, exc))
                    continue
                self._read([b])
        if self.has_est:
            Dc = np.ascontiguousarray(self.D)
            x_d = np.matmul(self.HX, Dc[:, :, None])[..., 0]
            u_d = np.matmul(self.HU, Dc[:, :, None])[..., 0]
        else:
            x_d, u_d = np.zeros((len(self.srcs), self.n)), np.zeros((len(self.srcs), 2))
        dth = (self.TH - self.THS) / self.scale
        x_s = np.matmul(self.GX, dth[:, :, None])[..., 0] + x_d
        u_s = np.matmul(self.GU, dth[:, :, None])[..., 0]
        z = self.XN - self.XRS
        zx = np.ascontiguousarray(z - x_s)
        u_dev = (u_s + _mv(self.K, zx)) + self.PLAN0 * self.Du
        u_nom = (self.URS + u_d) + u_dev
        x_r, u_r = self.TRX.copy(), self.TRU + u_d
        out = (self.TH[:, 0].copy(), self.TH[:, 1].copy(), x_r, u_r, self.XN - x_r, u_nom - u_r)
        zc = np.ascontiguousarray(z)
        d_n = np.zeros_like(z)
        if self.has_est:
            d_n[:, : self.p] = self.D
        self.XN = (
            (self.XRS + np.matmul(self.A, zc[:, :, None])[..., 0])
            + np.matmul(self.Bm, np.ascontiguousarray(u_d + u_dev)[:, :, None])[..., 0]
        ) + d_n
        self.k += 1
        return out, failed


def _qp_counts(cores: dict) -> np.ndarray:
    """The nominal MPC's counters of one run (:data:`fahv.loop.simulate.QP_COUNTS`)."""
    mpc = getattr(cores["nominal_trajectory"], "mpc", None)
    if mpc is None:
        return np.zeros(3, dtype=int)
    return np.array([mpc.stats.solves, mpc.stats.fallback, mpc.stats.terminal], dtype=int)


def _run_kernel(cores: list[dict], info: dict) -> list[RunResult | Exception]:
    """The batched loop over runs that share their design matrices (see the module notes)."""
    B = len(cores)
    c0 = cores[0]
    pl0, nt0, ct0 = c0["plant"], c0["notch_filter"], c0["controller"]
    Ts, n_steps, n_sub, limits = pl0.Ts, pl0.n_steps, pl0.plant.n_sub, pl0.limits
    vp = _stack_params(cores)
    tube = ct0.law.tube
    tauF, N_inv, tau2 = tube.tau * tube.F, tube.N_inv, tube.tau**2
    n = tube.F.shape[1]

    def rf(name):
        return np.array([getattr(c["nominal_trajectory"].command, name) for c in cores])

    cmd_h0, cmd_V0, cmd_hc, cmd_Vc = rf("h0"), rf("V0"), rf("h_c"), rf("V_c")
    cmd_ts, cmd_tr = rf("t_start"), rf("t_ramp")
    cmd_step = np.array([c["nominal_trajectory"].command.kind == "step" for c in cores])

    def command(t: float):
        with np.errstate(divide="ignore", invalid="ignore"):
            f = np.where(
                t < cmd_ts, 0.0, np.where(cmd_step, 1.0, np.minimum(1.0, (t - cmd_ts) / cmd_tr))
            )
        return cmd_h0 + f * (cmd_hc - cmd_h0), cmd_V0 + f * (cmd_Vc - cmd_V0)

    mode = nominal_mode(c0)
    if mode == "governor":
        nominal = _GovernorLanes(cores, command)
    elif mode == "mpc":
        nominal = _MPCLanes(cores)
    else:
        nominal = _PerRunLanes(cores, Ts)

    # states, from the cores as built (initial values exactly those of simulate)
    X = np.stack([c["plant"].plant.x for c in cores], axis=1)  # (9, B)
    X0 = X.copy()
    enabled = nt0.enabled
    if enabled:
        filt = nt0.filter
        Ad, Bd, C_q, D_q = filt._Ad, filt._Bd, filt.C_q, filt.D_q
        XQ = np.stack([c["notch_filter"].filter.x_q for c in cores])
        QP = np.array([c["notch_filter"].filter._q_prev for c in cores], dtype=float)
    faults = [c["fault_injector"].fault for c in cores]
    code = np.array([_FAULT_CODES.get(type(f), -1) for f in faults])
    t_on = np.array([f.t_onset for f in faults], dtype=float)
    rho = np.array([f.params.get("rho_f", 1.0) for f in faults], dtype=float)
    bias = np.array([f.bias for f in faults], dtype=float)
    other = np.flatnonzero(code < 0)
    stuck = np.full(B, np.nan)
    stuck_set = np.zeros(B, dtype=bool)
    held = np.zeros((B, 2))
    u = np.zeros((B, 2))

    N = n_steps
    H = {
        "x": np.empty((N, B, 9)),
        "q_f": np.empty((N, B)),
        "x_r": np.empty((N, B, 9)),
        "x_n": np.empty((N, B, n)),
        "u": np.empty((N, B, 2)),
        "u_applied": np.empty((N, B, 2)),
        "h_c": np.empty((N, B)),
        "V_c": np.empty((N, B)),
        "h_g": np.empty((N, B)),
        "V_g": np.empty((N, B)),
        "tube_level": np.empty((N, B)),
        "fault_active": np.empty((N, B), dtype=bool),
    }
    alive = np.ones(B, dtype=bool)
    errors: list = [None] * B
    u_min, u_max = limits.u_min, limits.u_max

    def kill(mask, make_error):
        for b in np.flatnonzero(mask & alive):
            errors[b] = make_error(b)
        alive[mask] = False
        X[:, mask] = X0[:, mask]

    def f_batch(x, uu):
        return cm_rhs(x, uu, vp)

    with np.errstate(all="ignore"):
        for k in range(N):
            t = k * Ts
            bad = ~np.all(np.isfinite(X), axis=0)
            if bad.any():
                kill(bad, lambda b, t=t: RunError(f"plant: state not finite at t = {t:.2f} s"))
            XT = np.ascontiguousarray(X.T)  # (B, 9)
            H["x"][k] = XT
            # notch_filter
            q = XT[:, Q].copy()
            if enabled:
                XQ = _mv(Ad, XQ) + Bd[None, :] * (QP + q)[:, None]
                QP = q
                qf = (np.matmul(XQ[:, None, :], C_q))[:, 0] + D_q * q
            else:
                qf = q
            H["q_f"][k] = qf
            # nominal_trajectory (step k's output; the command u of step k - 1)
            H["h_c"][k], H["V_c"][k] = command(t)
            (hg, vg, xr_k, ur_k, xn_k, un_k), failed = nominal.step(k, XT, u, alive)
            for b, exc in failed:
                mask = np.zeros(B, dtype=bool)
                mask[b] = True
                kill(mask, lambda _b, exc=exc: exc)
            H["h_g"][k], H["V_g"][k] = hg, vg
            H["x_r"][k] = xr_k[:, :9]
            H["x_n"][k] = xn_k
            # controller (ancillary law, eq. 36 / 54)
            xm = XT.copy()
            if enabled:
                xm[:, Q] = qf
            if n == 11:
                xm = np.concatenate([xm, XQ], axis=1)
            e = np.ascontiguousarray(xm - xr_k - xn_k)
            u = (ur_k + un_k) + _mv(tauF, e)
            H["u"][k] = u
            H["tube_level"][k] = _quad(e, N_inv) / tau2
            # fault_injector
            act = (code != 0) & (t >= t_on - 1e-12)
            ua = u.copy()
            sel = act & (code == 1)
            ua[sel, DELTA_E] = rho[sel] * ua[sel, DELTA_E]
            sel = act & (code == 2)
            ua[sel, DELTA_E] += bias[sel]
            sel = act & (code == 3)
            new = sel & ~stuck_set
            stuck[new] = held[new, DELTA_E] if k > 0 else ua[new, DELTA_E]
            stuck_set |= sel
            ua[sel, DELTA_E] = stuck[sel]
            if k > 0:
                sel = act & (code == 4)
                ua[sel] = held[sel]
            for b in other:  # a fault kind without a batched form: its own injector
                ua[b] = c_apply(cores[b], t, u[b])
            held = ua.copy()
            H["u_applied"][k] = ua
            for b in other:
                act[b] = faults[b].active(t)
            H["fault_active"][k] = act
            # plant: saturated input held over [t_k, t_k+1], RK4
            us = np.clip(ua, u_min, u_max)
            bad = np.isnan(us).any(axis=1)
            if bad.any():
                kill(bad, lambda b, ua=ua: ValueError(f"plant input must be finite, got {ua[b]!r}"))
                us[bad] = u_min
            X = rk4_step(f_batch, X, np.ascontiguousarray(us.T), Ts, n_sub)
    out: list = []
    t_arr = np.array([k * Ts for k in range(N)], dtype=float)  # t_k = k Ts as the plant has it
    for b in range(B):
        if errors[b] is not None:
            out.append(errors[b])
            continue
        out.append(
            RunResult(
                t=t_arr.copy(),
                x=np.ascontiguousarray(H["x"][:, b]),
                q_f=H["q_f"][:, b].copy(),
                x_r=np.ascontiguousarray(H["x_r"][:, b]),
                x_n=np.ascontiguousarray(H["x_n"][:, b]),
                u=np.ascontiguousarray(H["u"][:, b]),
                u_applied=np.ascontiguousarray(H["u_applied"][:, b]),
                h_c=H["h_c"][:, b].copy(),
                V_c=H["V_c"][:, b].copy(),
                h_g=H["h_g"][:, b].copy(),
                V_g=H["V_g"][:, b].copy(),
                tube_level=H["tube_level"][:, b].copy(),
                fault_active=H["fault_active"][:, b].copy(),
                lmi_counts=np.zeros(3, dtype=int),
                qp_counts=_qp_counts(cores[b]),
                info={
                    "variant": info["variant"],
                    "case": info["case"],
                    "Ts": Ts,
                    "fault": info["fault"],
                },  # fmt: skip
            )
        )
    return out


def c_apply(cores: dict, t: float, u: np.ndarray) -> np.ndarray:
    """A fault kind without batched form: one step of the run's own injector."""
    return cores["fault_injector"].injector.apply(t, np.array(u))
