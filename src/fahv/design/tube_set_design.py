"""The eight-state tube set of a case (`tube.form: eight_state`), designed and checked.

From the case's `eight_state` section: the nominal and scheduling boxes
(`fahv.bounds.domain.nominal_box`), the vertices along the nominal
(`fahv.bounds.vertices.nominal_vertices`), the closure of W_8 and Z_8
(`fahv.tube.closure.close_tube_set`), the onset of the design's loss as a
transient (`fahv.onset.bound.onset_bound`) and the loops of the variants that
feed q through a notch (`fahv.tube.notch_loop`, with a gain designed for the loop
when the case asks for one, `designed_notch_loop`). The onset bound and the notch
loops both start from the closed tube set and not from each other: their invariant
ellipsoids (the onset's steady set at each contraction factor, each notch loop) are
Dask tasks spread over the cores' processes.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import replace

import dask
import numpy as np
from dask import delayed

from fahv.bounds.domain import SchedulingBox, nominal_box
from fahv.bounds.one_step_bound import altitude_bound
from fahv.bounds.vertices import NominalVertices, nominal_vertices
from fahv.cluster import active_client
from fahv.control.base import ATTITUDE_BOUND_DEG
from fahv.errors import DesignError
from fahv.onset.bound import (
    STEADY_LAMS,
    onset_bound,
    onset_jumps,
    steady_disturbance,
    steady_set,
)
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.tube.closure import close_tube_set
from fahv.tube.lines import notch_loop_line
from fahv.tube.notch_gain import notch_gain
from fahv.tube.notch_loop import NotchLoop, notch_loop, notch_tube
from fahv.tube.tube_set import EIGHT_STATES, TubeSet


def _state_max(case: dict, log) -> np.ndarray | None:
    """Z_8's largest supports: alpha, theta bounded by the requirement less the QP's rows."""
    if not case["eight_state"]["certify_attitude"]:
        return None
    state_max = np.full(8, np.inf)
    state_max[1:3] = np.radians(ATTITUDE_BOUND_DEG - case["mpc"]["att_max"])
    log(f"eight-state tube: supports in alpha and theta bounded to "
        f"{ATTITUDE_BOUND_DEG - case['mpc']['att_max']:.3f} deg (requirement "
        f"{ATTITUDE_BOUND_DEG} deg less the QP's rows mpc.att_max)")  # fmt: skip
    return state_max


def log_input_rate(nv, tube_set: TubeSet, case: dict, vehicle, log) -> None:
    """The `input rate` line of `fahv verify`, logged by the design that makes the tube set.

    Parameters
    ----------
    nv : NominalVertices
        The vertices along the nominal (`vertices()` gives A (R, 9, 9), B (R, 9, 2)).
    tube_set : TubeSet
        Its F_8 (2, 8), N_8 (8, 8) and W_8 (8,).
    case : dict
        The design file's data (`Ts` [s], `mpc.du_max`).
    vehicle : Vehicle
        Its elevator servo's rate limit (none: no line).
    log : callable
        Receives the line.

    Raises
    ------
    DesignError
        If the tube's part of the elevator command and the plan's rate rows move faster
        than the vehicle's servo (`fahv.certificate.verify.check_input_rate`).
    """
    from fahv.certificate.verify import check_input_rate

    A, B = nv.vertices()
    for check in check_input_rate(A[:, 1:, 1:], B[:, 1:, :], tube_set.F_8, tube_set.N_8,
                                  tube_set.W_8, case, vehicle):  # fmt: skip
        log(check.text())
        if not check.ok:
            raise DesignError(f"certificate failed: {check.line}")


def _contain(case: dict, box, vehicle, trim_map, unc, rho_min: float, log) -> np.ndarray | None:
    """The onset's first jumps J / rho_min, over the level kappa Z_8 may hold them at."""
    kappa = case["eight_state"]["onset_in_tube"]
    if kappa <= 0.0:
        return None
    J, _ = onset_jumps(box, vehicle, trim_map, unc, rho_min, case["Ts"], case["plant_substeps"],
                       interior=1024)  # fmt: skip
    log(f"eight-state tube: the first jumps of a {100 * (1 - rho_min):.1f} % loss at "
        f"{len(J)} box points held in {kappa:g} Z_8 (eight_state.onset_in_tube)")  # fmt: skip
    return J[:, 1:] / rho_min / kappa


