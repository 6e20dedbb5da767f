"""The measurement of B runs: channels, noise statistics, pipeline, faults, bounds."""

import math
import re
from pathlib import Path

import numpy as np
import pytest

from fahv.errors import ConfigError, VehicleDataError
from fahv.model.vehicle import ETA1_DOT, ETA2_DOT, IQ
from fahv.sensors.data import DEFAULT_MEASURED, load_sensors, replace_channel, sensors_from_mapping
from fahv.sensors.faults import SENSOR_FAULTS, sensor_fault_from_section
from fahv.sensors.measure import Sensors, measure_history, noise_bound, true_outputs, white_noise

DATA = load_sensors()
X0 = np.array([85500.0, 7900.0, 0.03, 0.03, 0.0, 0.1, 0.0, 0.01, 0.0, 0.0, 0.0])


def test_packaged_noise_values_and_units():
    ch = DATA.channels
    assert (ch["h"].stddev, ch["V"].stddev) == (3.2, 1.0)
    assert math.degrees(ch["theta"].stddev) == pytest.approx(0.057, rel=1e-12)
    assert math.degrees(ch["alpha"].stddev) == pytest.approx(0.057, rel=1e-12)
    assert math.degrees(ch["q"].stddev) == pytest.approx(0.18, rel=1e-12)
    assert set(DATA.representative) == {"gyro_mode_slopes.phi_1", "gyro_mode_slopes.phi_2"}
    assert DEFAULT_MEASURED == ("h", "V", "theta", "q")


def test_gyro_sees_the_modes_through_their_slopes():
    x = np.zeros((2, 11))
    x[:, IQ] = [0.01, 0.0]
    x[:, ETA1_DOT] = [2.0, 0.0]
    x[:, ETA2_DOT] = [0.0, -3.0]
    q = true_outputs(x, DATA, ("q",))[:, 0]
    np.testing.assert_allclose(q, [0.01 + 2.0 * DATA.phi_1, -3.0 * DATA.phi_2], rtol=1e-15)


def test_noise_statistics_over_100000_steps():
    # mean and std of white noise with mean 0.5, stddev 2: tolerances 4 standard errors
    data = replace_channel(DATA, "h", mean=0.5, stddev=2.0)
    n = white_noise(7, "h", np.arange(100_000), data.channels["h"])
    assert n.mean() == pytest.approx(0.5, abs=4 * 2.0 / math.sqrt(1e5))
    assert n.std() == pytest.approx(2.0, abs=4 * 2.0 / math.sqrt(2e5))
    other = white_noise(7, "V", np.arange(100_000), data.channels["V"])
    assert abs(np.corrcoef(n, other)[0, 1]) < 0.01


def test_step_by_step_equals_batch_in_another_order():
    seeds = [4, 9, 1]
    one = [Sensors(DATA, [s], 0.02) for s in seeds]
    batch = Sensors(DATA, seeds[::-1], 0.02)
    for k in range(50):
        y_b = batch.measure(k, np.tile(X0, (3, 1)))
        y_1 = np.vstack([s.measure(k, X0[None]) for s in one])
        np.testing.assert_array_equal(y_b[::-1], y_1)
    # the white noise of the sensors is the stateless draw of (seed, channel, step)
    np.testing.assert_array_equal(
        y_1[:, 0], X0[0] + white_noise(np.array(seeds), "h", 49, DATA.channels["h"])
    )
    # with every part of the model on (turn-on and Gauss-Markov biases, lag, delay, hold)
    data = replace_channel(DATA, "q", bias_stddev=1e-3, dynamic_bias_stddev=1e-3,
                           dynamic_bias_correlation_time=0.5, lag=30.0, delay=1, period=2,
                           drift_rate=1e-4, precision=1e-5)  # fmt: skip
    x = X0 + 0.01 * np.random.default_rng(1).standard_normal((40, 3, 11))
    batch = measure_history(data, seeds[::-1], 0.02, x[:, ::-1])[:, ::-1]
    for i, seed in enumerate(seeds):
        np.testing.assert_array_equal(measure_history(data, [seed], 0.02, x[:, i]), batch[:, i])


def test_delay_hold_bias_lag_and_quantisation():
    data = replace_channel(DATA, "h", stddev=0.0, delay=2, period=3, bias=1.0, precision=0.5)
    data = replace_channel(data, "V", stddev=0.0, lag=10.0)
    s = Sensors(data, [1], 0.02, measured=("h", "V"))
    h = 100.0 + np.arange(8)  # true h ramps 1 ft per step
    y = np.array(
        [s.measure(k, np.r_[h[k], 7900.0 + 1.0 * (k > 0), np.zeros(9)][None])[0] for k in range(8)]
    )
    # sample at 0, 3, 6 of h two steps earlier (h_0 before step 2), + 1 ft, held between
    np.testing.assert_array_equal(y[:, 0], [101, 101, 101, 102, 102, 102, 105, 105])
    # lag 10/(s + 10): after k steps of 0.02 s, 1 - exp(-0.2 k) of the 1 ft/s step
    np.testing.assert_allclose(y[1:, 1] - 7900.0, 1.0 - np.exp(-0.2 * np.arange(1, 8)), atol=1e-9)


