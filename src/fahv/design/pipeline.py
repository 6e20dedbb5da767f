"""Offline design: a design file -> certified artefacts with their provenance.

`run_design` runs the stages of `fahv.design.stages` top to bottom, as the
paper builds its controller (sec. 3-4, Algorithm 1): the design model and its LPV form
(sec. 3.1) -> the disturbance set W (eq. 13-19) -> F and Z (LMI 24-28) and the tube the
law runs on (`tube.form`) -> the tightened inputs (eq. 30) -> the nominal gain and
ellipsoid (eq. 32-35) -> the certificate over the tube's own domain -> the offline part
of every law a variant uses. Each stage returns a frozen record
(`fahv.design.results`) that the later stages read.

Every certificate is re-checked where it is made and printed with its margin (the lines
are formatted by `fahv.certificate.report`); nothing is written unless all hold.
What depends on a scenario (its x0, its vehicle draw) is not designed here
(`fahv.spec.scenario`).
"""

from __future__ import annotations

import numpy as np

from fahv.config.spec import defaults_text
from fahv.design.estimate import estimate_stage
from fahv.design.results import (
    DesignModel,
    Disturbance,
    FormCertificate,
    FormTube,
    Nominal,
    Tightening,
    VertexTube,
)
from fahv.design.stages import (
    certificate_stage,
    disturbance_stage,
    early_laws_stage,
    laws_stage,
    model_stage,
    nominal_stage,
    tightening_stage,
    tube_form_stage,
    vertex_tube_stage,
)
from fahv.model.vehicle import load_vehicle
from fahv.spec.artefacts import Design, provenance, split_warm_starts
from fahv.spec.files import SpecFile
from fahv.spec.scenario import design_part, scenario_design
from fahv.version import __version__


def summary_of(spec: SpecFile, vehicle, model: DesignModel, dist: Disturbance,
               vertex: VertexTube, tube: FormTube, tightening: Tightening,
               nominal: Nominal, cert: FormCertificate) -> dict:  # fmt: skip
    """The stored scalars of a finished design: provenance, W, tube, certificates."""
    c, tau, W = spec.data, vertex.tau, dist.W
    return {
        "code_version": __version__,
        "provenance": provenance(spec, vehicle),
        "defaults_used": {
            k: list(v) if isinstance(v, tuple) else v for k, v in spec.defaults_used.items()
        },
        "n_vertices": int(model.tp.n_vertices),
        "W_parts": {k: v.tolist() for k, v in W.parts.items()},
        "W_dominant": W.dominant(),
        "tube": {
            "form": c["tube"]["form"],
            "lam": tube.lam,
            "min_eig": float(vertex.eigs.min()),
            "tightening": (tau * tube.tightening).tolist(),
            "z_box": np.sqrt(np.diag(tube.N)).tolist(),
            "rho_f": vertex.rho_f,
            "row_room": vertex.room_f.tolist(),
            "loss_covered": tightening.coverage.summary(),
            "notch_in_loop": [loop.summary() for loop in tube.notch_loops],
        },
        "certificate": cert.summary,
        "nominal": {**nominal.certificate, "s": nominal.design.s, "lam": nominal.design.lam},
        "design_name": spec.name,
        "design_step": dict(c["design_step"]),
        "uncertainty_scale": float(c["uncertainty"]["scale"]),
    }


