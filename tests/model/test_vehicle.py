"""Vehicle data file validation and model structure."""

import numpy as np
import pytest
import yaml

from fahv.config.yamlio import load_yaml
from fahv.errors import VehicleDataError
from fahv.model.dynamics import cm_rhs, ecm_rhs, make_model
from fahv.model.notch import NotchFilter
from fahv.model.trim import trim
from fahv.model.vehicle import IQ, load_vehicle

DATA = (
    load_vehicle.__globals__["resources"]
    .files("fahv.data")
    .joinpath("vehicle_parker2007.yaml")
    .read_text()
)


def _write(tmp_path, mutate):
    data = load_yaml(DATA)
    mutate(data)
    p = tmp_path / "veh.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


def test_packaged_file_loads_with_sources(vehicle):
    assert vehicle.params.m == 300.0 and vehicle.params.I_yy == 5.0e5
    # flexible data is marked representative, rigid data is not
    assert "omega_1" in vehicle.representative and "N2_de" in vehicle.representative
    assert "m" not in vehicle.representative and "c_e" not in vehicle.representative


def test_missing_key_named(tmp_path):
    p = _write(tmp_path, lambda d: d["parameters"].pop("I_yy"))
    with pytest.raises(VehicleDataError, match=r"missing key 'parameters.I_yy'"):
        load_vehicle(p)


def test_non_numeric_value_named(tmp_path):
    p = _write(tmp_path, lambda d: d["parameters"]["S"].update(value="seventeen"))
    with pytest.raises(VehicleDataError, match=r"'parameters.S' must be a number"):
        load_vehicle(p)


def test_non_finite_value_named(tmp_path):
    p = _write(tmp_path, lambda d: d["parameters"]["c_e"].update(value=float("nan")))
    with pytest.raises(VehicleDataError, match=r"'parameters.c_e' must be finite"):
        load_vehicle(p)


@pytest.mark.parametrize("key", ["m", "I_yy", "omega_2"])
def test_non_physical_value_named(tmp_path, key):
    p = _write(tmp_path, lambda d: d["parameters"][key].update(value=0.0))
    with pytest.raises(VehicleDataError, match=rf"'parameters.{key}' = 0.0 is not physical"):
        load_vehicle(p)


def test_missing_source_and_unknown_key(tmp_path):
    p = _write(tmp_path, lambda d: d["parameters"]["m"].pop("source"))
    with pytest.raises(VehicleDataError, match=r"'parameters.m' has no 'source'"):
        load_vehicle(p)
    p = _write(tmp_path, lambda d: d["parameters"].update(mass={"value": 1, "source": "x"}))
    with pytest.raises(VehicleDataError, match=r"unknown parameter\(s\) \['mass'\]"):
        load_vehicle(p)


def test_missing_and_malformed_file(tmp_path):
    with pytest.raises(VehicleDataError, match="vehicle file not found"):
        load_vehicle(tmp_path / "nope.yaml")
    bad = tmp_path / "bad.yaml"
    bad.write_text("parameters: [1, 2\n")
    with pytest.raises(VehicleDataError, match="not valid YAML"):
        load_vehicle(bad)


def test_yaml_1_2_floats_accepted(tmp_path):
    p = tmp_path / "v.yaml"
    p.write_text(DATA.replace("value: 5.0e5", "value: 4e5"))
    assert load_vehicle(p).params.I_yy == 4.0e5


