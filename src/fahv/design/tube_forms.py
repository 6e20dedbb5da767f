"""Tube forms: the registered ways a design makes and certifies its tube (`tube.form`).

Every form starts from the vertex tube (F, Z from LMI 24 over the TP vertices for the
sampled W, `fahv.design.results.VertexTube`) and the trim map, and makes, through
two calls:

* `TubeForm.design`: the tube the law runs on (F, N, its tightening, its notch
  loops), before the inputs are tightened (eq. 30): a `fahv.design.results.FormTube`;
* `TubeForm.certify`: the certificate over the tube's own domain, once the
  tightened inputs and the loss coverage are known, with the arrays the QP needs: a
  `fahv.design.results.FormCertificate`.

Forms: `vertices` (`VerticesForm`, the paper's Z over the TP vertices for a
sampled W, checked over its domain by `fahv.tube.vertex_tube.certify_tube`) and
`eight_state` (`EightStateForm`, the tube set (W_8, Z_8) along the nominal,
closed over its own domain by `fahv.design.tube_set_design.design_tube_set`).
A new form subclasses `TubeForm` and is added with `register_tube_form`.
The eight-state form runs the onset bound (`fahv.onset`) on its closed tube set,
which is why the forms sit in the design package, above the tube and the onset.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import ClassVar

import numpy as np

from fahv.bounds.disturbance import STATE_DEVIATIONS
from fahv.bounds.domain import nominal_box
from fahv.certificate.report import (
    input_rows_line,
    nominal_range_line,
    notch_loop_line,
    state_rows_line,
    tube_set_lines,
    vertex_certificate_lines,
)
from fahv.control.mpc.attitude import attitude_bounds
from fahv.control.mpc.estimator import estimator_gains
from fahv.design.results import (
    DesignModel,
    Disturbance,
    FormCertificate,
    FormTube,
    NotchVariants,
    Tightening,
    VertexTube,
)
from fahv.design.tube_set_design import design_tube_set
from fahv.errors import DesignError
from fahv.model.vehicle import IQ, Vehicle
from fahv.spec.artefacts import variant_gain_key
from fahv.synthesis.feedback import ActiveSet
from fahv.tube.notch_loop import notch_loop, notch_tube
from fahv.tube.rows import input_rows, state_rows
from fahv.tube.vertex_tube import certify_tube

#: A stage clock's callback: told the name of each part of a long stage.
Tell = Callable[[str], None]


class TubeForm:
    """Interface of a tube form (module docstring); subclasses set `name`."""

    name: ClassVar[str] = ""

    def design(self, spec: dict, vehicle: Vehicle, model: DesignModel, dist: Disturbance,
               vertex: VertexTube, notches: NotchVariants, log: Callable[[str], None],
               tell: Tell, previous=None) -> FormTube:  # fmt: skip
        """Make the tube the law runs on from the vertex tube.

        Parameters
        ----------
        spec : dict
            The validated design data.
        vehicle : fahv.model.vehicle.Vehicle
        model, dist, vertex
            The results of the stages before (sec. 3.1, eq. 13-19, LMI 24-28).
        notches : NotchVariants
            The tube variants that feed q through a notch.
        log : callable
            Receives the progress lines of long computations.
        tell : callable
            Told the start of each part of the form's design (the stage clock).
        previous : Mapping[str, ndarray], optional
            The arrays of an earlier design of the same file: where the form's LMIs start
            their constraint generation (e.g. `closure_active_set`).

        Returns
        -------
        FormTube
        """
        raise NotImplementedError

    def certify(self, spec: dict, vehicle: Vehicle, model: DesignModel, vertex: VertexTube,
                tube: FormTube, tightening: Tightening,
                progress=None) -> FormCertificate:  # fmt: skip
        """The certificate over the tube's domain (the summary's `certificate`).

        Parameters
        ----------
        spec, vehicle, model, vertex
            As `design`.
        tube : FormTube
            What `design` made.
        tightening : Tightening
            The tightened inputs and the loss coverage (eq. 30).
        progress : callable, optional
            Iterable wrapper (tqdm) of long loops.

        Returns
        -------
        FormCertificate
        """
        raise NotImplementedError


class VerticesForm(TubeForm):
    """The paper's tube: Z over the TP vertices for the sampled W (LMI 24, eq. 25-28).

    Its notch loops are checked at the fault vertices (stability, or certified in the
    loop's own states, `fahv.tube.notch_loop`); its certificate is checked over
    its domain (`fahv.tube.vertex_tube.certify_tube`): for a sampled W it is
    reported as not closed, with the measured factor.
    """

    name = "vertices"

    def design(self, spec, vehicle, model, dist, vertex, notches, log, tell,
               previous=None) -> FormTube:  # fmt: skip
        """F, N of the vertex tube; its notch loops checked (`previous` is not used)."""
        t, tau, Ts = vertex.tube, vertex.tau, spec["Ts"]
        Af, Bf = vertex.Af, vertex.Bf
        loops = [notch_loop(Af, Bf, tau * t.F, nf, Ts, IQ, v)
                 for v, nf in notches.stable_only.items()]  # fmt: skip
        loops += [notch_tube(Af, Bf, tau * t.F, tau**2 * t.N, dist.W.w_max, nf, Ts, IQ, t.lam, v)
                  for v, nf in notches.certified.items()]  # fmt: skip
        return FormTube(t.F, t.N, t.tightening, t.lam, tuple(loops),
                        lines=tuple(notch_loop_line(loop) for loop in loops))  # fmt: skip

    def certify(self, spec, vehicle, model, vertex, tube, tightening, progress=None):
        """W over the tube's domain and the exact RPI level (`certify_tube`)."""
        domain_spec = spec
        if "mpc" in spec:  # the domain of the certificate: the attitude rows the QP will use
            att = attitude_bounds(vertex.tube.N, spec["mpc"]["att_max"])
            att_max = float(np.degrees(att.used.max()))
            domain_spec = {**spec, "mpc": {**spec["mpc"], "att_max": att_max}}
        cert = certify_tube(domain_spec, vehicle, model.tp, model.trim, vertex.Af, vertex.Bf,
                            vertex.tube, vertex.tau, tightening.u_lo, tightening.u_hi,
                            vertex.rho_f, model.Dx, STATE_DEVIATIONS, progress)  # fmt: skip
        return FormCertificate(cert.summary(), {}, tuple(vertex_certificate_lines(cert)))


class EightStateForm(TubeForm):
    """The tube set (W_8, Z_8) on the eight states after h, along the nominal.

    W_8 is bounded over the tube's own domain (the nominal box, the tube, every corner
    of the parameter box, the fault range) and closed with Z_8
    (`fahv.design.tube_set_design.design_tube_set`); the QP's rows (`mpc.u_box`,
    `mpc.hv_box`, `mpc.x_box`) keep the nominal inside the range it covers.
    """

    name = "eight_state"

    def design(self, spec, vehicle, model, dist, vertex, notches, log, tell,
               previous=None) -> FormTube:  # fmt: skip
        """Close the tube set (the vertex tube gives the directions' column scale)."""
        t = vertex.tube
        cols = np.concatenate([t.z_box, t.tightening])  # the directions' column scale
        # the design check asks for an estimate; its gain along the elevator column, if any
        mpc = spec["mpc"]
        gamma, gamma_e = estimator_gains(spec["Ts"], mpc["est_tau"], mpc["est_tau_elevator"])
        estimate = (
            {}
            if gamma_e is None
            else {"gamma_e": gamma_e, "directions": model.disc.B[:, :, 1],
                  "projection_scale": model.Dx}
        )  # fmt: skip
        hv_box = command_range(spec, vehicle.envelope)  # before the design: a clear error first
        ts, nominal, box = design_tube_set(
            spec, vehicle, model.trim, np.concatenate([model.Dx, model.Du]), dist.W.w_max, cols,
            vertex.rho_f, vertex.room_f, log, gamma=gamma, notches=notches.certified,
            stable_only=notches.stable_only, stage=tell, warm=closure_active_set(previous),
            starts=ellipsoid_starts(previous), **estimate,
        )  # fmt: skip
        return FormTube(ts.F, ts.N, ts.tightening, ts.lam, (), ts, nominal, box, hv_box, cols,
                        tuple(tube_set_lines(ts, nominal, box)))  # fmt: skip

    def certify(self, spec, vehicle, model, vertex, tube, tightening, progress=None):
        """The QP's rows from the nominal box and the corners' trims; the tube set's record."""
        ts = tube.tube_set
        offsets = tightening.coverage.trim_offsets()
        u_box = input_rows(offsets, tube.nominal)
        x_box = state_rows(ts.certified_range(tube.box))
        arrays = {"u_box": u_box, "hv_box": tube.hv_box, "x_box": x_box}
        if ts.active_set is not None:  # where the next design of this file starts its LMIs
            arrays.update(closure_vertices=ts.active_set.vertices,
                          closure_points=ts.active_set.points)  # fmt: skip
        arrays.update({ELLIPSOID_VERTICES + k: v for k, v in ts.ellipsoid_vertices.items()})
        for v, F_8v in ts.notch_gains.items():  # a gain designed for a variant's notch loop
            arrays[variant_gain_key(v)] = np.hstack([np.zeros((2, 1)), F_8v])
        summary = ts.summary(tube.nominal, tube.box)  # W_8 over its own domain
        # the directions' column scale: with the summary, the vertex data can be rebuilt
        # and the certificate re-checked from the stored design (fahv verify)
        summary["col_scale"] = tube.col_scale.tolist()
        lines = (input_rows_line(offsets, tube.nominal, u_box), nominal_range_line(tube.hv_box),
                 state_rows_line(x_box))  # fmt: skip
        return FormCertificate(summary, arrays, lines)


def closure_active_set(previous) -> ActiveSet | None:
    """The closure's active set stored in an earlier design's arrays (None if none is).

    Parameters
    ----------
    previous : Mapping[str, ndarray] or None
        The arrays of the design the output folder held before (`closure_vertices`,
        `closure_points`), or None.

    Returns
    -------
    fahv.synthesis.feedback.ActiveSet or None
    """
    if previous is None or "closure_vertices" not in previous:
        return None
    return ActiveSet(np.asarray(previous["closure_vertices"], int),
                     np.asarray(previous.get("closure_points", np.zeros(0)), int))  # fmt: skip


#: Prefix of the stored arrays that hold the vertices an invariant ellipsoid's last LMI
#: solve held (`ellipsoid_vertices_steady_0.995`, `ellipsoid_vertices_notch_tube_mpc`).
ELLIPSOID_VERTICES = "ellipsoid_vertices_"


def ellipsoid_starts(previous) -> dict[str, np.ndarray]:
    """The invariant ellipsoids' active sets stored in an earlier design's arrays.

    Parameters
    ----------
    previous : Mapping[str, ndarray] or None
        The arrays of the design the output folder held before, or None.

    Returns
    -------
    dict[str, (a,) ndarray of int]
        By ellipsoid name (`ELLIPSOID_VERTICES` stripped); empty if none is stored.
    """
    if previous is None:
        return {}
    return {k[len(ELLIPSOID_VERTICES):]: np.asarray(v, int) for k, v in previous.items()
            if k.startswith(ELLIPSOID_VERTICES)}  # fmt: skip


#: The registered tube forms, by `tube.form`.
TUBE_FORMS: dict[str, TubeForm] = {}


def register_tube_form(form: TubeForm) -> TubeForm:
    """Add a tube form to `TUBE_FORMS` under its `TubeForm.name`.

    Raises
    ------
    ValueError
        If the name is empty or taken.
    """
    if not form.name or form.name in TUBE_FORMS:
        raise ValueError(f"tube form name {form.name!r} is empty or already registered")
    TUBE_FORMS[form.name] = form
    return form


register_tube_form(VerticesForm())
register_tube_form(EightStateForm())


def command_range(spec: dict, envelope) -> np.ndarray:
    """The eight-state tube's nominal h, V range, checked against the design step.

    The tube set is certified for a nominal inside its nominal box (the envelope less
    `eight_state.h_margin` / `V_margin`, `fahv.bounds.domain.nominal_box`);
    the QP keeps its set point and prediction in that range (`mpc.hv_box`).

    Parameters
    ----------
    spec : dict
        The validated design data (its `eight_state` and `design_step` sections).
    envelope : fahv.model.envelope.Envelope

    Returns
    -------
    (2, 2) ndarray
        `[[h lo, V lo], [h hi, V hi]]` in ft, ft/s.

    Raises
    ------
    DesignError
        If the design step's start or end lies outside it (names which and the range).
    """
    nominal, _ = nominal_box(spec["eight_state"], envelope)
    hv_box = np.array([nominal.lo[:2], nominal.hi[:2]])
    step = spec["design_step"]
    for what, h, V in (("initial point", step["h0"], step["V0"]),
                       ("command", step["h_c"], step["V_c"])):  # fmt: skip
        if not (hv_box[0, 0] <= h <= hv_box[1, 0] and hv_box[0, 1] <= V <= hv_box[1, 1]):
            raise DesignError(
                f"design_step: the {what} ({h} ft, {V} ft/s) lies outside the nominal range "
                f"the tube is certified for, h {hv_box[0, 0]:.0f}..{hv_box[1, 0]:.0f} ft, V "
                f"{hv_box[0, 1]:.2f}..{hv_box[1, 1]:.2f} ft/s (the envelope less "
                "eight_state.h_margin / V_margin)"
            )
    return hv_box
