"""The eight-state tube set in `fahv design` (fahv.design.tube_set_design): case keys, plumbing.

The closure itself (16384 vertices, LMI iterations of minutes) is not run here: the stored
tube sets' bounds are reproduced from their own vertex data in
tests/design/test_one_step_bound.py.
"""

import copy
import re

import numpy as np
import pytest
from tube_set_records import load_record

import fahv.design.tube_set_design as tsd
from fahv.bounds.domain import nominal_box
from fahv.errors import DesignError, SpecError
from fahv.spec.files import spec_file
from fahv.spec.scenario import load_run_spec, run_spec_data
from fahv.tube.notch_gain import NotchGain
from fahv.tube.notch_loop import NotchLoop
from fahv.tube.tube_set import TubeSet

CASE = "offline_design/scenarios/case1.yaml"


@pytest.fixture(scope="module")
def raw8():
    return run_spec_data(CASE)


def test_eight_state_case_sets_every_knob(raw8):
    c = load_run_spec(CASE)
    assert c.defaults_used == {}
    assert c["tube"]["form"] == "eight_state" and c["eight_state"]["k"] == 7
    plain = load_run_spec("offline_design/scenarios/case1_paper.yaml")
    assert plain["tube"]["form"] == "vertices" and "eight_state" not in plain.data


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda d: d["mpc"].update(nominal_model="lpv"), "'tube.form' eight_state needs"),
        (lambda d: d["mpc"].update(h_reset=False), "'tube.form' eight_state needs"),
        (lambda d: d["mpc"].update(est_tau=0.0), "'tube.form' eight_state needs"),
        (lambda d: d["mpc"].update(att_max=0.45), "'tube.form' eight_state needs"),
        (lambda d: d["mpc"].update(att_max=0.0), "'tube.form' eight_state needs"),
        (
            lambda d: d.update(design_model="ecm", variants=["tube_mpc"]),
            "'tube.form' eight_state needs",
        ),
        (lambda d: d["eight_state"].update(Phi=[1.0, 0.0]), "'eight_state.Phi' must be an incr"),
        (lambda d: d["eight_state"].update(reach=[0.1] * 8), "'eight_state.reach' must have 9"),
        (lambda d: d["tube"].update(form="ellipse"), "'tube.form'"),
        (
            lambda d: (
                d["eight_state"].update(certify_attitude=True, attitude=0.6),
                d["mpc"].update(att_max=0.5),
            ),
            "'eight_state.certify_attitude' needs",
        ),
        (
            lambda d: d["eight_state"].update(notch_gain="designed", notch_continuation=[0.1]),
            "'eight_state.notch_continuation' must increase to below notch.eps_p",
        ),
        (
            lambda d: (d["eight_state"].update(notch_gain="designed"), d["tube"].update(tau=0.8)),
            "'eight_state.notch_gain' 'designed' needs tube.tau 1",
        ),
        (
            lambda d: d["eight_state"].update(
                notch_gain="designed", notch_continuation=[0.06, 0.05]
            ),
            "'eight_state.notch_continuation' must increase",
        ),
        (
            lambda d: (
                d["eight_state"].update(notch_gain="designed"),
                d["tube"].update(filter_nominal_q=False),
            ),
            "'eight_state.notch_gain' 'designed' needs notch.enabled and tube.filter_nominal_q",
        ),
        (lambda d: d["eight_state"].update(notch_gain="mine"), "'eight_state.notch_gain'"),
    ],
)
def test_eight_state_case_refuses_a_loop_it_is_not_closed_for(raw8, mutate, match):
    d = copy.deepcopy(raw8)
    mutate(d)
    with pytest.raises(SpecError, match=match):
        spec_file(d, "bad.yaml")