def test_cm_flexible_coupling_solved_exactly(vehicle):
    """The coupled eta_ddot pair of eq. (1) holds as written (both equations)."""
    vp = vehicle.params
    x = np.array([85500.0, 7900.0, 0.03, 0.02, 0.01, 1.5, 0.3, 0.7, -0.2])
    u = np.array([0.3, 0.2])
    f = cm_rhs(x, u, vp)
    from fahv.model.dynamics import forces

    _, _, _, M, N1, N2 = forces(x, u, vp)
    k1, k2 = 1 + vp.psi_1**2 / vp.I_yy, 1 + vp.psi_2**2 / vp.I_yy
    e1, e2 = f[6], f[8]
    r1 = (
        -2 * vp.zeta_1 * vp.omega_1 * x[6]
        - vp.omega_1**2 * x[5]
        + N1
        - vp.psi_1 * M / vp.I_yy
        - vp.psi_1 * vp.psi_2 * e2 / vp.I_yy
    ) / k1
    r2 = (
        -2 * vp.zeta_2 * vp.omega_2 * x[8]
        - vp.omega_2**2 * x[7]
        + N2
        - vp.psi_2 * M / vp.I_yy
        - vp.psi_2 * vp.psi_1 * e1 / vp.I_yy
    ) / k2
    assert e1 == pytest.approx(r1, rel=1e-12)
    assert e2 == pytest.approx(r2, rel=1e-12)
    assert f[IQ] == pytest.approx((M + vp.psi_1 * e1 + vp.psi_2 * e2) / vp.I_yy, rel=1e-12)


def test_ecm_is_cm_in_series_with_notch(vehicle):
    """ECM rows equal CM rows with q recovered from q' (eq. 39) and the filter rows."""
    notch = NotchFilter(19.05, 0.02, 19.05, 0.5)
    A_q, B_q, C_q, D_q = notch.ss()
    x_cm = np.array([85500.0, 7900.0, 0.03, 0.02, 0.01, 1.5, 0.3, 0.7, -0.2])
    x_q = np.array([0.002, -0.0001])
    qp = C_q @ x_q + D_q * x_cm[IQ]
    x_e = np.concatenate([x_cm[:4], [qp], x_cm[5:], x_q])
    u = np.array([0.3, 0.2])
    fe = ecm_rhs(x_e, u, vehicle.params, A_q, B_q, C_q, D_q)
    fc = cm_rhs(x_cm, u, vehicle.params)
    rows = [0, 1, 2, 3, 5, 6, 7, 8]
    np.testing.assert_allclose(fe[rows], fc[rows], rtol=1e-13)
    xq_dot = A_q @ x_q + B_q * x_cm[IQ]
    np.testing.assert_allclose(fe[9:], xq_dot, rtol=1e-13)
    assert fe[IQ] == pytest.approx(C_q @ xq_dot + D_q * fc[IQ], rel=1e-13)


def test_ecm_trim_has_zero_filter_states(vehicle):
    notch = NotchFilter(19.05, 0.02, 19.05, 0.5)
    tp = trim(vehicle, 85500.0, 7900.0, "ecm", notch=notch)
    m = make_model("ecm", vehicle, notch)
    assert np.max(np.abs(m.f(tp.x_r_ecm, tp.u_r) / m.state_scale(vehicle, notch))) < 1e-8


def test_a_vehicle_file_is_parsed_once_per_content(tmp_path, monkeypatch):
    """A campaign loads the vehicle many times: parsed once per process and content, read
    again each time, so an edited file is seen; every caller gets its own document."""
    from fahv.model import vehicle as vehicle_module
    from fahv.sensors.data import load_sensors

    path = tmp_path / "vehicle.yaml"
    text = (vehicle_module.resources.files("fahv.data") / "vehicle_parker2007.yaml").read_text()
    path.write_text(text)
    calls = []
    parse = vehicle_module.load_yaml
    monkeypatch.setattr(vehicle_module, "load_yaml", lambda t: calls.append(1) or parse(t))
    a = load_vehicle(path)
    assert load_vehicle(path) is a and load_sensors(path) is load_sensors(path)
    assert len(calls) == 1
    doc, _ = vehicle_module.read_vehicle_file(path)
    doc["params"] = None  # a caller's copy: the cache is untouched
    assert load_sensors(path) is not None and len(calls) == 1
    path.write_text(text.replace("name: parker2007-curve-fit", "name: edited"))
    assert load_vehicle(path).name == "edited" and len(calls) == 2
