"""Per-hop latency from recorded DDS timestamps (fahv.runs.latency), on synthetic stamps."""

import numpy as np
import pytest

from fahv.loop.graph import TOPICS
from fahv.runs.latency import (
    format_latencies,
    hop_latencies,
    load_timestamps,
    run_controller,
    save_timestamps,
)

MS = 1_000_000  # ns


def synthetic_stamps(n=10, recorder_delay_ns=100_000):
    """A lockstep graph with known costs per hop [ms]: estimator 0.1, notch 0.5, nominal
    0.8, controller 0.3 after the later of its inputs, fault injector 0.2, plant 1.0 to the
    state and 0.05 more to the measurement; step = 2.45 ms."""
    src = {t: [] for t in TOPICS}
    t0 = 0
    for k in range(n):
        state = t0
        meas = state + 0.05 * MS
        est = meas + 0.1 * MS
        q = est + 0.5 * MS
        nom = est + 0.8 * MS
        cmd = max(state, q, nom) + 0.3 * MS
        act = cmd + 0.2 * MS
        for topic, ts in (
            ("/clock", state),
            ("/hsv/state", state),
            ("/hsv/measurement", meas),
            ("/hsv/state_estimate", est),
            ("/hsv/q_filtered", q),
            ("/hsv/nominal", nom),
            ("/hsv/tube_status", cmd - 10_000),
            ("/hsv/control_command", cmd),
            ("/hsv/actuator_command", act),
            ("/hsv/fault_status", act + 5_000),
        ):
            src[topic].append((k, int(ts), int(ts) + recorder_delay_ns))
        t0 = act + 1.0 * MS
    return {t: np.array(v, dtype=np.int64) for t, v in src.items()}


def test_hop_latencies_add_up_to_the_step():
    lat = hop_latencies(synthetic_stamps())
    hops = {h["node"]: h for h in lat["hops"]}
    expected = {
        "state_estimator": 0.1,
        "notch_filter": 0.5,
        "nominal_trajectory": 0.8,
        "tube_mpc": 0.3,
        "fault_injector": 0.2,
        "plant": 1.05,
    }
    assert list(hops) == list(expected)  # graph order
    for node, ms in expected.items():
        assert hops[node]["median_ms"] == pytest.approx(ms, abs=1e-9)
        assert hops[node]["max_ms"] == pytest.approx(ms, abs=1e-9)
    assert hops["tube_mpc"]["output"] == "/hsv/control_command"  # what the next node waits for
    assert hops["plant"]["n"] == 9  # state k + 1 answers command k
    assert hops["plant"]["output"] == "/hsv/measurement"  # what the estimator waits for
    assert hops["notch_filter"]["n"] == 10
    assert lat["step"]["median_ms"] == pytest.approx(2.45, abs=1e-9)
    # critical path: plant, estimator, the later of notch / nominal, controller, injector
    assert 1.05 + 0.1 + 0.8 + 0.3 + 0.2 == pytest.approx(lat["step"]["median_ms"])
    assert lat["dds_hop"]["median_ms"] == pytest.approx(0.1, abs=1e-9)
    text = format_latencies(lat)
    assert "step period: /hsv/state k -> k + 1" in text
    assert "   2.450" in text and "33 %" in text  # nominal_trajectory: 0.8 of 2.45 ms


def test_timestamps_round_trip_and_missing_file(tmp_path):
    stamps = synthetic_stamps(n=4)
    flat = {t: v.ravel().tolist() for t, v in stamps.items()}  # as the recorder keeps them
    path = save_timestamps(tmp_path, flat)
    assert path.name == "timestamps.npz"
    back = load_timestamps(tmp_path)
    assert set(back) == set(TOPICS)
    np.testing.assert_array_equal(back["/hsv/state"], stamps["/hsv/state"])
    assert load_timestamps(tmp_path / "nowhere") is None
    assert run_controller(tmp_path) == "tube_mpc"
    (tmp_path / "params.yaml").write_text("rmpc:\n  ros__parameters: {}\n")
    assert run_controller(tmp_path) == "rmpc"
    assert hop_latencies(back, "rmpc")["hops"][3]["node"] == "rmpc"
