import copy
import warnings

import pytest

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
