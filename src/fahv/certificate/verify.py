"""Verification of a stored design: every certificate re-checked from its arrays, no solver.

`fahv design` synthesises (LMIs, the W-Z iteration); this module re-checks what it
certified, from the stored arrays and the current model code, and trusts no solver
status. Each check gives one line with its margin (the distance to the bound it must
respect; negative when it fails):

`model`
    The TP vertices, weighting functions, scales and trim map, rebuilt from the vehicle
    file with the current model code, equal the stored ones (`MODEL_RTOL`). A model
    change that moves the vertices fails here, before any certificate is trusted.
`tightening` (eq. 30)
    The stored tightened input limits equal the true limits less the support of
    tau F Z, sqrt(F_j N F_j') per input, recomputed from F and N.
`tube RPI` (LMI 24)
    Exact worst one-step level of the tube under its gain over every vertex (fault
    vertices included) and every corner of W: at most 1.
`W_8 over the domain`, `scheduling box` (eight-state tube)
    The one-step bound of the nonlinear, perturbed plant over the tube's own domain
    lies inside W_8, and the scheduling box holds the nominal box grown by the tube
    (`check_eight_state`); the exact level is then taken over those vertices.
`input rate` (eight-state tube, a vehicle with a servo rate limit)
    The tube's part of the elevator command over Z_8, W_8 and the vertices, plus the
    nominal plan's rate rows, moves at most the servo's rate limit per step
    (`check_input_rate`; the disturbance estimate's part is not bounded).
`attitude`
    The attitude requirement (0.5 deg) follows from the QP's rows plus the support of Z
    in alpha and theta, where the design claimed it.
`nominal K` (LMI 33-35)
    The nominal ellipsoid E(Q) contracts under K at every vertex and K keeps the
    nominal input inside u_n,max on E(Q).
`terminal set`
    E(Q) is invariant under K at every vertex (the tracking MPC's terminal set).
`RMPC` (Wan & Kothare 2003)
    Every ellipsoid of the baseline's sequence: contraction, input bound, nesting.
`estimate` (a design with an `estimate` section)
    The covariance bound of the loop on the estimate at every vertex pair and the
    attitude and elevator-rate claims with their probability
    (`fahv.certificate.verify_estimate`).

`verify` runs them; `verified_design` caches a pass by content hash
(design hash, code hash, vehicle hash), so that a design is re-checked once per code
version, not once per run.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable, Collection
from functools import cache, partial
from pathlib import Path

import numpy as np
from filelock import FileLock

from fahv.certificate.check_result import CheckResult
from fahv.certificate.eight_state import eight_state_vertices, elevator_rate_step
from fahv.errors import DesignError
from fahv.spec.artefacts import Design, code_hash

#: Relative tolerance of the model check, per array. The model is built on one BLAS
#: thread (`fahv.model.blas`): the rebuild is then bit-identical to the design on
#: one machine (measured 0 for every array with OPENBLAS_NUM_THREADS 1 and 2, numpy
#: imported before or after fahv). Not pinned, two threads moved W_V by 1.02e-8, W_h by
#: 4.4e-14 and A, B by 1.3e-10 (cm_certified); each tolerance is 100 times that, so
#: that another BLAS build or processor cannot refuse a sound design; the scales and
#: the trim map never moved and keep a floor of 1e-10. A model change moves them by far
#: more (a 1e-6 change of A fails).
MODEL_RTOL = {"A": 1e-8, "B": 1e-8, "W_h": 1e-6, "W_V": 1e-6, "Dx": 1e-10, "Du": 1e-10,
              "trim_x": 1e-10, "trim_u": 1e-10}  # fmt: skip
#: Tolerance of the tightening check (the stored limits are the same float expression).
TIGHTENING_RTOL = 1e-9


def rel_diff(a, b) -> float:
    """Largest absolute difference of two arrays over the largest entry of `b`.

    Parameters
    ----------
    a, b : array_like
        The arrays compared (any shape; `b` is the reference).

    Returns
    -------
    float
        max |a - b| / max |b| (0 for empty arrays, inf when the shapes differ).

    Examples
    --------
    >>> rel_diff([1.0, 2.0], [1.0, 2.0 + 1e-9]) < 1e-9, rel_diff([1.0], [1.0, 2.0])
    (True, inf)
    """
    a, b = np.asarray(a, float), np.asarray(b, float)
    if a.shape != b.shape:
        return np.inf
    return float(np.max(np.abs(a - b)) / max(np.max(np.abs(b)), 1e-300)) if b.size else 0.0


def check_model(design: Design, vehicle) -> CheckResult:
    """Rebuild the TP model and trim map with the current code; compare with the stored ones."""
    from fahv.model.notch import NotchFilter
    from fahv.model.tp_model import build_tp_model
    from fahv.model.trim import trim_map

    c, a = design.case, design.arrays
    kind = c["design_model"]
    n = c["notch"]
    notch = (
        NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], n["eps_p"]) if kind == "ecm" else None
    )
    tp = build_tp_model(vehicle, kind, *c["vertices"], *c["samples"], notch)
    disc = tp.discretize(c["Ts"])
    tm = trim_map(vehicle, *c["trim_grid"], kind, notch)
    got = {"A": disc.A, "B": disc.B, "W_h": tp.W_h, "W_V": tp.W_V, "Dx": tp.state_scale,
           "Du": tp.input_scale, "trim_x": tm.x_r, "trim_u": tm.u_r}  # fmt: skip
    diffs = {k: rel_diff(v, a[k]) for k, v in got.items()}
    worst = max(diffs, key=lambda k: diffs[k] / MODEL_RTOL[k])  # closest to its tolerance
    ok = all(diffs[k] <= MODEL_RTOL[k] for k in diffs)
    return CheckResult(
        "model", ok, MODEL_RTOL[worst] - diffs[worst],
        f"TP vertices, weights, scales and trim map rebuilt with the current model code: "
        f"relative difference {diffs[worst]:.2e} ({worst}) <= {MODEL_RTOL[worst]:g} (the "
        f"array closest to its tolerance)",
    )  # fmt: skip


def check_tightening(design: Design, vehicle) -> CheckResult:
    """The stored tightened limits u_lo, u_hi against the limits less tau sqrt(F_j N F_j')."""
    a, tau = design.arrays, float(design.case["tube"]["tau"])
    F, N = np.asarray(a["F"], float), np.asarray(a["N"], float)
    support = tau * np.sqrt(np.einsum("jn,nm,jm->j", F, N, F))
    lo = vehicle.limits.u_min + support
    hi = vehicle.limits.u_max - support
    diff = max(rel_diff(lo, a["u_lo"]), rel_diff(hi, a["u_hi"]))
    empty = bool(np.any(hi <= lo))
    ok = diff <= TIGHTENING_RTOL and not empty
    return CheckResult(
        "tightening", ok, TIGHTENING_RTOL - diff,
        f"eq. (30): stored limits vs true limits less tau F Z (support {support[0]:.4f} / "
        f"{np.degrees(support[1]):.3f} deg): relative difference {diff:.1e} <= "
        f"{TIGHTENING_RTOL:g}; tightened set {'EMPTY' if empty else 'non-empty'}",
    )  # fmt: skip


def check_tube_rpi(design: Design) -> CheckResult:
    """Exact worst one-step level of the vertex tube over the fault vertices and W's corners."""
    from fahv.bounds.vertices import fault_vertices, gain_vertices
    from fahv.synthesis.rpi_level import worst_level

    a, c = design.arrays, design.case
    rho = float(design.summary["tube"]["rho_f"])
    tau = float(c["tube"]["tau"])
    Af, Bf = fault_vertices(a["A"], a["B"], rho)
    At, Bt = gain_vertices(Af, Bf, tau)
    level, _ = worst_level(At, Bt, a["F"], a["N"], a["w_max"])
    return CheckResult(
        "tube RPI", level <= 1.0, 1.0 - level,
        f"LMI (24) re-checked exactly: worst one-step level over {At.shape[0]} vertices "
        f"(rho_f in {{{rho:g}, 1}}{f', gains tau F, tau = {tau:g}' if tau < 1 else ''}) and "
        f"every corner of W = {level:.6f} <= 1",
    )  # fmt: skip


def check_nominal(design: Design) -> CheckResult:
    """E(Q) contracts under K at every vertex (34') and K respects u_n,max on E(Q) (35)."""
    from fahv.synthesis.lmi import scale_vertices
    from fahv.synthesis.nominal import contraction, input_ratio

    a = design.arrays
    Dx, Du = np.asarray(a["Dx"], float), np.asarray(a["Du"], float)
    As, Bs = scale_vertices(a["A"], a["B"], Dx, Du)
    Qs = a["Q"] / np.outer(Dx, Dx)
    Ks = a["K"] * Dx[None, :] / Du[:, None]
    con = float(contraction(As, Bs, Ks, Qs))
    ratio = float(np.max(input_ratio(a["K"], a["Q"], a["u_n_max"])))
    ok = con < 1.0 and ratio <= 1.0 + 1e-6
    return CheckResult(
        "nominal K",
        ok,
        min(1.0 - con, 1.0 - ratio),
        f"LMI (33-35'): contraction {con:.6f} < 1, input ratio {ratio:.4f} <= 1",
    )


def check_terminal(design: Design) -> CheckResult:
    """E(Q) invariant under K at every vertex: the terminal set of the tracking MPC."""
    from fahv.model.trim import TrimMap
    from fahv.synthesis.nominal import verify_terminal

    a = design.arrays
    step = design.summary.get("design_step") or {}
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    path = np.array([tm(step["h0"], step["V0"])[1], tm(step["h_c"], step["V_c"])[1]])
    try:
        cert = verify_terminal(a["A"], a["B"], a["K"], a["Q"], a["u_lo"], a["u_hi"], path)
    except DesignError as exc:
        return CheckResult("terminal set", False, -1.0, str(exc))
    inv = float(cert["invariance"])
    return CheckResult(
        "terminal set",
        inv <= 1.0,
        1.0 - inv,
        f"E(Q) invariant under K at every vertex: norm {inv:.6f} <= 1",
    )


def check_rmpc(design: Design) -> CheckResult:
    """Every ellipsoid of the RMPC baseline's sequence re-checked (Wan & Kothare 2003)."""
    from fahv.synthesis.offline_rmpc import EllipsoidSequence, verify_sequence

    a, r = design.arrays, design.case["rmpc"]
    seq = EllipsoidSequence(a["rmpc_Q"], a["rmpc_P"], a["rmpc_K"], a["rmpc_gamma"],
                            a["rmpc_z"], a["rmpc_Ds"], a["u_room"])  # fmt: skip
    try:
        cert = verify_sequence(a["rmpc_A"], a["rmpc_B"], seq, np.asarray(r["psi"], float),
                               np.full(2, float(r["sigma"])))  # fmt: skip
    except DesignError as exc:
        return CheckResult("RMPC", False, -1.0, str(exc))
    con = float(np.max(cert["contraction"]))
    ratio = float(np.max(cert["input_ratio"]))
    nest = float(np.max(cert["nesting"], initial=0.0))
    ok = con < 1.0 and ratio <= 1.0 + 1e-6 and nest < 1.0
    return CheckResult(
        "RMPC", ok, min(1.0 - con, 1.0 - ratio, 1.0 - nest),
        f"{seq.Q.shape[0]} ellipsoids on the {a['rmpc_A'].shape[0]}-vertex DM: contraction "
        f"<= {con:.7f} < 1, input ratio <= {ratio:.4f} <= 1, nesting <= {nest:.4f} < 1",
    )  # fmt: skip


def check_attitude(design: Design) -> CheckResult:
    """The attitude requirement from the tube: the QP's rows plus Z's support in alpha, theta.

    Recomputes the support sqrt(N_jj) and the rows' bounds from the stored N and the
    design's `mpc.att_max` (`fahv.control.mpc.attitude.attitude_bounds`), compares
    the rows with the stored ones, and states whether the requirement follows from the
    certificate, as the design claimed. A design that claimed it must still have it; one
    that did not (the paper's) is reported, not failed.
    """
    from fahv.control.mpc.attitude import attitude_bounds

    a, c = design.arrays, design.case
    offset = float(a["att_trim_offset"]) if "att_trim_offset" in a else 0.0
    att = attitude_bounds(a["N"], c["mpc"]["att_max"], offset)
    same = np.allclose(att.used, a["att_max"], rtol=0, atol=1e-15)
    claimed = bool((c.get("eight_state") or {}).get("certify_attitude", False))
    margin = float(np.min(att.certified - att.used))
    ok = same and (att.is_certified or not claimed)
    sup = np.degrees(att.support)
    verdict = "follows from the certificate" if att.is_certified else "NOT certified (as stated)"
    return CheckResult(
        "attitude", ok, margin if att.is_certified else 0.0,
        f"support of Z {sup[0]:.3f} / {sup[1]:.3f} deg under QP rows at "
        f"{np.degrees(att.used[0]):.3f} deg (requirement 0.5 deg): {verdict}"
        + ("" if same else "; the stored rows differ from the recomputed ones"),
    )  # fmt: skip


def checks_of(design: Design, vehicle) -> list[tuple[str, Callable[[], object]]]:
    """The checks that apply to a design (by its tube form and its variants' laws).

    Returns
    -------
    list of (str, callable)
        The certificate's name and its check bound to its arguments; calling it gives a
        `CheckResult` or a list of them.
    """
    from fahv.control import VARIANTS

    laws = {VARIANTS[v].law for v in design.case["variants"]}
    out = [
        ("model", partial(check_model, design, vehicle)),
        ("tightening", partial(check_tightening, design, vehicle)),
    ]
    # the eight-state vertices (most of a re-check's time) built once for every check
    vertices = cache(partial(eight_state_vertices, design, vehicle))
    if design.case["tube"]["form"] == "eight_state":
        out.append(("eight-state tube", partial(check_eight_state, design, vehicle, vertices)))
    else:
        out.append(("tube RPI", partial(check_tube_rpi, design)))
    if "att_max" in design.arrays and "mpc" in design.case:
        out.append(("attitude", partial(check_attitude, design)))
    if design.case.get("estimate") and "estimate_Sigma" in design.arrays:
        from fahv.certificate.verify_estimate import check_estimate

        out.append(("estimate", partial(check_estimate, design, vehicle, vertices)))
    out.append(("nominal K", partial(check_nominal, design)))
    if "K" in design.arrays and "Q" in design.arrays:
        out.append(("terminal set", partial(check_terminal, design)))
    if "rmpc" in laws:
        out.append(("RMPC", partial(check_rmpc, design)))
    return out


def check_eight_state(design: Design, vehicle, vertices=None) -> list[CheckResult]:
    """The eight-state tube's certificate over its own domain, from the stored F_8, N_8, W_8.

    The vertices along the nominal over the scheduling box are rebuilt from the design
    file's `eight_state` section with the current model code (the sampled W and the
    column scale of the parameter directions are the stored ones); F_8, N_8 are the
    stored F, N without their h row and column, W_8 the stored certificate's. Three
    lines: the one-step bound of the nonlinear plant over the domain inside W_8 (every
    row), the scheduling box holding the nominal box grown by the tube, and the exact
    worst one-step level of Z_8 (LMI 24 re-checked exactly); a fourth with the elevator
    servo's rate limit (`check_input_rate`). `vertices`, if given, returns the vertices
    (`fahv.certificate.eight_state.eight_state_vertices`, built once by `checks_of`).
    """
    from fahv.bounds.domain import box_shortfall, nominal_box
    from fahv.bounds.one_step_bound import altitude_bound
    from fahv.synthesis.rpi_level import worst_level

    a, c, s = design.arrays, design.case, design.summary
    cert = s["certificate"]
    nominal, _ = nominal_box(c["eight_state"], vehicle.envelope)
    nv, A, B = vertices() if vertices is not None else eight_state_vertices(design, vehicle)
    F_8, N_8 = np.asarray(a["F"], float)[:, 1:], np.asarray(a["N"], float)[1:, 1:]
    W_8 = np.asarray(cert["W_8"], float)
    ab = altitude_bound(nv, A, B, F_8, N_8, int(cert["moves"]))
    ratio = ab.bound / W_8
    short = box_shortfall(nv.box, nominal, F_8, N_8, ab.H)
    level, _ = worst_level(A[:, 1:, 1:], B[:, 1:, :], F_8, N_8, W_8)
    return [
        CheckResult(
            "W_8 over the domain", bool(np.all(ratio <= 1.0)), float(1.0 - ratio.max()),
            f"one-step bound of the nonlinear plant over {A.shape[0]} vertices along the "
            f"nominal (scheduling box, uncertainty box corners, rho_f in "
            f"{{{s['tube']['rho_f']:g}, 1}}) / W_8 per row: "
            + " ".join(f"{r:.3f}" for r in ratio) + f" <= 1 (H = {ab.H:.2f} ft)",
        ),
        CheckResult(
            "scheduling box", not short, 0.0 if not short else -max(short.values()),
            "the scheduling box holds the nominal box grown by the tube"
            + ("" if not short else ": short by " + ", ".join(f"{k} {v:.3g}"
                                                                for k, v in short.items())),
        ),
        CheckResult(
            "tube RPI", level <= 1.0, 1.0 - level,
            f"Z_8 (LMI 24 along the nominal) re-checked exactly: worst one-step level over "
            f"{A.shape[0]} vertices and every corner of W_8 = {level:.6f} <= 1",
        ),
    ] + check_input_rate(A[:, 1:, 1:], B[:, 1:, :], F_8, N_8, W_8, c, vehicle)  # fmt: skip


def check_input_rate(A_8, B_8, F_8, N_8, W_8, case: dict, vehicle) -> list[CheckResult]:
    """The elevator command's rate against the servo's (`fahv.bounds.input_rate.law_rate`).

    The tube's part F e over Z_8, W_8 and the vertices, plus the nominal plan's rate rows
    (`mpc.du_max`), against the elevator servo's rate limit times Ts (the vehicle file's
    `actuators.second_order`). The nominal input's disturbance-estimate part is not
    bounded (the line says so).

    Parameters
    ----------
    A_8, B_8 : (R, 8, 8), (R, 8, 2) ndarray
        Vertex matrices of the eight states after h.
    F_8, N_8, W_8 : (2, 8), (8, 8), (8,) ndarray
        The tube gain, Z_8's shape and W_8 (state units, inputs [Phi, delta_e rad]).
    case : dict
        The design file's data (`Ts` [s], `mpc.du_max` [-, deg]).
    vehicle : fahv.model.vehicle.Vehicle
        Its `actuators` give the servo.

    Returns
    -------
    list of CheckResult
        One line; none when the vehicle file gives no finite elevator rate limit.
    """
    from fahv.bounds.input_rate import law_rate

    limit = float(np.degrees(elevator_rate_step(vehicle, float(case["Ts"]))))
    if not np.isfinite(limit):
        return []
    r = law_rate(A_8, B_8, F_8, N_8, W_8, float((case.get("tube") or {}).get("tau", 1.0)))
    tube, plan = float(np.degrees(r.per_step[1])), float((case.get("mpc") or {}).get(
        "du_max", (0.0, 0.0))[1])  # fmt: skip
    total = tube + plan
    return [CheckResult(
        "input rate", bool(total <= limit), 1.0 - total / limit,
        f"the tube's part of the delta_e command moves at most {tube:.3f} deg per step over "
        f"{A_8.shape[0]} vertices (Z_8 {np.degrees(r.over_z[1]):.3f}, W_8 "
        f"{np.degrees(r.over_w[1]):.3f}), with the nominal plan's rate rows {plan:.3f}: "
        f"{total:.3f} <= {limit:.3f} deg per step of the servo; the disturbance estimate's "
        "part of the nominal input is not bounded",
    )]  # fmt: skip


def verify(design: Design, vehicle, log: Callable[[str], None] = print,
           only: Collection[str] | None = None) -> list[CheckResult]:  # fmt: skip
    """Re-check every certificate of a stored design (module docstring); log each line.

    Parameters
    ----------
    design : Design
        A stored design (its `case` is the design file's data).
    vehicle : fahv.model.vehicle.Vehicle
        The vehicle the design was made for.
    log : callable
        Receives one line per check.
    only : collection of str, optional
        Names of the checks to run (the names `checks_of` gives), e.g. {"model"}; default
        every check that applies.

    Returns
    -------
    list of CheckResult
        In the order checked; the caller decides what a failure means
        (`require_verified` raises).

    Raises
    ------
    ValueError
        If `only` names a check that does not apply to the design (naming those that do).
    """
    checks = checks_of(design, vehicle)
    if only is not None:
        unknown = set(only) - {name for name, _ in checks}
        if unknown:
            raise ValueError(f"no check {sorted(unknown)} applies to this design; its "
                             f"checks: {', '.join(name for name, _ in checks)}")  # fmt: skip
        checks = [(name, check) for name, check in checks if name in only]
    out = []
    for name, check in checks:
        try:
            res = check()
        except (KeyError, ValueError, np.linalg.LinAlgError) as exc:
            res = CheckResult(name, False, -np.inf,
                              f"could not be re-checked: {type(exc).__name__}: {exc}")  # fmt: skip
        for r in res if isinstance(res, list) else [res]:
            log(r.text())
            out.append(r)
    return out


def require_verified(results: list[CheckResult], name: str) -> None:
    """Raise `DesignError` naming every failed certificate of design `name`."""
    bad = [r for r in results if not r.ok]
    if bad:
        raise DesignError(
            f"design {name} does not verify: "
            + "; ".join(f"{r.name} ({r.line})" for r in bad)
            + "; re-make it with `fahv design` on its design file"
        )


def verdict_key(design: Design, vehicle) -> str:
    """Content hash a verification verdict holds for: design, code and vehicle hashes."""
    text = json.dumps([design.summary["design_hash"], code_hash(), vehicle.data_hash])
    return hashlib.sha256(text.encode()).hexdigest()[:16]


def record_pass(design: Design, vehicle, folder: Path, results: list[CheckResult]) -> None:
    """Record a passing verification in `folder` (`folder/.verified-<key>`, `verdict_key`).

    Runs of the same arrays, library code and vehicle file then reuse it
    (`verified_design`). Nothing is recorded in a read-only folder (the next run
    verifies again).

    Parameters
    ----------
    design : Design
    vehicle : Vehicle
    folder : Path
        The design's folder.
    results : list of CheckResult
        The verification's lines, all passing (written to the record).
    """
    mark = Path(folder) / f".verified-{verdict_key(design, vehicle)}"
    try:
        mark.write_text("\n".join(r.text() for r in results) + "\n")
    except OSError:
        pass  # a read-only checkout verifies again next time


def verified_design(design: Design, vehicle, folder: Path, log=print) -> list[CheckResult] | None:
    """Verify a stored design unless a pass for the same content is recorded in `folder`.

    A pass is recorded as `folder/.verified-<key>` (`verdict_key`): it holds
    for these arrays, this library code and this vehicle file only. Processes that
    load the same design at once wait for one verification (a file lock,
    `folder/.verified.lock`; without it in a read-only folder).

    Returns
    -------
    list of CheckResult or None
        The results when verified now; None when a recorded pass was reused.

    Raises
    ------
    DesignError
        If a certificate fails (nothing is recorded then).
    """
    mark = Path(folder) / f".verified-{verdict_key(design, vehicle)}"
    if mark.is_file():
        return None
    # processes loading the same design at once (test workers, nodes, a campaign's
    # workers) wait for one verification; a read-only checkout verifies without the lock
    lock = FileLock(str(Path(folder) / ".verified.lock"))
    try:
        lock.acquire()
    except OSError:
        lock = None
    try:
        if mark.is_file():
            return None
        results = verify(design, vehicle, log)
        require_verified(results, design.summary.get("design_name", str(folder)))
        record_pass(design, vehicle, folder, results)
        return results
    finally:
        if lock is not None:
            lock.release()
