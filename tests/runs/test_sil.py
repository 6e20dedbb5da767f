"""The ROS 2 node graph (short horizons): lockstep equals the in-process simulation,
the recording opens in rosbags, a killed node and bad parameters fail clearly."""

import math
import subprocess
import threading
import time

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from fahv.loop.graph import TOPICS
from fahv.loop.simulate import simulate
from fahv.model.vehicle import load_vehicle
from fahv.runs.bag import iter_raw, read_run, run_result_of
from fahv.runs.metrics import metrics
from fahv.runs.replay import run_replay
from fahv.sil.runner import run_sil
from fahv.sil.workspace import WS

pytestmark = pytest.mark.ros  # every test here runs the built node graph

T = 4.0
N = 200
#: The implementable loop: servos, the sensors and the Kalman filter whose predictor
#: integrates the servos (the nodes' other numbers than the exact-state loop's, which the
#: main job and the other graph tests fly).
KALMAN = {"plant": {"measured": "h,V,theta,q", "actuators": "second_order"},
          "state_estimator": {"estimator": "kalman", "measured": "h,V,theta,q",
                              "actuators": "second_order"}}  # fmt: skip


@pytest.fixture(scope="module")
def sil_run(design, tmp_path_factory):
    out = tmp_path_factory.mktemp("bags")
    res = run_sil(design, "tube_mpc", duration=T, out_dir=out, quiet=True, overrides=KALMAN)
    return res


def test_sil_equals_in_process_simulation(sil_run, design):
    assert sil_run.returncode == 0
    rec = read_run(sil_run.bag)
    assert rec.metadata["status"] == "complete"
    assert rec.metadata["source"] == "sil"
    assert rec.metadata["design_hash"] == design.summary["design_hash"]
    assert all(rec.metadata[f"anomalies{t.replace('/', '.')}"] == "0" for t in TOPICS)
    run = run_result_of(rec)
    ref = simulate(design, "tube_mpc", duration=T, overrides=KALMAN)
    assert run.x.shape == ref.x.shape == (N, 9)
    rel = np.abs(run.x - ref.x) / np.maximum(np.abs(ref.x), 1e-12)
    assert rel.max() <= 1e-9
    np.testing.assert_allclose(run.u, ref.u, rtol=1e-9, atol=0)
    np.testing.assert_allclose(run.tube_level, ref.tube_level, rtol=1e-9, atol=0)
    # the plant node's sensors drew the in-process numbers (h, V, theta and the gyro's q),
    # and the estimator node's filter estimated what the in-process filter does
    assert run.y.shape == ref.y.shape == (N, 4)
    np.testing.assert_allclose(run.y, ref.y, rtol=1e-9, atol=0)
    np.testing.assert_allclose(run.x_hat, ref.x_hat, rtol=1e-9, atol=0)
    assert not np.array_equal(run.x_hat, run.x)
    lim = load_vehicle().limits
    m, m_ref = metrics(run, lim), metrics(ref, lim)
    assert m["alpha_err_max_deg"] == pytest.approx(m_ref["alpha_err_max_deg"], rel=1e-9)
    assert sil_run.simulated_s == T  # the run's duration parameter, exact


def test_sil_recording_opens_in_rosbags(sil_run):
    with AnyReader([sil_run.bag]) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert set(conns) == set(TOPICS)
        for c in conns.values():
            assert c.msgdef.data.strip(), f"{c.topic} has no message definition"
            assert c.msgcount == N
        assert "float64[] x_q" in conns["/hsv/q_filtered"].msgdef.data
        n = 0
        for conn, t_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            if conn.topic != "/clock":
                assert t_ns == msg.k * 20_000_000
            n += 1
    assert n == N * len(TOPICS)


def _pids(pattern):
    r = subprocess.run(["pgrep", "-f", pattern], capture_output=True, text=True)
    return [int(p) for p in r.stdout.split()]


