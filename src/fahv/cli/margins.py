"""`fahv margins`: classical loop margins of a stored design, with and without the notch."""

from __future__ import annotations

import time
from dataclasses import replace
from pathlib import Path
from typing import NamedTuple

from fahv.analysis.margin_figures import margin_figures
from fahv.analysis.margin_report import margin_table, meets, notch_summary
from fahv.analysis.margin_study import margin_study
from fahv.cli.common import add_vehicle_option, vehicle_of
from fahv.cli.design import resolve_design_file
from fahv.model.vehicle import load_vehicle
from fahv.sil.workspace import ROOT
from fahv.spec.store import stored_design

#: The design whose table docs/results/margins.md shows (`<!-- margins-table -->`).
DOCS_DESIGN = "cm_certified"


def study_of(design: str, design_dir=None, vehicle=None, every_setting: bool = False):
    """The margin study of a stored design given as `fahv.cli.design.resolve_design_file`.

    Parameters
    ----------
    design : str
        Design or scenario: a file, or a name in offline_design/.
    design_dir : str, optional
        Artefact folder of the stored design.
    vehicle : fahv.model.vehicle.Vehicle, optional
        Default: the packaged vehicle.
    every_setting : bool
        Every notch setting over the LPV vertices (`fahv.analysis.margin_study.margin_study`).

    Returns
    -------
    (MarginStudy, Design, Path)
        The study, the stored design and its folder.

    Raises
    ------
    SpecError, DesignError
        If the design does not resolve, or is missing or stale.
    ValueError
        If it is not a nine-state design.
    """
    vehicle = load_vehicle() if vehicle is None else vehicle
    _, stored, folder = stored_design(resolve_design_file(design), design_dir, vehicle)
    name = stored.summary.get("design_name", folder.name)
    return margin_study(stored, vehicle, every_setting, name=name), stored, folder


def docs_table() -> str:
    """The Markdown table and summary `fahv margins cm_certified --markdown` prints.

    The design file of the repository (`fahv.sil.workspace.ROOT`), for the docs
    build's hook (`docs/hooks/generated.py`, marker `margins-table`).

    Returns
    -------
    str
        The Markdown the command prints, without the timing line.
    """
    study, _, _ = study_of(str(ROOT / "offline_design" / "designs" / f"{DOCS_DESIGN}.yaml"))
    return _markdown(study)


def _markdown(study) -> str:
    """The Markdown of a study: its table, then its notch summary as a list."""
    rows = study.table_rows()
    return margin_table(rows, markdown=True) + "\n\n" + "\n".join(
        f"- {line}" for line in notch_summary(rows))  # fmt: skip


class EstimateLoop(NamedTuple):
    """The law on a scenario's Kalman estimate: its margins and what `--out` draws of it.

    Attributes
    ----------
    rows : list of fahv.analysis.margins.LoopMargins
        `fahv.analysis.estimated_loop.estimated_margins` of every notch setting.
    line : str
        The line that names the filter, the law and the break.
    flt : fahv.estimation.kalman.GainScheduledKalman
        The scenario's filter (`fahv.estimation.kalman.design_filter`).
    settings : list of fahv.analysis.margin_study.NotchSetting
        The notch settings with the law's gain tau F.
    """

    rows: list
    line: str
    flt: object
    settings: list


def estimate_loop(arg: str, study, stored, vehicle, vehicle_file=None) -> EstimateLoop | None:
    """The margins of the law on the Kalman estimate when `arg` is a scenario with one.

    The scenario is read and its filter designed once, for the table and the figure.

    Parameters
    ----------
    arg : str
        The command's argument (a design or a scenario, `resolve_design_file`).
    study : fahv.analysis.margin_study.MarginStudy
        The study of its design (the notch settings; their F scaled by the scenario's
        tau over the design's, eq. 53-54).
    stored : fahv.spec.artefacts.Design
    vehicle : fahv.model.vehicle.Vehicle
    vehicle_file : str, optional
        Its file, which holds the sensors' data (the packaged one by default).

    Returns
    -------
    EstimateLoop or None
        None for a design or a scenario without an estimator.
    """
    from fahv.campaign.spec import scenario_path
    from fahv.spec.scenario import load_scenario
    from fahv.spec.schema import NO_ESTIMATOR, estimator_kind, estimator_value, law_tau

    path = scenario_path(arg)
    if not path.is_file() or path.resolve() == resolve_design_file(arg).resolve():
        return None
    c = load_scenario(path).run_spec.data
    if estimator_kind(c) == NO_ESTIMATOR:
        return None
    from fahv.analysis.estimated_loop import estimated_margins
    from fahv.estimation.kalman import design_filter
    from fahv.loop.cores import servos_of
    from fahv.sensors.data import load_sensors, measured_channels
    from fahv.spec.schema import plant_choices

    measured = measured_channels(plant_choices(c)["measured"])
    a, model = stored.arrays, estimator_value(c, "actuators")
    servos = servos_of(vehicle, model, "state_estimator")
    flt = design_filter(a, vehicle, load_sensors(vehicle_file), measured, c["Ts"],
                        c["plant_substeps"], a["x0"][None], servos,
                        estimator_value(c, "state_disturbance"))  # fmt: skip
    tau, tau_design = law_tau(c), float(c["tube"]["tau"])
    settings = [replace(s, F=s.F * (tau / tau_design)) for s in study.settings]
    actuators = ("ideal actuators" if servos is None else
                 f"the {model} servos in the plant and the filter, linear")  # fmt: skip
    law = "F" if tau == 1.0 else f"{tau:g} F"
    line = (f"the law on the Kalman estimate of {', '.join(measured)} (scenario {path.stem}; "
            f"{actuators}): u = v + {law} x_hat, broken at the elevator command, the filter "
            "fed the commanded input")  # fmt: skip
    return EstimateLoop(estimated_margins(stored, flt, settings), line, flt, settings)


