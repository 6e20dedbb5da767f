import copy
import warnings

import pytest

from fahv.case import case_from_mapping
from fahv.design import run_design
from fahv.tp_model import build_tp_model
from fahv.vehicle import load_vehicle
from fahv.yamlio import load_yaml

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
def design(raw):
    """Case 1 designed with a small W sample (shared by the design, SIL and log tests)."""
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    return run_design(quick(raw), log=lambda *_: None)