def test_killed_node_is_named_and_the_recording_stays_readable(design, tmp_path, capfd):
    watchdog = 5.0
    result = {}

    def target():
        result["res"] = run_sil(
            design, "tube_mpc", duration=300.0, out_dir=tmp_path, watchdog_s=watchdog, quiet=True
        )

    th = threading.Thread(target=target)
    th.start()
    t0 = time.monotonic()
    bag = None
    while time.monotonic() - t0 < 90:  # wait until the recorder has created the run
        bags = list(tmp_path.glob("*/run.json"))
        if bags:
            bag = bags[0].parent
            break
        time.sleep(0.2)
    pattern = f"lib/hsv_ctrl/tube_mpc .*{bag.name if bag else 'none'}/params.yaml"
    assert bag is not None, "the graph did not start"
    log = WS / "log" / "sil" / bag.name / "logs" / "recorder.log"
    while time.monotonic() - t0 < 120:  # stepping (a fixed wait was too short under load)
        if log.is_file() and "progress 500" in log.read_text():
            break
        time.sleep(0.2)
    pids = _pids(pattern)
    assert pids
    t_kill = time.monotonic()
    subprocess.run(["kill", "-9", *map(str, pids)], check=True)
    th.join(timeout=60)
    assert not th.is_alive()
    elapsed = time.monotonic() - t_kill
    res = result["res"]
    err = capfd.readouterr().err
    assert res.returncode == 1
    assert "node 'tube_mpc' failed (killed by signal SIGKILL)" in err
    assert elapsed < watchdog + 20.0
    rec = read_run(bag)
    assert not rec.truncated
    assert rec.metadata["status"].startswith("interrupted")
    n = rec.topics["/hsv/state"]["count"]
    assert 10 < n < 15000


@pytest.mark.parametrize(
    ("key", "value", "message"),
    [
        ("F_shape", [2, 8], "tube_mpc: parameter 'F' has 18 values, but 'F_shape' = [2, 8]"),
        ("F", "nan", "tube_mpc: parameter 'F' has a non-finite value at index 4"),
    ],
)
def test_bad_parameter_file_stops_the_node_naming_the_key(
    design, tmp_path, capfd, key, value, message
):
    from fahv.loop.params import node_parameters

    if value == "nan":
        F = list(node_parameters(design)["tube_mpc"]["F"])
        F[4] = math.nan
        value = F
    res = run_sil(
        design,
        "tube_mpc",
        duration=2.0,
        out_dir=tmp_path,
        watchdog_s=5.0,
        overrides={"tube_mpc": {key: value}},
        quiet=True,
    )
    err = capfd.readouterr().err
    assert res.returncode == 1
    assert "node 'tube_mpc' failed (bad parameter)" in err
    assert message in err


def test_replay_into_a_fresh_tube_mpc_reproduces_the_recorded_commands(sil_run, tmp_path):
    """Regression use of fahv replay: the controller's recorded inputs (state, q', nominal)
    into a new tube_mpc node with the run's parameters give the recorded outputs, byte
    for byte (CDR)."""
    res = run_replay(sil_run.bag, nodes=["tube_mpc"], rate=0.0, out=tmp_path / "rp", quiet=True)
    assert res.returncode == 0
    rec = read_run(res.out)
    assert rec.metadata["status"] == "complete" and rec.metadata["source"] == "replay"
    assert rec.metadata["replayed_topics"] == "/hsv/state_estimate,/hsv/q_filtered,/hsv/nominal"
    for topic in ("/hsv/control_command", "/hsv/tube_status", "/hsv/state"):
        orig = [data for *_, data in iter_raw(sil_run.bag, [topic])]
        new = [data for *_, data in iter_raw(res.out, [topic])]
        assert len(orig) == N
        assert new == orig, topic


def test_replay_names_a_topic_it_cannot_publish(sil_run, tmp_path):
    res = run_replay(sil_run.bag, topics=["/hsv/bogus"], rate=0.0, quiet=True)
    assert res.returncode == 1
    log = (res.log_dir / "logs" / "replay.log").read_text()
    assert "replay: parameter 'topics' must be one of ('/clock', " in log
    assert "got '/hsv/bogus'" in log