def _estimate_figure(args, study, stored, est: EstimateLoop) -> Path:
    """The Nichols figure of the loop on the estimate (`estimate_nichols_figure`)."""
    from fahv.analysis.estimated_loop import design_point_loops
    from fahv.analysis.margin_figures import estimate_nichols_figure

    loops = design_point_loops(stored, est.flt, est.settings)
    title = est.line.split(" (", 1)[0] + f", scenario {Path(args.design).stem}"
    out = Path(args.out) / f"margins_{study.design_name}_estimate_nichols.{args.format}"
    return estimate_nichols_figure(study, loops, est.rows, title, out)


def cmd_margins(args) -> int:
    """Print the margin table of a design and write its Bode and Nichols figures."""
    t0 = time.monotonic()
    vehicle = vehicle_of(args)
    study, stored, folder = study_of(args.design, args.design_dir, vehicle,
                                     args.every_notch)  # fmt: skip
    print(
        f"design {study.design_name} ({folder}), hash {stored.summary['design_hash']}: "
        f"loop u = v + F e with the constraints inactive, Ts = {study.Ts:g} s, "
        f"omega_1 = {study.omega_flex[0]:.2f} rad/s, omega_2 = {study.omega_flex[1]:.2f} rad/s"
    )
    if args.markdown:
        print(_markdown(study))
    else:
        print(margin_table(study.table_rows()))
        for line in notch_summary(study.table_rows()):
            print(line)
    est = estimate_loop(args.design, study, stored, vehicle, args.vehicle)
    if est is not None:
        print(est.line)
        print(margin_table(est.rows, markdown=args.markdown))
        for r in est.rows:  # the classical requirement, said for the loop on the estimate too
            print(f"the loop on the estimate, break at {r.break_at}, notch {r.notch}, "
                  f"{r.point}: GM+ {r.gm_up_db:.1f} dB, PM {r.pm_deg:.1f} deg; "
                  f"6 dB / 45 deg met: {'yes' if meets(r) else 'no'}")  # fmt: skip
    for label, rho in study.corner_rho.items():
        print(
            f"notch {label}: closed loop stable at {int((rho < 1).sum())} of {len(rho)} "
            f"parameter box corners (largest spectral radius {rho.max():.6f})"
        )
    if args.out:
        paths = margin_figures(study, stored, Path(args.out), args.format)
        if est is not None:
            paths.append(_estimate_figure(args, study, stored, est))
        for path in paths:
            print(f"wrote {path}")
    print(f"margins: {time.monotonic() - t0:.1f} s")
    return 0


def add_parsers(sub) -> None:
    """Add the parser of this command."""
    p = sub.add_parser(
        "margins",
        help="gain, phase, delay and disk margins of the tube loop, with and without the notch",
        description="Classical loop margins of a stored design's tube loop u = v + F e "
        "(constraints inactive), broken at the elevator input delta_e and at the pitch-rate "
        "sensor q, for every notch setting of its tube variants and the paper's eps_p: at the "
        "design point, worst over the LPV vertices, and at the parameter box corner of the most "
        "unstable airframe. Margins by python-control (stability_margins, disk_margins).",
    )
    p.add_argument("design", help="design or scenario: a file, or a name in offline_design/")
    p.add_argument("--design-dir", default=None, help="artefact folder of the stored design")
    p.add_argument("--out", default="figures",
                   help="folder of the Bode and Nichols figures ('' writes none)")  # fmt: skip
    p.add_argument("--format", choices=("png", "pdf"), default="png")
    p.add_argument("--markdown", action="store_true", help="print the table as Markdown")
    p.add_argument("--every-notch", action="store_true",
                   help="every notch setting over the LPV vertices (default: the notch at "
                   "omega_1 as designed and no notch)")  # fmt: skip
    add_vehicle_option(p)
    p.set_defaults(func=cmd_margins)
