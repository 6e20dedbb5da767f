import copy
import warnings

import pytest
import yaml

from fahv.config.yamlio import load_yaml
from fahv.design.case import case_from_mapping
from fahv.design.pipeline import run_design
from fahv.model.tp_model import build_tp_model
from fahv.model.vehicle import load_vehicle

CASE1 = "offline_design/case1.yaml"


@pytest.fixture(scope="session")
def vehicle():
    return load_vehicle()


@pytest.fixture(scope="session")
def tp_cm(vehicle):
    """20-vertex CM TP model on a coarse 11 x 11 grid (shared by the tube tests)."""
    return build_tp_model(vehicle, "cm", 4, 5, 11, 11)


@pytest.fixture(scope="session")
def raw():
    with open(CASE1) as fh:
        return load_yaml(fh.read())


def quick(raw, **changes):
    """Case 1 with a small W sample (CI) and the given top-level changes."""
    d = copy.deepcopy(raw)
    d["disturbance"]["samples"] = 40
    d.update(changes)
    return case_from_mapping(d, "quick.yaml")


@pytest.fixture(scope="session")
def make_case(raw):
    """Factory of quick cases: ``make_case(**changes)`` (Case 1, small W sample)."""
    return lambda **changes: quick(raw, **changes)


@pytest.fixture(scope="session")
def design(raw):
    """Case 1 designed with a small W sample (shared by the design, SIL and log tests)."""
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    return run_design(quick(raw), log=lambda *_: None)


@pytest.fixture(scope="session")
def quick_case(design, raw, tmp_path_factory):
    """The test design as a case file plus its saved artefacts, for the `fahv` command:
    (case file, artefact folder) to pass as ``fahv simulate|sil CASE --design DIR``."""
    from fahv.design.artefacts import save_design
    from fahv.loop.params import node_parameters, parameter_file

    folder = tmp_path_factory.mktemp("case")
    d = copy.deepcopy(raw)
    d["disturbance"]["samples"] = 40
    case_file = folder / "quick.yaml"
    case_file.write_text(yaml.safe_dump(d, sort_keys=False))
    params = yaml.safe_dump(parameter_file(node_parameters(design)), sort_keys=False)
    save_design(design, folder / "artefacts", {"params.yaml": params})
    return case_file, folder / "artefacts"
