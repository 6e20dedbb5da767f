"""Tube forms: the registered ways a design makes and certifies its tube (``tube.form``).

Every form starts from the vertex tube the pipeline has designed (F, Z from LMI 24 over
the TP vertices for the sampled W) and the trim map, and fills in, through two calls:

* :meth:`TubeForm.design`: the tube the law runs on (F, N, its tightening, its notch
  loops), before the inputs are tightened (eq. 30);
* :meth:`TubeForm.certify`: the certificate over the tube's own domain, once the
  tightened inputs and the loss coverage are known, with the arrays the QP needs.

Forms: ``vertices`` (:class:`VertexTube`, the paper's Z over the TP vertices for a
sampled W, checked over its domain by :func:`fahv.tube.vertex_tube.certify_tube`) and
``eight_state`` (:class:`EightStateTube`, the tube set (W_8, Z_8) along the nominal,
closed over its own domain by :func:`fahv.design.tube_set_design.design_tube_set`).
A new form subclasses :class:`TubeForm` and is added with :func:`register_tube_form`.
"""

from __future__ import annotations

from typing import Any, ClassVar

import numpy as np

from fahv.bounds.disturbance import DEFAULT_DEV_BOX
from fahv.bounds.domain import nominal_box
from fahv.certificate.report import (
    input_rows_line,
    nominal_range_line,
    notch_loop_line,
    state_rows_line,
    tube_set_lines,
)
from fahv.control.mpc.attitude import attitude_bounds
from fahv.control.mpc.estimator import estimator_gains
from fahv.design.tube_set_design import design_tube_set
from fahv.errors import DesignError
from fahv.model.vehicle import IQ
from fahv.spec.artefacts import variant_gain_key
from fahv.tube.notch_loop import notch_loop, notch_tube
from fahv.tube.rows import input_rows, state_rows
from fahv.tube.vertex_tube import certify_tube


class TubeForm:
    """Interface of a tube form (module docstring); subclasses set :attr:`name`.

    Both methods read and fill the pipeline's :class:`fahv.design.pipeline.DesignState`
    ``st``: :meth:`design` sets ``st.F``, ``st.N``, ``st.tightening``, ``st.lam`` and
    ``st.notch_loops``; :meth:`certify` returns the summary's ``certificate`` and adds
    arrays to ``st.arrays``.
    """

    name: ClassVar[str] = ""

    def design(self, st: Any) -> None:
        """Make the tube the law runs on (sets ``st.F``, ``st.N``, ``st.tightening`` ...)."""
        raise NotImplementedError

    def certify(self, st: Any) -> dict:
        """The certificate over the tube's domain (the summary's ``certificate``)."""
        raise NotImplementedError


class VertexTube(TubeForm):
    """The paper's tube: Z over the TP vertices for the sampled W (LMI 24, eq. 25-28).

    Its notch loops are checked at the fault vertices (stability, or certified in the
    loop's own states, :mod:`fahv.tube.notch_loop`); its certificate is checked over
    its domain (:func:`fahv.tube.vertex_tube.certify_tube`): for a sampled W it is
    reported as not closed, with the measured factor.
    """

    name = "vertices"

    def design(self, st: Any) -> None:
        """F, N of the vertex tube; its notch loops checked and logged."""
        t = st.tube
        st.F, st.N, st.tightening, st.lam = t.F, t.N, t.tightening, t.lam
        c, tau = st.c, st.tau
        st.notch_loops = [notch_loop(st.Af, st.Bf, tau * t.F, nf, c["Ts"], IQ, v)
                          for v, nf in st.stable_only.items()]  # fmt: skip
        st.notch_loops += [notch_tube(st.Af, st.Bf, tau * t.F, tau**2 * t.N, st.W.w_max, nf,
                                      c["Ts"], IQ, t.lam, v)
                           for v, nf in st.notches.items()]  # fmt: skip
        for loop in st.notch_loops:
            st.log(notch_loop_line(loop))

    def certify(self, st: Any) -> dict:
        """W over the tube's domain and the exact RPI level (:func:`certify_tube`)."""
        c = st.c
        cert_case = c
        if "mpc" in c:  # the domain of the certificate: the attitude rows the QP will use
            att = attitude_bounds(st.tube.N, c["mpc"]["att_max"])
            cert_case = {**c, "mpc": {**c["mpc"], "att_max": float(np.degrees(att.used.max()))}}
        return certify_tube(cert_case, st.veh, st.tp, st.tm, st.Af, st.Bf, st.tube, st.tau,
                            st.u_lo, st.u_hi, st.rho_f, st.Dx, DEFAULT_DEV_BOX, st.log,
                            st.progress)  # fmt: skip