def test_gauss_markov_bias_has_its_stddev_and_correlation():
    data = replace_channel(DATA, "q", stddev=0.0, dynamic_bias_stddev=0.01,
                           dynamic_bias_correlation_time=1.0)  # fmt: skip
    s = Sensors(data, list(range(20)), 0.1, measured=("q",))
    b = np.array([s.measure(k, np.zeros((20, 11)))[:, 0] for k in range(2000)])
    # 20 runs x 2000 steps, ~20 x 10 independent stretches of 10 tau: 10 % on the std
    assert b.std() == pytest.approx(0.01, rel=0.1)
    lag1 = np.mean(b[1:] * b[:-1]) / np.mean(b * b)
    assert lag1 == pytest.approx(math.exp(-0.1), abs=0.02)


@pytest.mark.parametrize("kind", ["bias_step", "drift", "stuck", "dropout"])
def test_sensor_faults(kind):
    params = {"bias_step": {"bias": 5.0}, "drift": {"rate": 2.0}}.get(kind, {})
    fault = sensor_fault_from_section({"channel": "h", "kind": kind, "t_onset": 0.1, **params})
    data = replace_channel(DATA, "h", stddev=0.0)
    s = Sensors(data, [1, 2], 0.02, faults=[fault, None])
    h = 1000.0 + 10.0 * np.arange(10)
    y = np.array([s.measure(k, np.c_[[h[k]] * 2, np.zeros((2, 10))])[:, 0] for k in range(10)])
    np.testing.assert_array_equal(y[:, 1], h)  # the healthy run
    t = 0.02 * np.arange(10)
    expected = {
        "bias_step": h + 5.0 * (t >= 0.1 - 1e-12),
        "drift": h + 2.0 * np.maximum(t - 0.1, 0.0),
        "stuck": np.where(t >= 0.1 - 1e-12, h[4], h),
        "dropout": np.where(t >= 0.1 - 1e-12, h[4], h),
    }[kind]
    np.testing.assert_allclose(y[:, 0], expected, rtol=0, atol=1e-9)


def test_sensor_fault_section_errors_name_the_key():
    assert SENSOR_FAULTS.names() == ("none", "bias_step", "drift", "stuck", "dropout")
    cases = [
        ({"channel": "q", "kind": "frozen", "t_onset": 1.0}, "sensor_fault.kind"),
        ({"channel": "eta_1", "kind": "stuck", "t_onset": 1.0}, "sensor_fault.channel"),
        ({"channel": "q", "kind": "stuck"}, "sensor_fault.t_onset"),
        ({"channel": "q", "kind": "bias_step", "t_onset": 1.0}, "sensor_fault.bias"),
        ({"channel": "q", "kind": "stuck", "t_onset": 1.0, "rate": 1.0}, "unknown key(s) ['rate']"),
        ({"channel": "q", "kind": "drift", "t_onset": 1.0, "rate": "x"}, "sensor_fault.rate"),
    ]
    for section, text in cases:
        with pytest.raises(ConfigError, match=re.escape(text)):
            sensor_fault_from_section(section)


def test_vehicle_file_errors_name_the_key():
    good = {"sensors": {"gyro_mode_slopes": {"phi_1": {"value": 0.0, "unit": "rad", "source": "s"},
                                            "phi_2": {"value": 0.0, "unit": "rad", "source": "s"}},
                        **{c: {} for c in ("h", "V", "theta", "q", "alpha")}}}  # fmt: skip
    assert sensors_from_mapping(good).channels["h"].stddev == 0.0
    bad = [
        ({"h": {"stddev": {"value": 1.0, "unit": "ft"}}}, "'sensors.h.stddev' has no 'source'"),
        (
            {"q": {"stddev": {"value": 1.0, "unit": "ft", "source": "s"}}},
            "'sensors.q.stddev' has unit",
        ),
        ({"V": {"noise": {"value": 1.0, "unit": "ft/s", "source": "s"}}}, "in 'sensors.V'"),
        (
            {"h": {"stddev": {"value": -1.0, "unit": "ft", "source": "s"}}},
            "'sensors.h.stddev' = -1.0",
        ),
        ({"h": {"period": {"value": 0, "unit": "steps", "source": "s"}}}, "'sensors.h.period'"),
    ]
    for change, text in bad:
        data = {"sensors": {**good["sensors"], **change}}
        with pytest.raises(VehicleDataError, match=re.escape(text)):
            sensors_from_mapping(data)