def _notch_loops(nv, tube_set: TubeSet, case: dict, notches, stable_only, log, starts=None):
    """The notch variants' loops at the tube set's vertices, and the gains designed.

    `starts` maps `notch_key` to the vertices an earlier design's loop held.
    """
    s, Ts = case["eight_state"], case["Ts"]
    A, B = nv.vertices()
    A_8, B_8, iq = A[:, 1:, 1:], B[:, 1:, :], EIGHT_STATES.index("q")
    loops = tuple(notch_loop(A_8, B_8, tube_set.F_8, nf, Ts, iq, v)
                  for v, nf in (stable_only or {}).items())  # fmt: skip
    gains = {}
    for v, nf in (notches or {}).items():
        loop = notch_tube(A_8, B_8, tube_set.F_8, tube_set.N_8, tube_set.W_8, nf, Ts, iq,
                          tube_set.lam, v, start=(starts or {}).get(notch_key(v)))  # fmt: skip
        if s["notch_gain"] == "designed" and not loop.certified:
            log(f"{notch_loop_line(loop)}; a gain is designed for this loop "
                "(eight_state.notch_gain)")  # fmt: skip
            got = designed_notch_loop(nv, A, B, tube_set, nf, Ts, v, s["notch_continuation"], log)
            if got is not None:
                loop, gains[v] = got
        loops += (loop,)
    return loops, gains


