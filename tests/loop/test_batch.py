"""The batched simulator gives every run the bits of simulate(), whatever its batch."""

import math

import numpy as np
import pytest

from fahv.errors import ParameterError, RunError
from fahv.loop.batch import shared_signature, simulate_batch
from fahv.loop.simulate import run_parameters, simulate

FIELDS = ("t", "x", "q_f", "x_r", "x_n", "u", "u_applied", "h_c", "V_c", "h_g", "V_g",
          "tube_level", "fault_active", "lmi_counts", "qp_counts")  # fmt: skip
DURATION = 3.0


def _overrides(design):
    """Runs with every fault kind, perturbed parameters, other commands and starts."""
    base = design.summary["plant_params"]
    rng = np.random.default_rng(5)
    kinds = [("loss_of_effectiveness", {"rho_f": 0.75}), ("bias", {"bias_deg": -2.5}),
             ("stuck", {}), ("dropout", {}), ("none", {})]  # fmt: skip
    out = []
    for i, (kind, extra) in enumerate(kinds):
        ov = {
            "plant": {f"params.{k}": v * (1 + 0.08 * rng.uniform(-1, 1)) for k, v in base.items()},
            "fault_injector": {"kind": kind, "t_onset": 0.4 + 0.5 * i, **extra},
        }
        if i == 1:
            ov["nominal_trajectory"] = {"command.h_c": 85200.0, "command.V_c": 7800.0}
        out.append(ov)
    return out


def _assert_same(a, b):
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert np.array_equal(x, y, equal_nan=x.dtype.kind == "f"), f
    assert a.info == b.info


def test_runs_share_a_batch_only_when_only_their_own_values_differ(design):
    base = run_parameters(design, "tube_mpc", 1.0, None)
    own = run_parameters(design, "tube_mpc", 1.0, _overrides(design)[1])
    assert shared_signature(base) == shared_signature(own)  # parameters, fault, command
    other = run_parameters(design, "tube_mpc", 1.0, {"tube_mpc": {"tau": 0.9}})
    assert shared_signature(base) != shared_signature(other)


@pytest.mark.parametrize("variant", ["tube_mpc", "tube_mpc_paper"])
def test_batch_equals_simulate_bit_for_bit(design, variant):
    ovs = _overrides(design)
    batch = simulate_batch(design, variant, ovs, DURATION)
    for ov, res in zip(ovs, batch, strict=True):
        _assert_same(simulate(design, variant, DURATION, overrides=ov), res)
    # the faults did act: the elevator loss scaled delta_e by 0.75 once active
    r = batch[0]
    on = r.fault_active
    assert on.any() and not on.all()
    np.testing.assert_allclose(r.u_applied[on, 1], 0.75 * r.u[on, 1], rtol=1e-15)


def test_result_does_not_depend_on_the_batch(design):
    ovs = _overrides(design)
    alone = simulate_batch(design, "tube_mpc", ovs[2:3], DURATION)[0]
    together = simulate_batch(design, "tube_mpc", ovs[::-1], DURATION)[2]
    _assert_same(alone, together)


@pytest.mark.parametrize("variant", ["tube_mpc_no_notch", "tube_mpc_notch2"])
def test_notch_variants_batched_and_equal(design, variant):
    ovs = _overrides(design)[:2]
    for ov, res in zip(ovs, simulate_batch(design, variant, ovs, 1.0), strict=True):
        _assert_same(simulate(design, variant, 1.0, overrides=ov), res)


def test_failing_runs_are_reported_and_the_others_complete(design):
    ovs = [None, {"plant": {"params.m": math.nan}}, {"plant": {"params.I_yy": 1e-3}}, None]
    res = simulate_batch(design, "tube_mpc", ovs, 4.0)
    assert isinstance(res[1], ParameterError)
    assert "params.m" in str(res[1]) and "finite" in str(res[1])
    assert isinstance(res[2], RunError)
    with pytest.raises(RunError) as exc:  # the same failure, at the same step, as simulate
        simulate(design, "tube_mpc", 4.0, overrides=ovs[2])
    assert str(res[2]) == str(exc.value)
    t_fail = float(str(res[2]).split("at t = ")[1].split(" s")[0])
    assert 1.0 < t_fail < 4.0  # the inertia 1e-3 of the nominal diverges in about 2 s
    # what the failed run flew is kept: every step before the failing one, all finite
    assert res[1].partial is None  # never built
    part = res[2].partial
    assert part.t.size == round(t_fail / part.info["Ts"])
    assert part.t[-1] == pytest.approx(t_fail - part.info["Ts"], abs=1e-9)
    assert np.isfinite(part.x).all() and np.isfinite(part.u).all()
    _assert_same(simulate(design, "tube_mpc", 4.0), res[0])
    _assert_same(res[0], res[3])


