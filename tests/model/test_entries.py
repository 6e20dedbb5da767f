"""The entry reader of the vehicle file (fahv.model.entries), shared by every section."""

import copy
import math
from importlib import resources

import pytest
import yaml

from fahv.config.yamlio import load_yaml
from fahv.errors import VehicleDataError
from fahv.model.entries import Entry, read_entry, unit_factors
from fahv.model.vehicle import load_vehicle
from fahv.sensors.data import load_sensors

DATA = load_yaml(resources.files("fahv.data").joinpath("vehicle_parker2007.yaml").read_text())
GOOD = {"value": 0.18, "unit": "deg/s", "source": "Wiese"}


@pytest.mark.parametrize(
    ("entry", "message"),
    [
        (
            {"value": 0.18, "unit": "deg/s"},
            "veh.yaml: 'sensors.q.stddev' has no 'source'",
        ),
        (
            {**GOOD, "source": ""},
            "veh.yaml: 'sensors.q.stddev' has no 'source'",
        ),
        (
            {**GOOD, "value": float("nan")},
            "veh.yaml: 'sensors.q.stddev' must be finite, got nan",
        ),
        (
            {**GOOD, "value": 10**400},
            "veh.yaml: 'sensors.q.stddev' must be finite, got " + repr(10**400),
        ),
        (
            {**GOOD, "value": True},
            "veh.yaml: 'sensors.q.stddev' must be a number, got True",
        ),
        (
            {**GOOD, "unit": "ft"},
            "veh.yaml: 'sensors.q.stddev' has unit 'ft'; expected one of ['deg/s', 'rad/s']",
        ),
        (
            {"value": 0.18, "source": "Wiese"},
            "veh.yaml: 'sensors.q.stddev' has unit None; expected one of ['deg/s', 'rad/s']",
        ),
        (
            {"unit": "deg/s", "source": "Wiese"},
            "veh.yaml: missing key 'sensors.q.stddev.value'",
        ),
        (
            0.18,
            "veh.yaml: 'sensors.q.stddev' must be a mapping with 'value', 'unit', 'source', "
            "got float",
        ),
    ],
)
def test_a_bad_entry_is_rejected_naming_the_file_and_the_full_key(entry, message):
    with pytest.raises(VehicleDataError) as err:
        read_entry({"stddev": entry}, "stddev", "veh.yaml", "sensors.q", unit_factors("rad/s"))
    assert str(err.value) == message


def test_a_missing_entry_is_named():
    with pytest.raises(VehicleDataError) as err:
        read_entry({"stddev": GOOD}, "mean", "veh.yaml", "sensors.q", unit_factors("rad/s"))
    assert str(err.value) == "veh.yaml: missing key 'sensors.q.mean'"


def test_a_good_entry_is_read_in_the_unit_asked_for():
    e = read_entry({"stddev": GOOD}, "stddev", "veh.yaml", "sensors.q", unit_factors("rad/s"))
    assert e == Entry(0.18 * (math.pi / 180.0), "deg/s", "Wiese", False)  # as math.radians
    # no units: any unit, the value as written; no source needed for a design choice
    scale = {"value": 5, "unit": "generalized coordinate/s", "representative": True}
    e = read_entry({"eta_1_dot": scale}, "eta_1_dot", "veh.yaml", "scales", sourced=False)
    assert e == Entry(5.0, "generalized coordinate/s", "", True)
    assert unit_factors("rad/s/s") == {"rad/s/s": 1.0, "deg/s/s": math.pi / 180.0}
    assert unit_factors("1/s") == {"1/s": 1.0} and unit_factors("-") == {"-": 1.0}


#: One entry of each section that reads its entries with `read_entry`, and its loader.
SECTIONS = [
    (("parameters", "c_e"), "parameters.c_e", load_vehicle),
    (("scales", "q"), "scales.q", load_vehicle),
    (
        ("actuators", "second_order", "delta_e", "omega_n"),
        "actuators.second_order.delta_e.omega_n",
        load_vehicle,
    ),
    (("sensors", "q", "stddev"), "sensors.q.stddev", load_sensors),
    (("sensors", "gyro_mode_slopes", "phi_1"), "sensors.gyro_mode_slopes.phi_1", load_sensors),
]


def _file_with(tmp_path, keys, **changes):
    data = copy.deepcopy(DATA)
    entry = data
    for k in keys:
        entry = entry[k]
    entry.update(changes)
    for k, v in list(entry.items()):
        if v is None:
            del entry[k]
    p = tmp_path / "veh.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


@pytest.mark.parametrize(("keys", "full", "load"), SECTIONS)
def test_every_section_rejects_a_bad_entry_with_the_same_message(tmp_path, keys, full, load):
    p = _file_with(tmp_path, keys, value=float("nan"))
    with pytest.raises(VehicleDataError) as err:
        load(p)
    assert str(err.value) == f"{p}: '{full}' must be finite, got nan"
    if keys[0] == "scales":
        return  # scales are design choices: no source, any unit
    p = _file_with(tmp_path, keys, source=None)
    with pytest.raises(VehicleDataError) as err:
        load(p)
    assert str(err.value) == f"{p}: '{full}' has no 'source'"


def test_sections_with_units_reject_a_wrong_unit(tmp_path):
    p = _file_with(tmp_path, ("sensors", "theta", "stddev"), unit="rad/s")
    with pytest.raises(VehicleDataError) as err:
        load_sensors(p)
    assert str(err.value) == (
        f"{p}: 'sensors.theta.stddev' has unit 'rad/s'; expected one of ['deg', 'rad']"
    )
    p = _file_with(tmp_path, ("actuators", "second_order", "Phi", "zeta"), unit="deg")
    with pytest.raises(VehicleDataError) as err:
        load_vehicle(p)
    assert str(err.value) == (
        f"{p}: 'actuators.second_order.Phi.zeta' has unit 'deg'; expected one of ['-']"
    )
