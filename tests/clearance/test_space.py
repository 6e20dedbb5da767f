"""The search space of a clearance (fahv.clearance.space) is the campaign's dispersion space:
its points give the values the campaign's draws give, through the same code."""

import numpy as np
import pytest
import yaml

from fahv.campaign.draws import draw, run_seed
from fahv.campaign.spec import load_campaign
from fahv.clearance.space import SearchSpace
from fahv.errors import CampaignError
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.sil.workspace import ROOT


def _campaign(tmp_path, scenario="case1", **dispersions):
    data = {"name": "space", "scenario": str(ROOT / f"offline_design/scenarios/{scenario}.yaml"),
            "seed": 7, "runs": 20, "variants": ["tube_mpc"], "duration": 10.0,
            "dispersions": dispersions}  # fmt: skip
    path = tmp_path / "space.yaml"
    path.write_text(yaml.safe_dump(data))
    return load_campaign(path)


EVERY = {
    "uncertainty": {"method": "uniform", "parameters": ["m", "c_e", "beta_1"]},
    "fault": {"kinds": ["loss_of_effectiveness", "bias"], "loss": [0.0, 0.2],
              "bias_deg": [-1.0, 1.0], "onset": [5.0, 200.0]},
    "command": {"dh": [-300.0, 600.0]},
    "initial": {"h0": [85300.0, 85700.0], "V0": [7850.0, 7950.0]},
}  # fmt: skip


def _point(space, values):
    """The point of the space whose values are a draw's (choices: their index)."""
    x = []
    for v in space.variables:
        if v.choices:
            x.append(float(v.choices.index(values["fault.kind"])) + 0.5)
        else:
            x.append(values[v.name])
    return np.array(x)


def test_a_point_gives_the_draws_values(tmp_path):
    """At the point of draw i's values, `values` returns draw i exactly (every key, in the
    same order), for 20 draws of a campaign that disperses every group but the hardware;
    its variables are the ranged ones with their bounds."""
    c = _campaign(tmp_path, **EVERY)
    space = SearchSpace.of(c.data, c.run_spec.data)
    assert space.names == ["s.m", "s.c_e", "s.beta_1", "fault.kind", "fault.t_onset",
                           "fault.loss", "fault.bias_deg", "initial.h0", "initial.V0",
                           "command.dh"]  # fmt: skip
    assert space.bounds[3] == (0.0, 2.0) and space.bounds[4] == (5.0, 200.0)
    for i in range(20):
        values = draw(c.data, c.run_spec.data, i)
        assert list(space.values(_point(space, values)).items()) == list(values.items()), i


def test_the_sensor_noise_held_or_searched(tmp_path):
    """On a loop with sensors the noise seed is run 0's by default, or a variable over the
    campaign's first K seeds; on the exact state there is none."""
    c = _campaign(tmp_path, "case1_implementable", uncertainty={"method": "uniform"})
    held = SearchSpace.of(c.data, c.run_spec.data)
    x = np.zeros(len(held.variables))
    assert held.values(x)["sensor_seed"] == run_seed(7, 0)
    assert held.names == [f"s.{p}" for p in PAPER_UNCERTAINTY]
    searched = SearchSpace.of(c.data, c.run_spec.data, noise_seeds=4)
    assert searched.names[-1] == "noise" and searched.bounds[-1] == (0.0, 4.0)
    seeds = {searched.values(np.r_[x, k + 0.5])["sensor_seed"] for k in range(4)}
    assert seeds == {run_seed(7, k) for k in range(4)}
    exact = _campaign(tmp_path, uncertainty={"method": "uniform"})
    assert "sensor_seed" not in SearchSpace.of(exact.data, exact.run_spec.data).values(x)


def test_bad_points_and_an_empty_space_are_refused(tmp_path):
    c = _campaign(tmp_path, **EVERY)
    space = SearchSpace.of(c.data, c.run_spec.data)
    lo = np.array([b[0] for b in space.bounds])
    with pytest.raises(ValueError, match="10 finite values"):
        space.values(lo[:3])
    with pytest.raises(ValueError, match="outside the search box"):
        space.values(lo - 1.0)
    with pytest.raises(ValueError, match="10 finite values"):
        space.values(np.r_[lo[:-1], np.nan])
    none = _campaign(tmp_path, uncertainty={"method": "none"})
    with pytest.raises(CampaignError, match="range nothing to search"):
        SearchSpace.of(none.data, none.run_spec.data)


def test_a_scenario_names_its_vehicle_by_its_s_p(tmp_path):
    """`uncertainty.s` of a scenario: ten values in [-1, 1] or none; other lengths and values
    are refused naming the key."""
    from fahv.errors import ConfigError
    from fahv.spec.files import spec_file
    from fahv.spec.schema import scenario_spec

    base = yaml.safe_load((ROOT / "offline_design/scenarios/case1.yaml").read_text())
    ok = {**base, "uncertainty": {"seed": 1, "scale": 1.0, "s": [0.5] * 10}}
    assert spec_file(ok, "ok.yaml", scenario_spec()).data["uncertainty"]["s"] == [0.5] * 10
    for s, why in (([0.5] * 3, "must be empty or hold 10 values"), ([1.5] * 10, "uncertainty.s")):
        bad = {**base, "uncertainty": {"seed": 1, "scale": 1.0, "s": s}}
        with pytest.raises(ConfigError, match=why):
            spec_file(bad, "bad.yaml", scenario_spec())