def test_rmpc_runs_batched_and_equal(paper_scenario_design):
    design = paper_scenario_design
    ovs = [{"fault_injector": {"kind": "bias", "t_onset": 0.0, "bias_deg": 1.0}}, None]
    ovs.append({"plant": {"params.m": 1.05 * design.summary["plant_params"]["m"]}})
    res = simulate_batch(design, "rmpc", ovs, 20.0)
    for ov, r in zip(ovs, res, strict=True):
        _assert_same(simulate(design, "rmpc", 20.0, overrides=ov), r)
    # off-line law: no online solve, every state inside the largest ellipsoid
    assert all(r.lmi_counts.tolist() == [0] for r in res)
    assert not np.array_equal(res[1].x, res[2].x)  # the runs differ, each equals simulate


def test_case2_eleven_state_law_batched_and_equal(case2_design):
    d = case2_design
    assert d.n_x == 11
    ovs = [{"fault_injector": {"kind": k, "t_onset": 0.5, "rho_f": 0.8, "bias_deg": 1.0}}
           for k in ("loss_of_effectiveness", "bias")]  # fmt: skip
    # the ECM's estimator measures in ECM coordinates (a replica of the notch filter)
    for ov, res in zip(ovs, simulate_batch(d, "tube_mpc", ovs, 1.5), strict=True):
        _assert_same(simulate(d, "tube_mpc", 1.5, overrides=ov), res)
        assert res.x_n.shape == (75, 11)


def test_nonlinear_nominal_refuses_the_eleven_state_design(case2_design):
    """mpc.nominal_model 'cm' moves the nominal by the 9-state CM: an ECM design (11
    states, q' and x_q) is refused with a RunError that names the key and the size."""
    from fahv.loop.cores import build_core
    from fahv.loop.params import node_parameters

    p = node_parameters(case2_design, "tube_mpc")["nominal_trajectory"]
    p["mpc.nominal_model"] = "cm"
    with pytest.raises(RunError, match=r"mpc\.nominal_model 'cm' needs the 9-state CM design, "
                       r"got 11 states"):  # fmt: skip
        build_core("nominal_trajectory", p)


def test_a_stuck_elevator_ends_simulate_and_the_batch_with_the_same_verdict():
    """Case 1 with the elevator stuck from 1 s: the nominal MPC's operating point leaves the
    trim map (where its Jacobian would be singular); both paths end there, the batch's
    other run completes."""
    from fahv.certificate.verified import load_or_design
    from fahv.sil.workspace import ROOT
    from fahv.verdict import RunEnded

    _, case1, _ = load_or_design(ROOT / "offline_design/scenarios/case1.yaml", log=lambda *_: None)
    stuck = {"fault_injector": {"kind": "stuck", "t_onset": 1.0}}
    with pytest.raises(RunEnded) as alone:
        simulate(case1, "tube_mpc", 8.0, overrides=stuck)
    res = simulate_batch(case1, "tube_mpc", [stuck, None], 8.0)
    v = alone.value.verdict
    assert res[0].verdict == v
    assert (v.name, v.node, v.step, v.t) == (
        "nominal_out_of_domain",
        "nominal_trajectory",
        275,
        5.5,
    )
    assert "(h, V) = (85552.7 ft, 7631.1 ft/s) left the trim map" in v.reason
    np.testing.assert_array_equal(res[0].partial.x, alone.value.partial.x)
    assert res[0].partial.t.size == 275 and np.isfinite(res[0].partial.x).all()
    assert res[1].t.size == 400  # the run without fault flies its 8 s