def run_design(spec: SpecFile, vehicle=None, progress=None, log=print, clock=None,
               previous=None) -> Design:  # fmt: skip
    """Run every stage of `fahv.design.stages` on a design file; the certified design.

    Parameters
    ----------
    spec : SpecFile
        A validated design file (`fahv.spec.files.load_design_file`), or a run spec
        (a design's entries with a scenario's, `fahv.spec.schema.run_spec`).
    vehicle : fahv.model.vehicle.Vehicle, optional
        The vehicle to design for; the packaged vehicle file by default.
    progress : callable, optional
        Iterable wrapper for long loops (tqdm).
    log : callable
        Receives one line per step and per certificate.
    clock : fahv.design.stage_clock.StageClock, optional
        Told the start of every stage (and of the tube form's parts): the progress
        lines and the stage times.
    previous : Mapping[str, ndarray], optional
        The warm starts of an earlier design of the same file (`Design.warm_starts`):
        where the constraint generation of its LMIs starts (the closure's `closure_vertices` and
        `closure_points`, the invariant ellipsoids' `ellipsoid_vertices_*`, the
        baseline's `rmpc_guess_*`). It changes how fast the design runs, not what is certified
        (every certificate is the exact check over every vertex).

    Returns
    -------
    Design
        For a design file, its stored form (`case`: the design data). For a run spec,
        its design part (`fahv.spec.scenario.design_part`) designed with the run
        spec's command as design step, carrying the run spec and its scenario arrays
        (`fahv.spec.scenario.scenario_design`), ready to run.

    Raises
    ------
    DesignError
        If an LMI is infeasible or a certificate fails (the message names which).
    """
    veh = load_vehicle() if vehicle is None else vehicle
    if "command" in spec.data:  # a run spec: its design part, then its scenario
        design = run_design(design_part(spec), veh, progress, log, clock, previous)
        return scenario_design(design, spec, veh, None, log)
    if spec.defaults_used:
        log("defaults used by the design file:\n" + defaults_text(spec.defaults_used))
    tell = (lambda name: None) if clock is None else clock.stage
    c = spec.data

    def done(result):
        for line in result.lines:
            log(line)
        return result

    tell("model")
    model = done(model_stage(c, veh))
    early = early_laws_stage(c, veh, model, previous)  # on the cluster, beside the tube
    tell("disturbance")
    dist = done(disturbance_stage(c, veh, model, progress))
    tell("vertex tube")
    vertex = done(vertex_tube_stage(c, veh, model, dist))
    tell("tube form")
    tube = done(tube_form_stage(c, veh, model, dist, vertex, log, tell, previous))
    tell("tightening")
    tightening = done(tightening_stage(c, veh, model, dist, vertex, tube))
    tell("nominal")
    nominal = done(nominal_stage(c, model, tightening))
    tell("certificate")
    cert = done(certificate_stage(c, veh, model, vertex, tube, tightening, progress))
    tell("laws")
    arrays = laws_stage(c, veh, model, dist, vertex, tube, tightening, nominal, cert, log,
                        previous, early)  # fmt: skip
    summary = summary_of(spec, veh, model, dist, vertex, tube, tightening, nominal, cert)
    certified, warm = split_warm_starts(arrays)
    design = Design(c, certified, summary, warm)
    if c.get("estimate"):
        tell("estimate")
        design = with_estimate(design, veh, previous, done)
    design.summary["design_hash"] = design.content_hash()
    return design


def with_estimate(design: Design, vehicle, previous, done) -> Design:
    """The design with its estimate stage's arrays and summary (`fahv.design.estimate`).

    Parameters
    ----------
    design : Design
        The finished exact-state part of a design with an `estimate` section.
    vehicle : fahv.model.vehicle.Vehicle
    previous : Mapping[str, ndarray] or None
        An earlier design's warm starts.
    done : callable
        Logs a stage result's lines and returns it.

    Returns
    -------
    Design

    Raises
    ------
    DesignError
        If a claim fails or the covariance bound does (`estimate_stage`).
    """
    est = done(estimate_stage(design, vehicle, previous))
    certified, warm = split_warm_starts(est.arrays())
    c = est.claims
    summary = {**design.summary, "estimate": {
        "tau": c.tau, "p_claim": c.p_claim, "r_attitude": c.r_attitude, "r_rate": c.r_rate,
        "std_attitude_deg": np.degrees(c.std_attitude).tolist(),
        "std_step_deg": float(np.degrees(c.std_step)), "min_eig": est.tube.min_eig,
        "rate_tube_deg": float(np.degrees(c.rate_tube)),
        "rate_limit_deg": float(np.degrees(c.rate_limit)),
        "model_t_worst": est.tube.model_t.tolist()}}
    return Design(design.case, {**design.arrays, **certified}, summary,
                  {**design.warm_starts, **warm})