def test_noise_bound_holds_with_its_probability():
    b = noise_bound(1.0, 15000, 0.999)
    assert b == pytest.approx(5.39993, abs=1e-5)
    # per step, P(|n| > b) = (1 - p) / N exactly
    assert 2 * (1 - 0.5 * (1 + math.erf(b / math.sqrt(2)))) == pytest.approx(1e-3 / 15000, rel=1e-6)
    # 2000 runs of 1000 steps: at most a few exceed the p = 0.99 bound (expected <= 20)
    z = white_noise(np.arange(2000)[:, None], "h", np.arange(1000)[None], DATA.channels["h"])
    out = np.mean(np.abs(z).max(axis=1) > noise_bound(3.2, 1000, 0.99))
    assert out < 0.015


def test_the_docs_bound_table_is_the_noise_bound_of_case_1():
    page = Path(__file__).parents[2] / "docs" / "theory" / "sensors.md"
    rows = re.findall(r"^\| `(\w+)` \| ([\d.]+) (ft/s|ft|deg/s|deg) \| ([\d.]+) \3 \|$",
                      page.read_text(), re.MULTILINE)  # fmt: skip
    assert [r[0] for r in rows] == ["h", "V", "theta", "q", "alpha"]
    for name, sigma, unit, bound in rows:
        value = DATA.channels[name].stddev
        if unit.startswith("deg"):
            value = math.degrees(value)
        assert float(sigma) == pytest.approx(value, rel=1e-12)
        assert float(bound) == pytest.approx(noise_bound(value, 15000, 0.999), rel=5e-4)


def test_a_record_measured_afterwards_gives_the_online_numbers():
    rng = np.random.default_rng(0)
    x = X0 + 0.01 * rng.standard_normal((30, 2, 11))
    fault = sensor_fault_from_section({"channel": "q", "kind": "stuck", "t_onset": 0.2})
    online = Sensors(DATA, [5, 6], 0.02, faults=[None, fault])
    y = np.stack([online.measure(k, x[k]) for k in range(30)])
    again = sensor_fault_from_section({"channel": "q", "kind": "stuck", "t_onset": 0.2})
    np.testing.assert_array_equal(measure_history(DATA, [5, 6], 0.02, x, faults=[None, again]), y)
    np.testing.assert_array_equal(measure_history(DATA, [5], 0.02, x[:, 0]), y[:, 0])


def test_a_dropout_with_a_duration_resumes_sampling():
    fault = sensor_fault_from_section(
        {"channel": "h", "kind": "dropout", "t_onset": 0.1, "duration": 0.06}
    )
    data = replace_channel(DATA, "h", stddev=0.0)
    x = np.zeros((10, 11))
    x[:, 0] = 1000.0 + 10.0 * np.arange(10)
    y = measure_history(data, [1], 0.02, x, measured=("h",), faults=[fault])[:, 0]
    # steps 5, 6, 7 (t = 0.10, 0.12, 0.14 < 0.16) hold step 4's 1040 ft; step 8 samples again
    np.testing.assert_array_equal(y, [1000, 1010, 1020, 1030, 1040, 1040, 1040, 1040, 1080, 1090])


def test_a_runs_sensor_dispersion_scales_its_noise_and_shifts_its_bias():
    """(stddev x 2, bias_stddev x 1, bias mean + 0.5 stddev): the same draws, the noise
    twice as large, every channel offset by half its stddev; (1, 1, 0): bit for bit the
    undispersed sensors. A negative factor is refused."""
    data = load_sensors()
    x = np.zeros((3, 9))
    x[:, 0], x[:, 1] = 85500.0, 7900.0
    base = Sensors(data, [5, 5, 5], 0.02)
    disp = Sensors(data, [5, 5, 5], 0.02, dispersion=[[1, 1, 0], [2, 1, 0], [1, 1, 0.5]])
    true = true_outputs(x, data, base.names)
    for k in range(20):
        y0, y1 = base.measure(k, x), disp.measure(k, x)
        assert np.array_equal(y1[0], y0[0])
        np.testing.assert_allclose(y1[1] - true[1], 2.0 * (y0[1] - true[1]), rtol=1e-9,
                                   atol=1e-9 * np.abs(true[1]).max())  # fmt: skip
        std = np.array([data.channels[c].stddev for c in base.names])
        np.testing.assert_allclose(y1[2] - y0[2], 0.5 * std, rtol=1e-6,
                                   atol=1e-9 * np.abs(true[2]).max())  # fmt: skip
    with pytest.raises(ValueError, match="factors >= 0"):
        Sensors(data, [5], 0.02, dispersion=[[-1.0, 1.0, 0.0]])
