import pytest

from fahv.vehicle import load_vehicle


@pytest.fixture(scope="session")
def vehicle():
    return load_vehicle()