@pytest.mark.parametrize("certify", [True, False])
def test_certify_attitude_bounds_the_supports_in_the_tube_lmi(raw8, vehicle, monkeypatch,
                                                              certify):  # fmt: skip
    """eight_state.certify_attitude: Z_8's alpha and theta supports bounded in the tube
    LMI by the requirement less the QP's rows (0.5 - 0.35 = 0.15 deg), nothing else."""

    class Vertices:
        J0 = np.zeros((64, 1))
        n_vehicles = [1]
        n_vertices = 4096

    seen = {}

    def closure(nv, nominal, W_8, *args, state_max=None, **kw):
        seen["state_max"] = state_max
        raise DesignError("closure reached")

    monkeypatch.setattr(tsd, "nominal_vertices", lambda *a, **k: Vertices())
    monkeypatch.setattr(tsd, "close_tube_set", closure)
    r = copy.deepcopy(raw8)
    r["eight_state"]["certify_attitude"] = certify
    r["eight_state"]["onset_in_tube"] = 0.0  # the attitude bound alone (the jumps: below)
    r["mpc"]["att_max"] = 0.35
    lines = []
    with pytest.raises(DesignError, match="closure reached"):
        tsd.design_tube_set(spec_file(r, "att.yaml").data, vehicle, None,
                            np.ones(11), np.ones(9), np.ones(11), 0.76, np.ones(2),
                            log=lines.append)  # fmt: skip
    if not certify:
        assert seen["state_max"] is None
        return
    np.testing.assert_allclose(np.degrees(seen["state_max"][1:3]), 0.15, rtol=1e-12)
    assert np.all(np.isinf(seen["state_max"][[0, 3, 4, 5, 6, 7]]))
    assert "bounded to 0.150 deg" in lines[-1]


@pytest.mark.parametrize("kappa", [0.0, 2.5])
def test_onset_in_tube_asks_the_tube_lmi_to_hold_the_onset_jumps(raw8, vehicle, monkeypatch,
                                                                 kappa):  # fmt: skip
    """eight_state.onset_in_tube kappa: the closure gets the first jumps of the design's
    loss over the scheduling box, J / rho_min, as points Z_8 must hold in kappa Z_8
    (``contain`` = J / rho_min / kappa, h's column dropped), from onset_jumps at rho_min
    with 1024 interior points; 0 asks nothing."""

    class Vertices:
        J0 = np.zeros((64, 1))
        n_vehicles = [1]
        n_vertices = 4096

    seen, J = {}, np.arange(27.0).reshape(3, 9)

    def jumps(box, veh, tm, unc, rho_f, Ts, n_sub, interior):
        seen["jumps"] = (rho_f, Ts, n_sub, interior)
        return J, 2

    def closure(nv, nominal, W_8, *args, contain=None, **kw):
        seen["contain"] = contain
        raise DesignError("closure reached")

    monkeypatch.setattr(tsd, "nominal_vertices", lambda *a, **k: Vertices())
    monkeypatch.setattr(tsd, "onset_jumps", jumps)
    monkeypatch.setattr(tsd, "close_tube_set", closure)
    r = copy.deepcopy(raw8)
    r["eight_state"]["onset_in_tube"] = kappa
    lines = []
    with pytest.raises(DesignError, match="closure reached"):
        tsd.design_tube_set(spec_file(r, "onset.yaml").data, vehicle, None,
                            np.ones(11), np.ones(9), np.ones(11), 0.76, np.ones(2),
                            log=lines.append)  # fmt: skip
    if kappa == 0.0:
        assert seen["contain"] is None and "jumps" not in seen
        return
    assert seen["jumps"] == (0.76, r["Ts"], r.get("plant_substeps", 5), 1024)
    np.testing.assert_allclose(seen["contain"], J[:, 1:] / 0.76 / 2.5, rtol=1e-15)
    assert "first jumps of a 24.0 % loss at 3 box points held in 2.5 Z_8" in lines[-1]


def _stored_tube_set():
    """The stored k = 5 tube set as the closure's result (its exact level 0.999505)."""
    d = load_record("closed_tube_h_reset.npz")
    return TubeSet(d["F"], d["N"], d["W"], float(d["H"]), float(d["lam"]), d["bound"], 0.999505,
                   int(d["moves"]), 0.0, 0.0)  # fmt: skip


