"""`fahv trim`, `tp`, `figures`, `tube`: modelling layer and tube feasibility study."""

from __future__ import annotations

import argparse
import json
import warnings
from pathlib import Path

import numpy as np

from fahv.bounds.disturbance import INPUT_DEVIATIONS, STATE_DEVIATIONS
from fahv.cli.common import add_vehicle_option, progress, shape_arg, vehicle_of
from fahv.errors import FahvError
from fahv.model import figures as plots
from fahv.model.linearize import classify_modes, linearize
from fahv.model.notch import NotchFilter
from fahv.model.tp_model import approximation_error, build_tp_model, offgrid_points
from fahv.model.trim import trim
from fahv.model.vehicle import STATE_NAMES
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.tube.feasibility import tube_feasibility


def cmd_trim(args) -> int:
    """Print the trim at (h, V) or over a grid."""
    veh = vehicle_of(args)
    env = veh.envelope
    if args.grid:
        pts = [
            (h, V)
            for h in np.linspace(env.h_min, env.h_max, args.grid[0])
            for V in np.linspace(env.V_min, env.V_max, args.grid[1])
        ]
    else:
        pts = [(args.h, args.V)]
    rows = []
    for h, V in pts:
        tp = trim(veh, float(h), float(V), args.model)
        rows.append(
            {
                "h_ft": h,
                "V_ft_s": V,
                "alpha_deg": np.degrees(tp.alpha),
                "delta_e_deg": np.degrees(tp.delta_e),
                "Phi": tp.Phi,
                "eta_1": tp.eta_1,
                "eta_2": tp.eta_2,
                "residual_scaled": tp.residual,
            }
        )
    if args.json:
        print(json.dumps(rows, indent=1))
        return 0
    print(f"trim of {args.model.upper()} ({veh.source_file})")
    print(
        f"{'h [ft]':>10} {'V [ft/s]':>10} {'alpha [deg]':>12} {'delta_e [deg]':>14} "
        f"{'Phi':>8} {'eta_1':>8} {'eta_2':>8} {'residual':>10}"
    )
    for r in rows:
        print(
            f"{r['h_ft']:10.1f} {r['V_ft_s']:10.2f} {r['alpha_deg']:12.4f} "
            f"{r['delta_e_deg']:14.4f} {r['Phi']:8.5f} {r['eta_1']:8.4f} {r['eta_2']:8.4f} "
            f"{r['residual_scaled']:10.2e}"
        )
    return 0


def _notch_arg(s: str):

    try:
        vals = [float(v) for v in s.split(",")]
        return NotchFilter(*vals)
    except (ValueError, TypeError) as exc:
        raise argparse.ArgumentTypeError(
            f"--notch expects omega_z,eps_z,omega_p,eps_p (e.g. 19.05,0.02,19.05,0.5): {exc}"
        ) from None


def _tp(args, veh, kind, shape, notch=None):

    def bar(it):
        return progress(it, desc=f"linearise {kind.upper()}", unit="pt", leave=False)

    return build_tp_model(
        veh, kind, shape[0], shape[1], args.samples[0], args.samples[1], notch, bar
    )


def cmd_tp(args) -> int:
    """TP transformation report."""
    veh = vehicle_of(args)
    notch = args.notch if args.model == "ecm" else None
    if args.model == "ecm" and notch is None:
        raise FahvError("--model ecm needs --notch omega_z,eps_z,omega_p,eps_p")
    tp = _tp(args, veh, args.model, args.vertices, notch)

    def sample(h, V):
        lm = linearize(veh, h, V, args.model, notch)
        return lm.A, lm.B

    pts = offgrid_points(tp, args.random_points, args.seed)
    err = approximation_error(tp, sample, pts)
    report = {
        "model": args.model,
        "vertices": tp.n_vertices,
        "shape": list(tp.shape),
        "sampling_grid": list(args.samples),
        "singular_values_h": (tp.sv_h[:6] / tp.sv_h[0]).tolist(),
        "singular_values_V": (tp.sv_V[:6] / tp.sv_V[0]).tolist(),
        "max_weight_per_vertex_h": tp.W_h.max(axis=0).tolist(),
        "max_weight_per_vertex_V": tp.W_V.max(axis=0).tolist(),
        "error": err,
    }
    if args.json:
        print(json.dumps(report, indent=1))
        return 0
    print(
        f"TP model of {args.model.upper()}: {tp.shape[0]} x {tp.shape[1]} = {tp.n_vertices} "
        f"vertices, sampled on {args.samples[0]} x {args.samples[1]} points"
    )
    print("normalised singular values of the centred unfoldings:")
    print("  h:", " ".join(f"{s:.2e}" for s in report["singular_values_h"]))
    print("  V:", " ".join(f"{s:.2e}" for s in report["singular_values_V"]))
    print("largest weight reached by each h-vertex:", " ".join(f"{w:.3f}" for w in tp.W_h.max(0)))
    print("largest weight reached by each V-vertex:", " ".join(f"{w:.3f}" for w in tp.W_V.max(0)))
    print(
        f"approximation error over {err['n_points']} off-grid points "
        f"(||S_tp - S||_F / ||S||_F, scaled): max {err['max_rel']:.2e}, "
        f"mean {err['mean_rel']:.2e}; largest scaled entry error {err['max_abs_scaled']:.2e}"
    )
    return 0


