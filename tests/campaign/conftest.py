import copy
import functools

import pytest
import yaml


@pytest.fixture(scope="session")
def mc_dir(tmp_path_factory, design, store_as_files):
    """A folder with the quick Case 1 design stored as `fahv` finds it, and its scenario."""
    d = tmp_path_factory.mktemp("mc")
    store_as_files(design, d)
    return d


BASE = {
    "name": "t",
    "scenario": "scenarios/quick.yaml",
    "seed": 11,
    "runs": 12,
    "variants": ["tube_mpc"],
    "duration": 6.0,
    "batch_size": 2,
    "dispersions": {
        "uncertainty": {"method": "uniform"},
        "fault": {
            "kinds": ["loss_of_effectiveness", "bias", "dropout"],
            "loss": [0.0, 0.24],
            "bias_deg": [-2.0, 2.0],
            "onset": [1.0, 4.0],
        },
        "command": {"dh": [-300.0, 600.0], "dV": [-100.0, 250.0]},
        "initial": {"h0": [85300.0, 85700.0], "V0": [7850.0, 7950.0]},
    },
}


def campaign_file(folder, name, scenario=None, **changes):
    """Path of campaign file `name` written into `folder`: `BASE` with `changes` (a
    dispersion group's or a top-level key's) and, given, another `scenario`."""
    data = copy.deepcopy(BASE)
    data["name"] = name
    if scenario is not None:
        data["scenario"] = scenario
    for key, value in changes.items():
        if key in data["dispersions"]:
            data["dispersions"][key] = value
        else:
            data[key] = value
    path = folder / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


@pytest.fixture(scope="session")
def write_campaign(mc_dir):
    """``write_campaign(name, **changes)`` -> path of a campaign file next to the case."""
    return functools.partial(campaign_file, mc_dir)