def test_design_runs_the_law_on_the_eight_state_tube_set(raw8, vehicle, monkeypatch):
    """A quick design of the case (40 W samples) with the closure replaced by a stored
    tube set: the law's F, N and tightened inputs are the tube set's, the summary carries its
    certificate, the node parameters take it, and 20 s of the loop (CM nominal, reset)
    keep e_8 inside Z_8 and |e_h| <= H with e_h = 0 at every re-plan."""
    import fahv.design.pipeline as pmod
    import fahv.design.tube_forms as forms
    from fahv.loop.params import node_parameters
    from fahv.loop.simulate import simulate
    from fahv.runs.metrics import metrics

    ts = _stored_tube_set()
    calls = []

    def stored(case, veh, tm, scale, w_max, cols, rho, room, log, gamma, **estimate):
        calls.append((rho, np.asarray(scale).shape, np.asarray(cols).shape, gamma,
                      estimate["gamma_e"], estimate["directions"].shape))  # fmt: skip
        return (ts, *nominal_box(case["eight_state"], veh.envelope))

    monkeypatch.setattr(forms, "design_tube_set", stored)
    r = copy.deepcopy(raw8)
    r["disturbance"]["samples"] = 40
    r["certificate"] = {"schedules": 0}
    # the tube laws (the RMPC baseline's off-line design, a minute, does not use the tube
    # set; the shipped eight-state design's RMPC is re-checked by tests/design/test_verify.py)
    r["variants"] = [v for v in r["variants"] if v != "rmpc"]
    r["tube"]["lam"] = r["tube"]["lam"][1:2]  # one of the vertex tube's three LMIs
    lines = []
    design = pmod.run_design(spec_file(r, "quick8.yaml"), log=lines.append)
    # the estimate's gains: Ts / est_tau, and 1 along the 20 LPV vertices' elevator columns
    assert calls == [(0.76, (11,), (11,), pytest.approx(0.2), 1.0, (20, 9))]
    a, s = design.arrays, design.summary
    np.testing.assert_array_equal(a["F"], ts.F)
    np.testing.assert_array_equal(a["N"], ts.N)
    lim = vehicle.limits
    np.testing.assert_allclose(a["u_lo"], lim.u_min + ts.tightening, rtol=1e-12)
    np.testing.assert_allclose(a["u_hi"], lim.u_max - ts.tightening, rtol=1e-12)
    assert s["tube"]["form"] == "eight_state"
    assert s["certificate"]["level"] == 0.999505 and s["certificate"]["H_ft"] == ts.H
    assert any(line.startswith("closed: Z_8 RPI for W_8") for line in lines)
    # the attitude rows: Z_8's alpha support (0.33 deg) leaves 0.17 deg: 0.37 not certified
    assert np.degrees(a["att_support"][0]) == pytest.approx(0.33, abs=0.01)
    # the nominal box's input ranges: checked against every corner's faulty trim, and
    # rows of the QP (mpc.u_box, Phi -, delta_e deg)
    assert any(line.startswith("nominal box inputs (applied input") for line in lines)
    # the box less the corners' trim offsets (Phi -0.0348..+0.0404, delta_e -1.007..+1.100
    # deg, with the remainder): the room of the manoeuvre part of the nominal input
    np.testing.assert_allclose(a["u_box"][:, 0], [-0.2 + 0.0348, 1.1 - 0.0404], atol=1e-4)
    np.testing.assert_allclose(np.degrees(a["u_box"][:, 1]), [-3.0 + 1.007, 7.0 - 1.100],
                               atol=1e-3)  # fmt: skip
    # the nominal's h, V range (mpc.hv_box): the envelope less h_margin 5 ft, V_margin 4.98
    np.testing.assert_allclose(a["hv_box"], [[85005.0, 7704.98], [86495.0, 8295.02]], rtol=1e-12)
    assert any(line.startswith("nominal range (mpc.hv_box): h 85005..86495 ft") for line in lines)
    params = node_parameters(design)
    np.testing.assert_allclose(params["nominal_trajectory"]["mpc.hv_box"],
                               [85005.0, 86495.0, 7704.98, 8295.02], rtol=1e-12)  # fmt: skip
    assert np.asarray(params["tube_mpc"]["F"]).size == 18
    # the range the certificate covers (the scheduling box less the tube) as rows of the
    # QP on the nominal's other states (mpc.x_box): alpha +/-0.65 deg, |q| <= 1.0 deg/s
    # from the trim at its own (h, V) (0.650, 1.002 on the certified design's own tube set)
    xb = a["x_box"]
    np.testing.assert_allclose(xb[0], -xb[1], rtol=1e-12)
    assert np.degrees(xb[1, 0]) == pytest.approx(0.65, abs=0.02)
    assert np.degrees(xb[1, 2]) == pytest.approx(1.0, abs=0.05)
    assert any(line.startswith("nominal state range (mpc.x_box): alpha -0.6") for line in lines)
    xp = np.asarray(params["nominal_trajectory"]["mpc.x_box"]).reshape(2, 7)
    np.testing.assert_allclose(np.radians(xp[:, :3]), xb[:, :3], rtol=1e-12)
    np.testing.assert_allclose(xp[:, 3:], xb[:, 3:], rtol=1e-12)
    np.testing.assert_allclose(params["nominal_trajectory"]["mpc.u_box"],
                               [-0.1652, 1.0596, -1.993, 5.900], atol=1e-3)  # fmt: skip
    run = simulate(design, "tube_mpc", duration=20.0)
    e = run.x - run.x_r - run.x_n[:, :9]
    l8 = np.einsum("ki,ij,kj->k", e[:, 1:], np.linalg.inv(ts.N_8), e[:, 1:])
    m = metrics(run, lim, design.case["fault"]["t_onset"])
    print(f"20 s: largest level in Z_8 {l8.max():.4f}, max |e_h| {m['tube_error_h_max_ft']:.4f} "
          f"ft (H = {ts.H:.3f} ft)")  # fmt: skip
    assert l8.max() <= 1.0
    assert m["tube_error_h_max_ft"] <= ts.H
    assert np.all(np.abs(e[25::25, 0]) <= 1e-6)  # the reset: e_h = 0 at each re-plan
    assert run.x[-1, 0] > 85500.0 + 1.0  # climbing
    # the nominal's range and its deviation from the trim at its own (h, V): it starts
    # on the trim, climbs inside the QP's range rows, and its attitude stays inside the
    # certified range (the scheduling box less the tube) the design stores
    from fahv.runs.metrics import nominal_deviation

    dev = nominal_deviation(run)
    assert np.abs(dev[0]).max() <= 1e-6
    assert 85499.9 <= m["nominal_h_min_ft"] and m["nominal_h_max_ft"] <= 86495.0
    assert run.x[-1, 0] + 20.0 > m["nominal_h_max_ft"] > run.x[-1, 0] - 20.0
    cert = s["certificate"]["certified_range"]
    assert 0.2 < m["nominal_alpha_dev_max_deg"] < np.degrees(cert["hi"][2])
    assert m["nominal_q_dev_max_degps"] < np.degrees(cert["other_half"][0])
    print("nominal:", {k: round(v, 4) for k, v in m.items() if k.startswith("nominal_")})