def cmd_figures(args) -> int:
    """Write the modelling figures."""
    veh = vehicle_of(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    h, V = args.point
    modes = {
        m.name: m
        for m in classify_modes(
            linearize(veh, h, V, "cm").A, veh.params.omega_1, veh.params.omega_2
        )
    }
    w1, w2 = modes["flexible 1"].wn, modes["flexible 2"].wn
    notch1 = NotchFilter(w1, args.eps_z, w1, 0.5)
    notch2 = NotchFilter(w2, args.eps_z, w2, 0.5)
    written = [
        plots.pole_map(veh, h, V, out / "fig04_pole_map.png"),
        plots.notch_effect(veh, h, V, w1, args.eps_z, out / "fig03_notch_effect.png"),
        plots.notch_modes(
            veh,
            h,
            V,
            {
                f"notch on mode 1 ({w1:.2f} rad/s)": notch1,
                f"notch on mode 2 ({w2:.2f} rad/s)": notch2,
            },
            out / "fig05_notch_modes.png",
        ),
    ]
    ph, pv = args.offgrid
    tp = _tp(args, veh, "dm", (4, 5))
    written.append(plots.bode_model_vs_lpv(veh, tp, ph, pv, out / "fig02_bode_dm_vs_lpv.png"))
    tpe = _tp(args, veh, "ecm", (2, 3), notch1)
    written.append(
        plots.bode_model_vs_lpv(veh, tpe, ph, pv, out / "fig08_bode_ecm_vs_lpv.png", notch1)
    )
    for p in written:
        print(p)
    return 0


def cmd_tube(args) -> int:
    """Tube feasibility study: W by source, F and Z, box tube, input room."""
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    veh = vehicle_of(args)
    rho_f = args.rho_f
    if rho_f is None:  # the effectiveness the case's design covers
        from fahv.design.stages import design_rho_f
        from fahv.spec.scenario import load_run_spec

        rho_f = design_rho_f(load_run_spec(args.case))
        print(f"rho_f = {rho_f:g}: the elevator effectiveness {args.case} designs its tube for")
    tp = _tp(args, veh, args.model, args.vertices)
    Dx = veh.state_scale
    for treatment in args.treatment:

        def bar(it, treatment=treatment):
            return progress(it, desc=f"sample W ({treatment})", leave=False)

        res = tube_feasibility(
            veh,
            tp,
            args.Ts,
            PAPER_UNCERTAINTY,
            rho_f,
            STATE_DEVIATIONS,
            INPUT_DEVIATIONS,
            args.samples_w,
            args.seed,
            args.margin,
            treatment,
            tuple(args.lam),
            progress=bar,
        )
        print(
            f"\n== fault treatment '{treatment}', design model {args.model.upper()} "
            f"({tp.n_vertices} vertices), Ts = {args.Ts} s, {res.W.n_samples} samples =="
        )
        print("W half-widths per step, scaled by the state scales (no margin):")
        print(f"  {'state':>10} " + " ".join(f"{k:>11}" for k in res.W.parts))
        for j, name in enumerate(STATE_NAMES):
            vals = " ".join(f"{res.W.parts[k][j] / Dx[j]:11.4g}" for k in res.W.parts)
            print(f"  {name:>10} {vals}")
        if res.tube is None:
            print(f"tube: no certified tube: {res.error}")
            continue
        t = res.tube
        print(
            f"tube: ellipsoid, lam = {t.lam}, certificate min eigenvalue "
            f"{t.min_eigs.min():.2e} over {t.min_eigs.size} vertices (verified)"
        )
        print("  bounding box of Z / scale:", " ".join(f"{v:.3g}" for v in t.z_box / Dx))
        print(
            f"  attitude bounds: alpha {np.degrees(t.z_box[2]):.3f} deg, "
            f"theta {np.degrees(t.z_box[3]):.3f} deg"
        )
        print(
            f"  input room {res.room[0]:.4f} / {np.degrees(res.room[1]):.3f} deg; "
            f"tightening max|F e| {t.tightening[0]:.4f} / "
            f"{np.degrees(t.tightening[1]):.3f} deg; left for the nominal input "
            f"{res.nominal_room[0]:.4f} / {np.degrees(res.nominal_room[1]):.3f} deg"
        )
        b = res.box
        print(
            f"  paper's box tube (eq. 25-28): {'feasible' if b.feasible else 'infeasible'}; "
            f"max rho(|A_i + B_i F|) = {b.spectral_radius_abs.max():.3f}"
        )
    return 0


def add_parsers(sub) -> None:
    """Add the parsers of this command group."""
    p = sub.add_parser("trim", help="trim table (eq. 5) at a point or over a grid")
    add_vehicle_option(p)
    p.add_argument("--h", type=float, default=85500.0, help="altitude [ft]")
    p.add_argument("--V", type=float, default=7900.0, help="speed [ft/s]")
    p.add_argument(
        "--grid",
        type=int,
        nargs=2,
        metavar=("NH", "NV"),
        help="trim over an NH x NV grid of the envelope instead",
    )
    p.add_argument("--model", choices=("dm", "cm"), default="dm")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=cmd_trim)
    p = sub.add_parser("tp", help="TP model transformation report (eq. 11)")
    add_vehicle_option(p)
    p.add_argument("--model", choices=("dm", "cm", "ecm"), default="dm")
    p.add_argument("--vertices", type=shape_arg, default=(4, 5), metavar="RHxRV")
    p.add_argument("--samples", type=shape_arg, default=(21, 21), metavar="NHxNV")
    p.add_argument("--notch", type=_notch_arg, default=None, metavar="omega_z,eps_z,omega_p,eps_p")
    p.add_argument("--random-points", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_tp)
    p = sub.add_parser("figures", help="modelling figures (paper Fig. 2, 3, 4, 5, 8)")
    add_vehicle_option(p)
    p.add_argument("--out", default="docs/figures", help="output folder")
    p.add_argument(
        "--point",
        type=float,
        nargs=2,
        default=(85500.0, 7900.0),
        metavar=("H", "V"),
        help="flight condition of Fig. 3-5",
    )
    p.add_argument(
        "--offgrid",
        type=float,
        nargs=2,
        default=(85730.0, 8013.0),
        metavar=("H", "V"),
        help="off-grid flight condition of Fig. 2 and 8",
    )
    p.add_argument("--eps-z", type=float, default=0.02, help="notch numerator damping")
    p.add_argument("--samples", type=shape_arg, default=(21, 21), metavar="NHxNV")
    p.set_defaults(func=cmd_figures)
    p = sub.add_parser("tube", help="tube feasibility study: W (eq. 19), F, Z, eq. (30)")
    add_vehicle_option(p)
    p.add_argument("--model", choices=("dm", "cm"), default="cm", help="LPV design model")
    p.add_argument("--vertices", type=shape_arg, default=(4, 5), metavar="RHxRV")
    p.add_argument("--samples", type=shape_arg, default=(21, 21), metavar="NHxNV")
    p.add_argument("--Ts", type=float, default=0.02, help="sampling period [s]")
    p.add_argument(
        "--rho-f",
        type=float,
        default=None,
        help="elevator effectiveness (default: the one the case's tube is designed for)",
    )
    p.add_argument(
        "--case",
        default="offline_design/scenarios/case1.yaml",
        help="case whose design effectiveness is the default of --rho-f",
    )
    p.add_argument("--samples-w", type=int, default=300, help="samples bounding W")
    p.add_argument("--margin", type=float, default=1.2, help="margin on the sampled W")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--lam", type=float, nargs="+", default=[0.98, 0.99, 0.995])
    p.add_argument(
        "--treatment", nargs="+", choices=("box", "polytopic"), default=["box", "polytopic"]
    )
    p.set_defaults(func=cmd_tube)