def design_tube_set(
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
    stage: Callable[[str], None] | None = None,
    warm=None,
    starts=None,
    **estimate,
) -> tuple[TubeSet, SchedulingBox, SchedulingBox]:
    """The eight-state tube set of a case (`tube.form: eight_state`), closed and checked.

    Parameters
    ----------
    case : dict
        Validated case data (its `eight_state`, `uncertainty`, `tube.tau`,
        `mpc.M`, `mpc.att_max`, `Ts`, `plant_substeps`).
    vehicle : fahv.model.vehicle.Vehicle
        The nominal vehicle.
    trim_map : fahv.model.trim.TrimMap
    scale : (11,) array_like
        Design scaling (Dx, Du).
    w_max : (9,) array_like
        The sampled W (eq. 19): the row scale of the parameter directions and the unit of
        `eight_state.w0`.
    col_scale : (11,) array_like
        Supports of e and F e over the vertex tube: the column scale of the directions.
    rho_min : float
        Smallest elevator effectiveness (eq. 15) the vertices cover.
    room : (2,) array_like
        Input room of each row with the faulty trim (the tube objective's weights).
    log : callable
    gamma : float, optional
        The case's estimator gain per step: the onset of the design loss is then bounded
        as a transient of the tube set (`fahv.onset.bound.onset_bound`,
        `tube_set.onset`).
    notches : dict, optional
        `{variant: NotchFilter}`: the tube variants that feed q through a notch; their
        loops are certified in their own states at the tube set's vertices
        (`fahv.tube.notch_loop.notch_tube`, a few minutes each;
        `tube_set.notch_loops`).
    stable_only : dict, optional
        `{variant: NotchFilter}`: notch variants whose error filters the measured q
        alone; their loops with F_8 are checked for stability only
        (`fahv.tube.notch_loop.notch_loop`, also in `tube_set.notch_loops`).
    stage : callable, optional
        Told the start of each part (vertices, closure, onset and notch loops): the
        design's progress lines (`fahv.design.stage_clock.StageClock`).
    warm : fahv.synthesis.feedback.ActiveSet, optional
        Where the closure's constraint generation starts (`close_tube_set`).
    starts : Mapping[str, ndarray], optional
        Where the invariant ellipsoids' constraint generation starts: the vertices an
        earlier design's solves held, by `steady_key` and `notch_key`
        (`TubeSet.ellipsoid_vertices`). Like `warm`, it changes how fast the design
        runs, not what is certified.
    **estimate
        `gamma_e`, `directions`, `projection_scale` of
        `fahv.onset.bound.onset_bound` (the estimate's gain along the elevator
        column).

    Returns
    -------
    tube_set : TubeSet
    nominal, box : SchedulingBox
        The nominal box and the scheduling box the tube set is closed over.

    Raises
    ------
    DesignError
        If the boxes are malformed, a plant step leaves the model, or the tube set does
        not close (`fahv.tube.closure.close_tube_set`).
    """
    stage = stage or (lambda name: None)
    s = case["eight_state"]
    nominal, box = nominal_box(s, vehicle.envelope)
    unc = {k: v * case["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    stage("tube set: vertices")
    nv = nominal_vertices(box, vehicle, trim_map, unc, rho_min, case["Ts"],
                          case["plant_substeps"], scale, s["k"], w_max, col_scale)  # fmt: skip
    tau = float(case["tube"]["tau"])
    if tau < 1.0:  # the adjustable law's gains tau' F, tau' in [tau, 1] (eq. 48)
        nv = replace(nv, tau=tau)
    log(f"eight-state tube: {nv.n_vertices} vertices along the nominal (64 scheduling-box "
        f"corners x 2^{s['k']} parameter directions x rho_f in {{{rho_min:g}, 1}}"
        + (f" x the gains tau' F_8 at tau' = {tau:g} and 1 (eq. 48)" if tau < 1.0 else "")
        + f"), {sum(nv.n_vehicles)} vehicles for the residual")  # fmt: skip
    scale = np.asarray(scale, float)
    w_max = np.asarray(w_max, float)
    state_max = _state_max(case, log)
    stage("tube set: closure")
    contain = _contain(case, box, vehicle, trim_map, unc, rho_min, log)
    tube_set = close_tube_set(nv, nominal, s["w0"] * w_max[1:], scale[:9], scale[9:], room,
                              s["lam"], case["mpc"]["M"], grow=s["grow"],
                              iterations=s["iterations"], w_ref=w_max, state_max=state_max,
                              contain=contain, warm=warm, log=log)  # fmt: skip
    log_input_rate(nv, tube_set, case, vehicle, log)
    stage("tube set: onset bound, notch loops")
    parts, lams, n_ellipsoids = _ellipsoid_tasks(
        nv, tube_set, case, box, vehicle, trim_map, unc, rho_min, gamma, notches, starts, estimate
    )
    got = _compute(parts, n_ellipsoids, log)
    return _with_ellipsoids(nv, tube_set, case, got, lams, notches, stable_only, log), nominal, box


def _ellipsoid_tasks(nv, tube_set: TubeSet, case: dict, box, vehicle, trim_map, unc,
                     rho_min: float, gamma, notches, starts, estimate):  # fmt: skip
    """What the closed tube set is checked with, as a graph of Dask tasks.

    The onset's steady set at each contraction factor, then the onset bound from the
    smallest (the longest chain: first, by priority); each notch loop, independent of
    them. Returns the tasks by name, the steady sets' factors and the ellipsoid count.
    """
    parts, lams, n_ellipsoids = {}, (), len(notches or {})
    nv_s = _shared(nv)  # the vertex data once per worker, not in every task
    if gamma is not None:
        bound = steady_disturbance(nv, tube_set, _jump_h(case, box, vehicle, trim_map, unc,
                                                         rho_min), gamma)  # fmt: skip
        A, B = nv.vertices()
        Acl_8 = A[:, 1:, 1:] + B[:, 1:, :] @ tube_set.F_8
        lams = tuple(dict.fromkeys((tube_set.lam, *STEADY_LAMS)))
        Acl_s = _shared(Acl_8)
        with dask.annotate(priority=2):
            steady = [delayed(steady_set)(Acl_s, tube_set.N_8, tube_set.F_8, bound, lam,
                                          (starts or {}).get(steady_key(lam)))
                      for lam in lams]  # fmt: skip
        parts["steady"] = steady
        n_ellipsoids += len(steady)
        with dask.annotate(priority=1):
            parts["onset"] = delayed(onset_bound)(
                nv_s, tube_set, vehicle, trim_map, unc, gamma, case["Ts"], case["plant_substeps"],
                steady_shaped=delayed(_smallest_steady)(steady), **estimate,
            )  # fmt: skip
    for v, nf in (notches or {}).items():
        parts[f"loop {v}"] = delayed(_notch_loops_logged)(nv_s, tube_set, case, {v: nf}, None,
                                                          starts)  # fmt: skip
    return parts, lams, n_ellipsoids


def _shared(obj):
    """`obj` scattered once to every worker of the active Dask client, or `obj` itself.

    The tasks take the future in its place, so that large arrays (the vertex data, tens
    of MB) travel once per worker instead of once per task in the graph. Without a
    distributed client (a library call) the object itself is used.
    """
    client = active_client()
    return obj if client is None else client.scatter(obj, broadcast=True, hash=False)


def _with_ellipsoids(nv, tube_set: TubeSet, case: dict, got: dict, lams, notches, stable_only,
                     log) -> TubeSet:  # fmt: skip
    """The tube set with its notch loops, onset bound and the ellipsoids' active sets."""
    loops, gains = _notch_loops(nv, tube_set, case, None, stable_only, log)  # stability only
    held = {}
    for v in notches or {}:
        got_loops, got_gains, lines = got[f"loop {v}"]
        for line in lines:
            log(line)
        loops, gains = loops + got_loops, {**gains, **got_gains}
        held.update({notch_key(loop.variant): np.asarray(loop.active, int)
                     for loop in got_loops if loop.active})  # fmt: skip
    tube_set = replace(tube_set, notch_loops=loops, notch_gains=gains)
    if "onset" in got:
        held.update({steady_key(lam): active for lam, (_, _, active)
                     in zip(lams, got["steady"], strict=True)})  # fmt: skip
        tube_set = replace(tube_set, onset=got["onset"])
    return replace(tube_set, ellipsoid_vertices=held)


def steady_key(lam: float) -> str:
    """The name of the onset's steady set at contraction factor lam among the ellipsoids.

    Parameters
    ----------
    lam : float
        Contraction factor of the steady set (`fahv.onset.bound.steady_set`).

    Returns
    -------
    str
        `steady_<lam>` (`TubeSet.ellipsoid_vertices`' key; the stored array is
        `ellipsoid_vertices_steady_<lam>`).
    """
    return f"steady_{lam:g}"


def notch_key(variant: str) -> str:
    """The name of a variant's notch loop among the ellipsoids.

    Parameters
    ----------
    variant : str
        A notch variant's name (`fahv.tube.notch_loop.notch_tube`).

    Returns
    -------
    str
        `notch_<variant>`, as `steady_key`.
    """
    return f"notch_{variant}"


def _compute(parts: dict, n_ellipsoids: int, log):
    """The tasks `parts` computed on the active Dask client, or on the cores' processes.

    A distributed client (`fahv design` starts one: a LocalCluster, or `--scheduler`)
    honours the tasks' priorities; without one (a library call), the local process
    scheduler takes them in its own order.
    """
    client = active_client()
    if client is not None:
        log(f"eight-state tube: the onset bound and the notch loops, {n_ellipsoids} invariant "
            f"ellipsoids, on {len(client.scheduler_info()['workers'])} Dask workers")  # fmt: skip
        return dask.compute(parts, scheduler=client, optimize_graph=False)[0]
    workers = min(n_ellipsoids, os.cpu_count() or 1)
    if workers > 1:  # the cores' processes take the tasks in turn
        log(f"eight-state tube: the onset bound and the notch loops, {n_ellipsoids} invariant "
            f"ellipsoids, on {workers} processes")  # fmt: skip
        return dask.compute(parts, scheduler="processes", num_workers=workers)[0]
    return dask.compute(parts, scheduler="sync")[0]


def _smallest_steady(steady) -> float:
    """The smallest c_w of the steady sets (`fahv.onset.bound.steady_set` results)."""
    return min(c_w for c_w, _, _ in steady)


def _jump_h(case: dict, box, vehicle, trim_map, unc, rho_min: float) -> float:
    """[ft] The largest altitude jump |J_h| / rho_min of the design loss's onset."""
    J, _ = onset_jumps(box, vehicle, trim_map, unc, rho_min, case["Ts"], case["plant_substeps"],
                       interior=1024)  # fmt: skip
    return float(np.abs(J[:, 0]).max() / rho_min)


def _notch_loops_logged(nv, tube_set: TubeSet, case: dict, notches, stable_only, starts=None):
    """`_notch_loops` with its log lines returned (it may run in another process)."""
    lines: list[str] = []
    loops, gains = _notch_loops(nv, tube_set, case, notches, stable_only, lines.append, starts)
    return loops, gains, lines


def designed_notch_loop(
    nv: NominalVertices,
    A,
    B,
    tube_set: TubeSet,
    notch,
    Ts: float,
    variant: str,
    continuation=(),
    log: Callable[[str], None] = print,
) -> tuple[NotchLoop, np.ndarray] | None:
    """A gain designed for the tube set's loop through the notch, closed on W_8 (or None).

    The loop u - v = F e' through the notch (`fahv.tube.notch_gain.notch_gain`,
    from F_8, with the tube set's Z_8 and tightening) keeps e_8 in Z_8 and the applied
    input within the tightening, but its input deviation is K xi, not F_8 e_8: W_8's
    bound over the product set is therefore recomputed for the loop's own joint set of
    (e_8, u - v) (`fahv.bounds.one_step_bound.altitude_bound` with `joint`); the
    loop is closed if its altitude bound is at most the tube set's H (the scheduling box
    holds that) and its bound lies inside W_8 (`NotchLoop.w_ratio` = (H / the tube
    set's H, bound / W_8), every entry <= 1).

    Parameters
    ----------
    nv : NominalVertices
    A, B : (R, 9, 9), (R, 9, 2) ndarray
        The tube set's vertices (`nv.vertices()`).
    tube_set : TubeSet
    notch : fahv.model.notch.NotchFilter
    Ts : float
        Control period [s].
    variant : str
    continuation : sequence of float
        `eight_state.notch_continuation`.
    log : callable

    Returns
    -------
    (NotchLoop, (2, 8) ndarray) or None
        The certified loop's re-check (`designed`, `w_ratio`) and its gain; None if no
        gain was certified and closed at the case's eps_p (the variant keeps F_8).

    Raises
    ------
    DesignError
        As `fahv.tube.notch_gain.notch_gain`.
    """
    iq = EIGHT_STATES.index("q")
    got = notch_gain(A[:, 1:, 1:], B[:, 1:, :], tube_set.F_8, tube_set.N_8, tube_set.W_8, notch,
                     Ts, iq, tube_set.lam, continuation, variant=variant, log=log)  # fmt: skip
    if got is None:
        return None
    ab = altitude_bound(nv, A, B, tube_set.F_8, tube_set.N_8, tube_set.moves,
                        joint=got.joint(notch, Ts, iq))  # fmt: skip
    # h first: the scheduling box was checked to hold |e_h| <= H, the loop's H must not exceed it
    ratio = [ab.H / tube_set.H, *(ab.bound / tube_set.W_8).tolist()]
    loop = replace(got.loop, w_ratio=tuple(ratio))
    log(f"variant {variant}: the designed gain's loop: H {ab.H:.3f} ft (the tube set's "
        f"{tube_set.H:.3f} ft), W_8's bound over its own set / W_8 "
        + " ".join(f"{v:.3f}" for v in loop.w_ratio[1:])
        + "; the onset lines are F_8's loop's, none is computed for this gain")  # fmt: skip
    if not loop.certified:  # the variant keeps F_8 (and its own loop's verdict)
        log(f"{notch_loop_line(loop)}; the variant runs F_8")
        return None
    return loop, got.F