def test_the_adjustable_law_runs_tau_F_8_and_tightens_by_tau_F_8_Z_8(raw8, vehicle, monkeypatch):
    """tube.tau 0.8 on the eight-state form (eq. 47-54): the tube set is asked for the
    gains tau' F_8 of [0.8, 1], the inputs are tightened by 0.8 F_8 Z_8 (eq. 53), the node
    takes tau, and 10 s of the loop keep the level inside Z. A stored tube set stands in
    for the closure (closed for the gain F_8 alone: plumbing only; the law's 0.8 F e and
    its level in Z: tests/control/test_tube_mpc_law.py)."""
    import fahv.design.pipeline as pmod
    import fahv.design.tube_forms as forms
    from fahv.loop.params import node_parameters
    from fahv.loop.simulate import simulate

    ts = _stored_tube_set()
    taus = []

    def stored(case, veh, tm, scale, w_max, cols, rho, room, log, gamma, **estimate):
        taus.append(case["tube"]["tau"])
        return (ts, *nominal_box(case["eight_state"], veh.envelope))

    monkeypatch.setattr(forms, "design_tube_set", stored)
    r = copy.deepcopy(raw8)
    r["disturbance"]["samples"] = 40
    r["certificate"] = {"schedules": 0}
    r["tube"]["tau"] = 0.8
    r["tube"]["lam"] = r["tube"]["lam"][1:2]  # one of the vertex tube's three LMIs
    r["variants"] = ["tube_mpc"]  # the law that runs tau (the RMPC baseline's minute: not here)
    design = pmod.run_design(spec_file(r, "quick8_tau.yaml"), log=lambda *_: None)
    assert taus == [0.8]
    a, lim = design.arrays, vehicle.limits
    np.testing.assert_allclose(a["u_lo"], lim.u_min + 0.8 * ts.tightening, rtol=1e-12)
    np.testing.assert_allclose(a["u_hi"], lim.u_max - 0.8 * ts.tightening, rtol=1e-12)
    assert node_parameters(design)["tube_mpc"]["tau"] == 0.8
    run = simulate(design, "tube_mpc", duration=10.0)
    print(f"tau 0.8, 10 s: largest level in Z {run.tube_level.max():.4f}")
    assert 0.0 < run.tube_level.max() < 1.0


