import pytest

from fahv.tp_model import build_tp_model
from fahv.vehicle import load_vehicle


@pytest.fixture(scope="session")
def vehicle():
    return load_vehicle()


@pytest.fixture(scope="session")
def tp_cm(vehicle):
    """20-vertex CM TP model on a coarse 11 x 11 grid (shared by the tube tests)."""
    return build_tp_model(vehicle, "cm", 4, 5, 11, 11)
