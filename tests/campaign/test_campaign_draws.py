import numpy as np
import pytest

from fahv.campaign.draws import draw, overrides, run_rng, scatter_columns
from fahv.campaign.spec import load_campaign
from fahv.model.trim import TrimMap
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY


@pytest.fixture
def campaign(write_campaign):
    return load_campaign(write_campaign("draws"))


def test_run_streams_are_the_seed_sequence_children():
    # run i, stream j: child j of child i of SeedSequence(seed) (spawn keyed by index)
    child = np.random.SeedSequence(11).spawn(4)[3].spawn(2)[1]
    assert run_rng(11, 3, "fault").random() == np.random.default_rng(child).random()


def test_a_run_is_a_function_of_seed_and_index(campaign):
    a = draw(campaign.data, campaign.run_spec.data, 5)
    assert a == draw(campaign.data, campaign.run_spec.data, 5)
    assert a != draw(campaign.data, campaign.run_spec.data, 6)
    other = dict(campaign.data, seed=12)
    assert a != draw(other, campaign.run_spec.data, 5)
    # more runs in the campaign do not change run 5 (uniform draws)
    assert a == draw(dict(campaign.data, runs=500), campaign.run_spec.data, 5)


def test_values_stay_in_their_ranges(campaign):
    d = campaign["dispersions"]
    for i in range(campaign["runs"]):
        v = draw(campaign.data, campaign.run_spec.data, i)
        assert all(-1.0 <= v[f"s.{k}"] <= 1.0 for k in PAPER_UNCERTAINTY)
        assert v["fault.kind"] in d["fault"]["kinds"]
        assert 1.0 <= v["fault.t_onset"] <= 4.0 and 0.7 <= v["fault.rho_f"] <= 1.0
        assert 85300.0 <= v["initial.h0"] <= 85700.0
        assert v["command.h_c"] == pytest.approx(v["initial.h0"] + v["command.dh"], abs=1e-9)
        assert -300.0 <= v["command.dh"] <= 600.0


def test_corners_visit_every_corner_once(campaign):
    data = dict(campaign.data, runs=8)
    data["dispersions"] = dict(data["dispersions"], uncertainty={
        "method": "corners", "scale": 1.0, "parameters": ["m", "I_yy", "c_e"]})  # fmt: skip
    corners = {tuple(draw(data, campaign.run_spec.data, i)[f"s.{k}"] for k in ("m", "I_yy", "c_e"))
               for i in range(8)}  # fmt: skip
    assert len(corners) == 8 and all(abs(c) == 1.0 for corner in corners for c in corner)


def test_latin_hypercube_is_stratified(campaign):
    n = 40
    data = dict(campaign.data, runs=n)
    data["dispersions"] = dict(data["dispersions"], uncertainty={
        "method": "lhs", "scale": 1.0, "parameters": list(PAPER_UNCERTAINTY)})  # fmt: skip
    s = np.array([[draw(data, campaign.run_spec.data, i)[f"s.{k}"] for k in PAPER_UNCERTAINTY]
                  for i in range(n)])  # fmt: skip
    for j in range(s.shape[1]):  # one point in each of the n strata of every parameter
        assert sorted(np.floor((s[:, j] + 1.0) / 2.0 * n).astype(int)) == list(range(n))


def test_overrides_carry_the_values_to_the_nodes(campaign, design):
    v = draw(campaign.data, campaign.run_spec.data, 2)
    ov = overrides(v, design, "tube_mpc")
    vp = load_vehicle().params
    for k, r in PAPER_UNCERTAINTY.items():
        assert ov["plant"][f"params.{k}"] == pytest.approx(getattr(vp, k) * (1 + v[f"s.{k}"] * r),
                                                           rel=1e-14)  # fmt: skip
    f = ov["fault_injector"]
    assert f["kind"] == v["fault.kind"] and f["t_onset"] == v["fault.t_onset"]
    a = design.arrays
    tm = TrimMap(a["trim_h"], a["trim_V"], a["trim_x"], a["trim_u"])
    x0 = tm(v["initial.h0"], v["initial.V0"])[0]
    np.testing.assert_array_equal(ov["plant"]["x0"], x0[:9])
    assert ov["plant"]["x0"][0] == pytest.approx(v["initial.h0"], abs=1e-6)
    assert ov["nominal_trajectory"]["command.h_c"] == v["command.h_c"]
    assert ov["state_estimator"]["x0"] == ov["plant"]["x0"]  # the filter starts there too
    assert scatter_columns(campaign.data)[-2:] == ["initial.h0", "initial.V0"]


def test_a_campaign_on_part_of_the_box_perturbs_by_that_part(campaign, design):
    """`uncertainty.scale` 0.5: the drawn s_p move each parameter by s_p 0.5 rel_p, in the
    campaign's runs (`run_batch`'s overrides) and in a rerun alike."""
    from fahv.campaign.draws import uncertainty_scale

    data = dict(campaign.data)
    data["dispersions"] = dict(data["dispersions"], uncertainty={
        **data["dispersions"]["uncertainty"], "scale": 0.5})  # fmt: skip
    assert uncertainty_scale(data) == 0.5
    v = draw(data, campaign.run_spec.data, 2)
    ov = overrides(v, design, "tube_mpc", uncertainty_scale(data))
    vp = load_vehicle().params
    for k, r in PAPER_UNCERTAINTY.items():
        assert ov["plant"][f"params.{k}"] == pytest.approx(
            getattr(vp, k) * (1 + 0.5 * v[f"s.{k}"] * r), rel=1e-14)


def test_a_campaign_on_the_sensors_gives_every_run_its_own_noise(campaign, design):
    """On a case whose estimator reads noisy sensors, each run draws its own sensor seed
    (the plant's `sensor_seed`), a function of (seed, index); on the exact state none."""
    assert "sensor_seed" not in draw(campaign.data, campaign.run_spec.data, 0)
    case = dict(campaign.run_spec.data, estimator={"kind": "kalman"})
    seeds = [draw(campaign.data, case, i)["sensor_seed"] for i in range(campaign["runs"])]
    assert len(set(seeds)) == campaign["runs"]
    assert seeds[3] == draw(campaign.data, case, 3)["sensor_seed"]
    ov = overrides({"sensor_seed": seeds[3]}, design, "tube_mpc")
    assert ov == {"plant": {"sensor_seed": seeds[3]}}