def test_a_nominal_box_without_room_for_the_faulty_trim_is_refused(raw8, monkeypatch):
    """delta_e down to -0.9 deg from the nominal trim: the lightest corner trims 1.007 deg
    below it, which leaves no room to manoeuvre; the design says so, naming the range."""
    import fahv.design.pipeline as pmod
    import fahv.design.tube_forms as forms
    from fahv.errors import DesignError

    ts = _stored_tube_set()
    monkeypatch.setattr(forms, "design_tube_set", lambda case, veh, *_, **__: (
        ts, *nominal_box(case["eight_state"], veh.envelope)))  # fmt: skip
    r = copy.deepcopy(raw8)
    r["disturbance"]["samples"] = 40
    r["certificate"] = {"schedules": 0}
    r["eight_state"]["delta_e"] = [-0.9, 7.0]
    r["tube"]["lam"] = r["tube"]["lam"][1:2]  # one of the vertex tube's three LMIs
    with pytest.raises(DesignError, match="eight_state.Phi / delta_e") as err:
        pmod.run_design(spec_file(r, "narrow.yaml"), log=lambda *_: None)
    print(err.value)
    need = float(re.search(r"delta_e -([\d.]+)\.\.\+[\d.]+ deg", str(err.value)).group(1))
    assert 1.0 < need < 1.02  # the lightest corner's trim, with the remainder between points


