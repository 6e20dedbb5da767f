"""The ``fahv`` command line.

Subcommands::

    fahv trim      trim table at a point or over a grid of the envelope
    fahv tp        TP model transformation report (singular values, error)
    fahv figures   modelling figures (paper Fig. 2, 3, 4, 5, 8) as PNG
    fahv tube      tube feasibility study (W by source, F, Z, input room)
    fahv design    offline design of a case file: certified artefacts + ROS parameters
    fahv simulate  in-process closed loop of a case: metrics table per variant
    fahv sil       the ROS 2 node graph of a case in lockstep, recorded to MCAP
    fahv plot      paper-style figures of recorded runs, overlaid
    fahv paper-figures   Fig. 9-17 of the paper from Cases 1 and 2
    fahv inspect   topics, metadata, step anomalies and metrics of a run
    fahv export    one CSV / Parquet table per topic, with units
    fahv compare   metrics of two runs side by side
    fahv replay    republish a run over DDS, e.g. into a fresh tube_mpc node

Every command that uses the vehicle takes ``--vehicle FILE``. Errors name the
input at fault and exit with status 2 (bad input) or 1 (failure).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
from tqdm import tqdm

from fahv.errors import FahvError


def _vehicle(args):
    from fahv.vehicle import load_vehicle

    return load_vehicle(args.vehicle)


def _add_vehicle(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--vehicle",
        metavar="FILE",
        default=None,
        help="vehicle data file (YAML); default: the packaged Parker 2007 curve fit "
        "with representative flexible data",
    )


def cmd_trim(args) -> int:
    """Print the trim at (h, V) or over a grid."""
    from fahv.trim import trim

    veh = _vehicle(args)
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
    from fahv.notch import NotchFilter

    try:
        vals = [float(v) for v in s.split(",")]
        return NotchFilter(*vals)
    except (ValueError, TypeError) as exc:
        raise argparse.ArgumentTypeError(
            f"--notch expects omega_z,eps_z,omega_p,eps_p (e.g. 19.05,0.02,19.05,0.5): {exc}"
        ) from None


def _shape(s: str) -> tuple[int, int]:
    try:
        a, b = (int(v) for v in s.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected AxB (e.g. 4x5), got {s!r}") from None
    return a, b


def _tp(args, veh, kind, shape, notch=None):
    from fahv.tp_model import build_tp_model

    def bar(it):
        return tqdm(it, desc=f"linearise {kind.upper()}", unit="pt", leave=False, disable=None)

    return build_tp_model(
        veh, kind, shape[0], shape[1], args.samples[0], args.samples[1], notch, bar
    )


def cmd_tp(args) -> int:
    """TP transformation report."""
    from fahv.tp_model import approximation_error, offgrid_points

    veh = _vehicle(args)
    notch = args.notch if args.model == "ecm" else None
    if args.model == "ecm" and notch is None:
        raise FahvError("--model ecm needs --notch omega_z,eps_z,omega_p,eps_p")
    tp = _tp(args, veh, args.model, args.vertices, notch)
    from fahv.linearize import linearize

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
    from fahv import plots
    from fahv.linearize import classify_modes, linearize
    from fahv.notch import NotchFilter

    veh = _vehicle(args)
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
    import warnings

    from fahv.plant import PAPER_UNCERTAINTY
    from fahv.tube.disturbance import DEFAULT_DEV_BOX, DEFAULT_DU_BOX
    from fahv.tube.feasibility import tube_feasibility
    from fahv.vehicle import STATE_NAMES

    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    veh = _vehicle(args)
    tp = _tp(args, veh, args.model, args.vertices)
    Dx = veh.state_scale
    for treatment in args.treatment:

        def bar(it, treatment=treatment):
            return tqdm(it, desc=f"sample W ({treatment})", leave=False, disable=None)

        res = tube_feasibility(
            veh,
            tp,
            args.Ts,
            PAPER_UNCERTAINTY,
            args.rho_f,
            DEFAULT_DEV_BOX,
            DEFAULT_DU_BOX,
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


def _artefact_dir(case, out):
    return Path(out) if out else Path("offline_design") / "artefacts" / case.name


def cmd_design(args) -> int:
    """Offline design of a case: print every certificate, write the artefacts."""
    import warnings

    from fahv.case import load_case
    from fahv.design import run_design, save_design

    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    case = load_case(args.case)

    def bar(it):
        return tqdm(it, desc="sample W", leave=False, disable=None)

    design = run_design(case, progress=bar)
    out = save_design(design, _artefact_dir(case, args.out))
    print(f"design hash {design.summary['design_hash']}; artefacts written to {out}/")
    return 0


#: Rows of the metrics table: key, label, format.
def _load_or_design(case_path, design_dir):
    """The valid design of a case file, designing it first if missing or outdated."""
    import warnings

    from fahv.case import load_case
    from fahv.design import load_design, run_design, save_design
    from fahv.errors import DesignError

    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    case = load_case(case_path)
    out = _artefact_dir(case, design_dir)
    try:
        design = load_design(out)
        if design.case != _jsonable(case.data):
            raise DesignError("case file changed since the design")
    except DesignError as exc:
        print(f"no valid design in {out} ({exc}); designing first")
        design = run_design(case)
        save_design(design, out)
    return case, design


def _simulate_recorded(design, variant: str, duration, out_dir):
    """simulate() with a progress bar, recorded to ``out_dir/<run>/`` unless it is None.

    The run folder also gets the run's ROS parameter file (``params.yaml``, the same
    a SIL run gets), so ``fahv replay --node ...`` can start nodes against it.
    """
    from fahv.runlog import RunWriter
    from fahv.sil import run_metadata, run_name, write_run_params
    from fahv.sim import simulate

    case = design.case
    desc = f"{case['name']} {variant}"

    def bar(it):
        return tqdm(it, desc=desc, leave=False, disable=None)

    if out_dir is None:
        return simulate(design, variant, duration, progress=bar)
    d = case["duration"] if duration is None else duration
    bag = Path(out_dir) / run_name(case["name"], variant, "sim")
    with RunWriter(bag, run_metadata(design, variant, "simulate", d), case["Ts"]) as writer:
        write_run_params(design, variant, bag, bag / "params.yaml", duration, 10.0)
        run = simulate(design, variant, duration, progress=bar, writer=writer)
    print(f"{desc}: run written to {bag}")
    return run


def cmd_simulate(args) -> int:
    """In-process closed loop of a case; records each variant to bags/, prints metrics."""
    from fahv.sil import ROOT
    from fahv.sim import metrics
    from fahv.vehicle import load_vehicle

    case, design = _load_or_design(args.case, args.design)
    variants = args.variant or case["variants"]
    limits = load_vehicle().limits
    table = {}
    for v in variants:
        out = None if args.no_record else Path(args.out or ROOT / "bags")
        run = _simulate_recorded(design, v, args.duration, out)
        table[v] = metrics(run, limits)
    if args.json:
        print(_json(table))
    else:
        from fahv.runtools import format_metrics

        print(f"case {case.name}, design {design.summary['design_hash']}")
        print(format_metrics(table))
    return 0


def cmd_sil(args) -> int:
    """Run a case through the ROS 2 node graph, recorded to MCAP; metrics of the run."""
    import warnings

    from fahv.runlog import read_run
    from fahv.sil import ROOT, run_sil
    from fahv.sim import metrics, run_result_of
    from fahv.vehicle import load_vehicle

    case, design = _load_or_design(args.case, args.design)
    variant = args.variant or case["variants"][0]
    res = run_sil(
        design,
        variant,
        args.duration,
        Path(args.out or ROOT / "bags"),
        args.watchdog,
        quiet=args.quiet,
    )
    if not res.bag.is_dir():
        print(f"error: the run produced no recording ({res.bag})", file=sys.stderr)
        return 1
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        rec = read_run(res.bag)
    run = run_result_of(rec)
    print(f"run written to {res.bag}")
    print(
        f"status {rec.metadata.get('status', '?')}, {run.t.size} steps, wall time "
        f"{res.wall_s:.1f} s, real-time factor {res.real_time_factor:.2f} "
        f"(simulated {res.simulated_s:g} s)"
    )
    if run.t.size:
        table = {variant: metrics(run, load_vehicle().limits)}
        if args.json:
            print(_json(table))
        else:
            from fahv.runtools import format_metrics

            print(f"case {case.name}, design {design.summary['design_hash']}")
            print(format_metrics(table))
    return 0 if res.returncode == 0 else 1


def _read(path):
    """read_run, its warnings (truncated file) printed to stderr."""
    import warnings

    from fahv.runlog import read_run

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        rec = read_run(path)
    for w in caught:
        print(f"warning: {w.message}", file=sys.stderr)
    return rec


def _json(obj) -> str:
    """Strict JSON (NaN and infinities as null)."""

    def clean(v):
        if isinstance(v, dict):
            return {str(k): clean(x) for k, x in v.items()}
        if isinstance(v, list | tuple):
            return [clean(x) for x in v]
        if isinstance(v, float) and not np.isfinite(v):
            return None
        if isinstance(v, np.generic):
            return clean(v.item())
        return v

    return json.dumps(clean(obj), indent=2)


def cmd_inspect(args) -> int:
    """Topics, metadata, step anomalies and metrics of a recorded run."""
    from fahv.runtools import format_summary, summarize
    from fahv.vehicle import load_vehicle

    s = summarize(_read(args.run), load_vehicle().limits)
    print(_json(s) if args.json else format_summary(s))
    return 0


def cmd_export(args) -> int:
    """One table per loop topic (CSV or Parquet) with a column dictionary."""
    from fahv.runlog import bag_paths
    from fahv.runtools import export_run

    folder, _ = bag_paths(args.run)
    out = Path(args.out) if args.out else folder / f"export_{args.format}"
    for path in export_run(_read(args.run), out, args.format):
        print(path)
    return 0


def cmd_compare(args) -> int:
    """Metrics of two runs side by side with their differences."""
    from fahv.runlog import bag_paths
    from fahv.runtools import compare, format_metrics, summarize
    from fahv.vehicle import load_vehicle

    lim = load_vehicle().limits
    a, b = (summarize(_read(r), lim) for r in (args.a, args.b))
    names = tuple(
        f"{tag}: {s['metadata'].get('variant', bag_paths(r)[0].name)}"
        f" ({s['metadata'].get('source', '?')})"
        for tag, s, r in (("A", a, args.a), ("B", b, args.b))
    )
    c = compare(a, b, names)
    if args.json:
        print(_json(c))
        return 0
    print(f"A = {a['file']}\nB = {b['file']}")
    for k, (va, vb) in c["metadata"].items():
        print(f"  {k}: A {va!s} | B {vb!s}")
    print(format_metrics(c["table"]))
    return 0


def cmd_replay(args) -> int:
    """Republish a recorded run (raw CDR), optionally into nodes under test."""
    from fahv.sil import run_replay

    res = run_replay(
        args.run,
        nodes=args.node or (),
        topics=args.topics,
        capture=args.capture,
        out=args.out,
        rate=0.0 if args.fast else args.rate,
        steps=args.steps,
        watchdog_s=args.watchdog,
        quiet=args.quiet,
    )
    if res.returncode != 0:
        print(f"fahv replay: failed (logs in {res.log_dir})", file=sys.stderr)
        return 1
    if res.out is not None:
        print(f"replayed run written to {res.out}")
    return 0


def cmd_plot(args) -> int:
    """Paper-style figures of one or several recorded runs, overlaid."""
    from fahv.runplots import GROUPS, plot_group
    from fahv.sim import run_result_of

    runs = []
    for path in args.runs:
        rec = _read(path)
        run = run_result_of(rec)
        if run.t.size == 0:
            raise FahvError(f"{path}: no complete step of the loop topics to plot")
        label = (
            f"{rec.metadata.get('variant', Path(path).name)} ({rec.metadata.get('source', '?')})"
        )
        runs.append((label, run))
    out = Path(args.out)
    for group in GROUPS:
        if group == "flexible_rates":
            continue
        print(plot_group(group, runs, out / f"{group}.{args.format}"))
    return 0


def cmd_paper_figures(args) -> int:
    """Simulate every variant of Cases 1 and 2 (recorded) and write Fig. 9-17."""
    from fahv.runplots import paper_figures
    from fahv.sil import ROOT
    from fahv.sim import run_result_of

    runs = {}
    for path in args.runs or []:  # recorded runs (simulated or SIL) instead of new ones
        rec = _read(path)
        key = (rec.metadata.get("case"), rec.metadata.get("variant"))
        if None in key:
            raise FahvError(f"{path}: no case/variant in the run metadata")
        runs[key] = run_result_of(rec)
        print(f"{key[0]} {key[1]}: {path} ({rec.metadata.get('source', '?')})")
    for case_path in [] if args.runs else args.cases:
        case, design = _load_or_design(case_path, None)
        for v in case["variants"]:
            runs[(case.name, v)] = _simulate_recorded(design, v, args.duration, ROOT / "bags")
    for path in paper_figures(runs, args.out):
        print(path)
    return 0


def _jsonable(data):
    return json.loads(json.dumps(data, default=list))


def build_parser() -> argparse.ArgumentParser:
    """Argument parser of the ``fahv`` command."""
    ap = argparse.ArgumentParser(prog="fahv", description=__doc__.split("\n\n")[0])
    sub = ap.add_subparsers(dest="command", required=True)

    p = sub.add_parser("trim", help="trim table (eq. 5) at a point or over a grid")
    _add_vehicle(p)
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
    _add_vehicle(p)
    p.add_argument("--model", choices=("dm", "cm", "ecm"), default="dm")
    p.add_argument("--vertices", type=_shape, default=(4, 5), metavar="RHxRV")
    p.add_argument("--samples", type=_shape, default=(21, 21), metavar="NHxNV")
    p.add_argument("--notch", type=_notch_arg, default=None, metavar="omega_z,eps_z,omega_p,eps_p")
    p.add_argument("--random-points", type=int, default=50)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_tp)

    p = sub.add_parser("figures", help="modelling figures (paper Fig. 2, 3, 4, 5, 8)")
    _add_vehicle(p)
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
    p.add_argument("--samples", type=_shape, default=(21, 21), metavar="NHxNV")
    p.set_defaults(func=cmd_figures)
    p = sub.add_parser("tube", help="tube feasibility study: W (eq. 19), F, Z, eq. (30)")
    _add_vehicle(p)
    p.add_argument("--model", choices=("dm", "cm"), default="cm", help="LPV design model")
    p.add_argument("--vertices", type=_shape, default=(4, 5), metavar="RHxRV")
    p.add_argument("--samples", type=_shape, default=(21, 21), metavar="NHxNV")
    p.add_argument("--Ts", type=float, default=0.02, help="sampling period [s]")
    p.add_argument("--rho-f", type=float, default=0.9, help="elevator effectiveness")
    p.add_argument("--samples-w", type=int, default=300, help="samples bounding W")
    p.add_argument("--margin", type=float, default=1.2, help="margin on the sampled W")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--lam", type=float, nargs="+", default=[0.98, 0.99, 0.995])
    p.add_argument(
        "--treatment", nargs="+", choices=("box", "polytopic"), default=["box", "polytopic"]
    )
    p.set_defaults(func=cmd_tube)
    p = sub.add_parser("design", help="offline design of a case: artefacts + ROS parameters")
    p.add_argument("case", help="case file, e.g. offline_design/case1.yaml")
    p.add_argument("--out", default=None, help="artefact folder (offline_design/artefacts/NAME)")
    p.set_defaults(func=cmd_design)
    p = sub.add_parser("simulate", help="in-process closed loop of a case, metrics table")
    p.add_argument("case", help="case file")
    p.add_argument("--design", default=None, help="artefact folder (designed if missing)")
    p.add_argument("--variant", nargs="+", default=None, help="variants (default: the case's)")
    p.add_argument("--duration", type=float, default=None, help="simulated time [s]")
    p.add_argument("--out", default=None, help="folder of the recorded runs (default bags/)")
    p.add_argument("--no-record", action="store_true", help="do not write the runs to MCAP")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_simulate)
    p = sub.add_parser(
        "sil", help="the ROS 2 node graph of a case in lockstep, recorded to bags/<run>/ (MCAP)"
    )
    p.add_argument("case", help="case file, e.g. offline_design/case1.yaml")
    p.add_argument(
        "--design", default=None, help="artefact folder (default offline_design/artefacts/NAME)"
    )
    p.add_argument("--variant", default=None, help="variant (default: the case's first)")
    p.add_argument("--duration", type=float, default=None, help="simulated time [s]")
    p.add_argument("--out", default=None, help="folder of the recorded runs (default bags/)")
    p.add_argument("--watchdog", type=float, default=10.0, help="node watchdog [s wall time]")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.add_argument("--json", action="store_true", help="metrics as JSON")
    p.set_defaults(func=cmd_sil)
    p = sub.add_parser("plot", help="paper-style figures of recorded runs, overlaid")
    p.add_argument("runs", nargs="+", help="run folders or .mcap files")
    p.add_argument("--out", default="figures", help="output folder")
    p.add_argument("--format", choices=("png", "pdf"), default="png")
    p.set_defaults(func=cmd_plot)
    p = sub.add_parser("inspect", help="topics, metadata, step anomalies and metrics of a run")
    p.add_argument("run", help="run folder or .mcap file")
    p.add_argument("--json", action="store_true", help="machine-readable output")
    p.set_defaults(func=cmd_inspect)
    p = sub.add_parser("export", help="one table per topic (CSV or Parquet) with units")
    p.add_argument("run", help="run folder or .mcap file")
    p.add_argument("--format", choices=("csv", "parquet"), default="csv")
    p.add_argument("--out", default=None, help="output folder (default <run>/export_<format>)")
    p.set_defaults(func=cmd_export)
    p = sub.add_parser("compare", help="metrics of two runs side by side, with differences")
    p.add_argument("a", help="run A (folder or .mcap)")
    p.add_argument("b", help="run B (folder or .mcap)")
    p.add_argument("--json", action="store_true")
    p.set_defaults(func=cmd_compare)
    p = sub.add_parser(
        "replay",
        help="republish a run's loop topics (raw CDR) over DDS, optionally into nodes under test",
    )
    p.add_argument("run", help="run folder or .mcap file")
    p.add_argument("--topics", nargs="+", default=None, help="topics to republish")
    p.add_argument(
        "--node",
        nargs="+",
        default=None,
        help="nodes to test against the replay with the run's parameters (e.g. tube_mpc)",
    )
    p.add_argument(
        "--capture", nargs="+", default=None, help="topics to capture (default: the nodes' outputs)"
    )
    p.add_argument("--out", default=None, help="run folder for the replayed + captured messages")
    p.add_argument("--rate", type=float, default=1.0, help="1: recorded timing, r: r x faster")
    p.add_argument("--fast", action="store_true", help="as fast as possible (lockstep on captures)")
    p.add_argument("--steps", type=int, default=0, help="steps to replay (0: all)")
    p.add_argument("--watchdog", type=float, default=10.0, help="node watchdog [s wall time]")
    p.add_argument("--quiet", action="store_true", help="no progress lines")
    p.set_defaults(func=cmd_replay)
    p = sub.add_parser(
        "paper-figures", help="simulate Cases 1 and 2 (all variants, recorded) and write Fig. 9-17"
    )
    p.add_argument(
        "--cases", nargs="+", default=["offline_design/case1.yaml", "offline_design/case2.yaml"]
    )
    p.add_argument("--duration", type=float, default=None, help="simulated time [s]")
    p.add_argument(
        "--runs", nargs="+", default=None, help="use these recorded runs instead of simulating"
    )
    p.add_argument("--out", default="docs/figures")
    p.set_defaults(func=cmd_paper_figures)
    return ap


def main(argv: list[str] | None = None) -> int:
    """Entry point of ``fahv``; returns the exit status."""
    args = build_parser().parse_args(argv)
    try:
        return args.func(args)
    except (FahvError, ValueError, OSError) as exc:
        print(f"fahv {args.command}: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