class EightStateTube(TubeForm):
    """The tube set (W_8, Z_8) on the eight states after h, along the nominal.

    W_8 is bounded over the tube's own domain (the nominal box, the tube, every corner
    of the uncertainty box, the fault range) and closed with Z_8
    (:func:`fahv.design.tube_set_design.design_tube_set`); the QP's rows (``mpc.u_box``,
    ``mpc.hv_box``, ``mpc.x_box``) keep the nominal inside the range it covers.
    """

    name = "eight_state"

    def design(self, st: Any) -> None:
        """Close the tube set (the vertex tube gives the directions' column scale)."""
        c, tube = st.c, st.tube
        st.cols = np.concatenate([tube.z_box, tube.tightening])  # the directions' column scale
        # the design check asks for an estimate; its gain along the elevator column, if any
        gamma, gamma_e = estimator_gains(c["Ts"], c["mpc"]["est_tau"], c["mpc"]["est_tau_elevator"])
        estimate = (
            {}
            if gamma_e is None
            else {"gamma_e": gamma_e, "directions": st.disc.B[:, :, 1], "projection_scale": st.Dx}
        )
        st.hv_box = command_range(c, st.veh.envelope)  # before the design: a clear error first
        ts, st.es_nominal, st.es_box = design_tube_set(
            c, st.veh, st.tm, np.concatenate([st.Dx, st.Du]), st.W.w_max, st.cols, st.rho_f,
            st.room_f, st.log, gamma=gamma, notches=st.notches, stable_only=st.stable_only,
            stage=st.stage, **estimate,
        )  # fmt: skip
        for line in tube_set_lines(ts, st.es_nominal, st.es_box):
            st.log(line)
        st.tube_set = ts
        st.F, st.N, st.tightening, st.lam = ts.F, ts.N, ts.tightening, ts.lam
        st.notch_loops = []

    def certify(self, st: Any) -> dict:
        """The QP's rows from the nominal box and the box corners' trims; the tube set's record."""
        ts = st.tube_set
        offsets = st.coverage.trim_offsets()
        u_box = input_rows(offsets, st.es_nominal)
        st.log(input_rows_line(offsets, st.es_nominal, u_box))
        st.log(nominal_range_line(st.hv_box))
        x_box = state_rows(ts.certified_range(st.es_box))
        st.log(state_rows_line(x_box))
        st.arrays.update(u_box=u_box, hv_box=st.hv_box, x_box=x_box)
        for v, F_8v in ts.notch_gains.items():  # a gain designed for a variant's notch loop
            st.arrays[variant_gain_key(v)] = np.hstack([np.zeros((2, 1)), F_8v])
        certificate = ts.summary(st.es_nominal, st.es_box)  # W_8 over its own domain
        # the directions' column scale: with the summary, the vertex data can be rebuilt
        # and the certificate re-checked from the stored design (fahv verify)
        certificate["col_scale"] = st.cols.tolist()
        return certificate


#: The registered tube forms, by ``tube.form``.
TUBE_FORMS: dict[str, TubeForm] = {}


def register_tube_form(form: TubeForm) -> TubeForm:
    """Add a tube form to :data:`TUBE_FORMS` under its :attr:`TubeForm.name`.

    Raises
    ------
    ValueError
        If the name is empty or taken.
    """
    if not form.name or form.name in TUBE_FORMS:
        raise ValueError(f"tube form name {form.name!r} is empty or already registered")
    TUBE_FORMS[form.name] = form
    return form


register_tube_form(VertexTube())
register_tube_form(EightStateTube())


def command_range(case: dict, envelope) -> np.ndarray:
    """The eight-state tube's nominal h, V range, checked against the design step.

    The tube set is certified for a nominal inside its nominal box (the envelope less
    ``eight_state.h_margin`` / ``V_margin``, :func:`fahv.bounds.domain.nominal_box`);
    the QP keeps its set point and prediction in that range (``mpc.hv_box``).

    Parameters
    ----------
    case : dict
        The validated design (its ``eight_state`` and ``design_step`` sections).
    envelope : fahv.model.vehicle.Envelope

    Returns
    -------
    (2, 2) ndarray
        ``[[h lo, V lo], [h hi, V hi]]`` in ft, ft/s.

    Raises
    ------
    DesignError
        If the design step's start or end lies outside it (names which and the range).
    """
    nominal, _ = nominal_box(case["eight_state"], envelope)
    hv_box = np.array([nominal.lo[:2], nominal.hi[:2]])
    cmd = case["design_step"]
    for what, h, V in (("initial point", cmd["h0"], cmd["V0"]),
                       ("command", cmd["h_c"], cmd["V_c"])):  # fmt: skip
        if not (hv_box[0, 0] <= h <= hv_box[1, 0] and hv_box[0, 1] <= V <= hv_box[1, 1]):
            raise DesignError(
                f"design_step: the {what} ({h} ft, {V} ft/s) lies outside the nominal range "
                f"the tube is certified for, h {hv_box[0, 0]:.0f}..{hv_box[1, 0]:.0f} ft, V "
                f"{hv_box[0, 1]:.2f}..{hv_box[1, 1]:.2f} ft/s (the envelope less "
                "eight_state.h_margin / V_margin)"
            )
    return hv_box