@pytest.mark.parametrize("closed", [True, False])
def test_a_designed_notch_gain_is_used_only_when_certified_and_closed(raw8, vehicle, monkeypatch,
                                                                       closed):  # fmt: skip
    """eight_state.notch_gain: designed. F_8's loop through the notch is checked first;
    when it is not certified, a gain is designed (notch_gain) and W_8 bounded again over
    the loop's own set (altitude_bound with the loop's joint shape). The variant gets the
    gain only if that bound lies inside W_8 and its H within the tube set's; otherwise it
    keeps F_8 and F_8's verdict, and the log says so."""
    from fahv.model.notch import NotchFilter

    ts = _stored_tube_set()
    R = 4

    class Vertices:
        J0 = np.zeros((64, 1))
        n_vehicles = [1]
        n_vertices = 4096

        def vertices(self):
            return np.tile(np.eye(9), (R, 1, 1)), np.zeros((R, 9, 2))

    base = NotchLoop("tube_mpc", 19.05, 0.1, 0.9991, 0.995, 0, float("inf"), None, None,
                     tuple(ts.tightening.tolist()))  # fmt: skip
    good = NotchLoop("tube_mpc", 19.05, 0.1, 0.9990, 0.995, 0, 0.99, 0.9999,
                     tuple((0.99 * ts.tightening).tolist()), tuple(ts.tightening.tolist()),
                     designed=True)  # fmt: skip
    F_new = 1.1 * ts.F_8
    seen = {}

    def gain(A, B, F, N, w, nf, Ts, iq, lam, continuation, variant, log):
        seen["gain"] = (A.shape, F is ts.F_8, continuation, nf.eps_p, iq)
        return NotchGain(F_new, np.eye(10), good, ((0.05, 0.98), (0.1, 0.99)))

    class Bound:
        H = ts.H * (0.99 if closed else 1.0)
        bound = ts.W_8 * (0.97 if closed else 1.02)

    def altitude(nv, A, B, F_8, N_8, moves, joint=None):
        seen["joint"] = joint.shape
        return Bound()

    monkeypatch.setattr(tsd, "nominal_vertices", lambda *a, **k: Vertices())
    monkeypatch.setattr(tsd, "close_tube_set", lambda *a, **k: ts)
    monkeypatch.setattr(tsd, "notch_tube", lambda *a, **k: base)
    monkeypatch.setattr(tsd, "notch_gain", gain)
    monkeypatch.setattr(tsd, "altitude_bound", altitude)
    r = copy.deepcopy(raw8)
    r["eight_state"].update(notch_gain="designed", notch_continuation=[0.05], onset_in_tube=0.0)
    lines = []
    got, _, _ = tsd.design_tube_set(spec_file(r, "gain.yaml").data, vehicle, None,
                                    np.ones(11), np.ones(9), np.ones(11), 0.76, np.ones(2),
                                    log=lines.append, notches={"tube_mpc": NotchFilter(
                                        19.05, 0.02, 19.05, 0.1)})  # fmt: skip
    assert seen["gain"] == ((R, 8, 8), True, [0.05], 0.1, 3)
    assert seen["joint"] == (10, 10)
    (loop,) = got.notch_loops
    if closed:
        assert got.notch_gains.keys() == {"tube_mpc"}
        np.testing.assert_array_equal(got.notch_gains["tube_mpc"], F_new)
        assert loop.designed and loop.certified
        np.testing.assert_allclose(loop.w_ratio, [0.99] + [0.97] * 8, rtol=1e-12)
    else:
        assert got.notch_gains == {}
        assert loop is base and not loop.certified
        assert "the variant runs F_8" in lines[-1]


def test_design_refuses_a_command_outside_the_nominal_range(raw8, vehicle):
    """The tube set is certified for a nominal inside the envelope less h_margin / V_margin:
    a design step beyond that range is refused before any design work, naming the point
    and the range; the range is what the QP gets as mpc.hv_box (and what a scenario is
    checked against, :func:`fahv.spec.scenario.uncertified`)."""
    from fahv.design.tube_forms import command_range
    from fahv.spec.scenario import design_part

    c = design_part(load_run_spec(CASE)).data
    np.testing.assert_allclose(command_range(c, vehicle.envelope),
                               [[85005.0, 7704.98], [86495.0, 8295.02]], rtol=1e-12)  # fmt: skip
    bad = {**c, "design_step": {**c["design_step"], "h_c": 86498.0}}  # 3 ft beyond the range
    with pytest.raises(DesignError, match=r"the command \(86498.0 ft, 8150.0 ft/s\) lies outside "
                       r"the nominal range .* h 85005..86495 ft"):  # fmt: skip
        command_range(bad, vehicle.envelope)


def test_the_shipped_designs_tube_set_is_its_design_files(vehicle):
    """The shipped cm_certified tube set (the one the sampling tests check) belongs to the
    design file as it stands: the same parameter directions and loss, and its nominal and
    scheduling boxes are the file's to 1e-12."""
    d = load_record("cm_certified")
    c = load_run_spec(CASE)
    assert int(d["k"]) == c["eight_state"]["k"] and float(d["rho_min"]) == c["tube"]["rho_min"]
    nominal, box = nominal_box(c["eight_state"], vehicle.envelope)
    for got, want in ((nominal, "nominal_"), (box, "")):
        np.testing.assert_allclose(got.lo, d[want + "lo"], rtol=1e-12)
        np.testing.assert_allclose(got.hi, d[want + "hi"], rtol=1e-12)
        np.testing.assert_allclose(got.other_half, d[want + "other_half"], rtol=1e-12)
