"""`fahv sil --live`: a real Foxglove WebSocket client (the protocol's reference
implementation, @foxglove/ws-protocol under Node.js, installed into tests/live by
scripts/setup.sh) subscribes while a short graph runs; every message it received
decodes and equals the recorded one. Also: `fahv sil` prints the domain and the line
to watch the graph from another shell, and that line works while the graph runs."""

import base64
import json
import os
import re
import shutil
import subprocess
import threading
import time
from pathlib import Path

import pytest
from rosbags.highlevel import AnyReader

from fahv.loop.graph import TOPICS
from fahv.runs.bag import iter_raw, read_run
from fahv.runs.live import schema_text
from fahv.runs.messages import decode
from fahv.runs.writer import RunWriter
from fahv.sil.workspace import ROOT

pytestmark = pytest.mark.ros  # runs the built node graph

CLIENT = ROOT / "tests" / "live" / "client.cjs"
N = 1500  # 30 s of simulated time at twice real time (--rate 2): 15 s of wall time, in
# which `ros2 topic list` looks while the graph runs (30 s unpaced ended before it did once
# the graph ran at 10 x real time)
RATE = 2.0


def _read_until(stream, pattern, sink):
    """Lines of ``stream`` into ``sink`` until one matches; the match (None at EOF)."""
    for line in stream:
        sink.append(line)
        m = re.search(pattern, line)
        if m:
            return m
    return None


def test_live_view_serves_every_loop_topic_to_a_foxglove_client(quick_case, tmp_path):
    node = shutil.which("node")
    assert node, "Node.js is needed for the Foxglove client (scripts/setup.sh)"
    assert (ROOT / "tests" / "live" / "node_modules" / "@foxglove" / "ws-protocol").is_dir(), (
        "tests/live/node_modules missing: run scripts/setup.sh"
    )
    case_file, art = quick_case
    fahv = str(ROOT / ".venv" / "bin" / "fahv")
    proc = subprocess.Popen(
        [fahv, "sil", str(case_file), "--design", str(art), "--duration", str(N * 0.02),
         "--out", str(tmp_path), "--quiet", "--live", "0", "--rate", str(RATE)],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    err: list[str] = []
    try:
        domain = _read_until(proc.stderr, r"to see it from another shell: (export .*)$", err)
        assert domain, "".join(err)
        live = _read_until(proc.stderr, r"live view on (ws://127\.0\.0\.1:\d+) \(", err)
        assert live, "".join(err)
        assert "foxglove_layout.json" in err[-1]
        client = subprocess.Popen(
            [node, str(CLIENT), live.group(1), "120", str(tmp_path / "client.jsonl")],
            cwd=CLIENT.parent,
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        # the user's line in another shell, while the graph runs (its first step is out)
        t0 = time.monotonic()
        got_path = tmp_path / "client.jsonl"
        while '"op":"message"' not in (got_path.read_text() if got_path.exists() else ""):
            assert time.monotonic() - t0 < 120 and proc.poll() is None, "".join(err)
            time.sleep(0.05)
        topics = subprocess.run(
            ["bash", "-c", domain.group(1)], capture_output=True, text=True, timeout=60,
            env={k: v for k, v in os.environ.items() if k != "ROS_DOMAIN_ID"},
        )  # fmt: skip
        rest = threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True)
        rest.start()
        out = proc.stdout.read()
        proc.wait(timeout=240)
        rest.join(timeout=10)
        _, client_err = client.communicate(timeout=60)
        got = (tmp_path / "client.jsonl").read_text()
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, out + "".join(err)
    assert "/hsv/state" in topics.stdout.split() and "/hsv/actuator_command" in topics.stdout
    bag = str(tmp_path / re.search(r"^run (\S+): status", out, re.M).group(1))
    rec = read_run(bag)
    assert rec.metadata["ros_domain_id"] == re.search(r"ROS_DOMAIN_ID=(\d+)", domain.group(1))[1]
    recorded = {}
    for topic, _, log_ns, data in iter_raw(bag, list(TOPICS)):
        recorded[(topic, log_ns)] = data
    events = [json.loads(ln) for ln in got.splitlines()]
    assert events and events[-1]["op"] == "close", got[-2000:] + client_err
    channels = {c["topic"]: c for e in events if e["op"] == "advertise" for c in e["channels"]}
    assert set(channels) == set(TOPICS)
    with AnyReader([Path(bag)]) as reader:  # the schemas the run file holds
        stored = {conn.topic: conn.msgdef.data for conn in reader.connections}
    for topic, c in channels.items():
        assert (c["encoding"], c["schemaEncoding"]) == ("cdr", "ros2msg")
        assert c["schemaName"] == TOPICS[topic] and c["schema"] == schema_text(topic)
        assert c["schema"].strip() == stored[topic].strip(), topic
    messages = [e for e in events if e["op"] == "message"]
    counts = dict.fromkeys(TOPICS, 0)
    for e in messages:  # every message received decodes, and is the recorded one
        data = base64.b64decode(e["data"])
        msg = decode(e["topic"], data)
        t_ns = int(e["timestamp"])
        if e["topic"] == "/clock":
            assert msg["clock"]["sec"] * 10**9 + msg["clock"]["nanosec"] == t_ns
        else:
            assert t_ns == msg["k"] * 20_000_000
        assert recorded[(e["topic"], t_ns)] == data
        counts[e["topic"]] += 1
    assert all(n > 0 for n in counts.values()), counts
    assert max(counts.values()) == N  # subscribed before step 0: every step arrived
    times = [int(e["timestamp"]) for e in events if e["op"] == "time"]
    assert times and times == sorted(times) and times[-1] == (N - 1) * 20_000_000
    # paced: the plant's N steps took at least (N - 1) Ts / rate of wall time
    from fahv.sil.workspace import WS

    plant_log = (WS / "log" / "sil" / Path(bag).name / "logs" / "plant.log").read_text()
    wall = float(re.search(r"done: \d+ steps in ([\d.]+) s wall", plant_log).group(1))
    assert (N - 1) * 0.02 / RATE <= wall < (N - 1) * 0.02 / RATE + 10.0, plant_log


def test_simulate_live_serves_the_in_process_run(design, tmp_path):
    """`fahv simulate --live`: the in-process run's messages, serialised once for the
    file and the server, reach a Foxglove client that subscribed before the run."""
    import time

    from fahv.cli.run import StepProgress
    from fahv.loop.simulate import simulate
    from fahv.runs.live import LiveView

    view = LiveView(0, 0.02)
    out = tmp_path / "client.jsonl"
    client = subprocess.Popen(
        [shutil.which("node"), str(CLIENT), view.url, "60", str(out)], cwd=CLIENT.parent,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    t0 = time.monotonic()  # subscribed once the advertisement arrived (then wait a little)
    while '"op":"advertise"' not in (out.read_text() if out.exists() else ""):
        assert time.monotonic() - t0 < 30 and client.poll() is None, client.stderr.read()
        time.sleep(0.05)
    time.sleep(0.5)
    with RunWriter(tmp_path / "sim", {"source": "simulate"}, 0.02) as writer:
        progress = StepProgress("live", 50, writer=writer, live=view)
        simulate(design, "tube_mpc", duration=1.0, writer=progress)
        progress.close()
    time.sleep(0.5)
    view.close()
    client.wait(timeout=30)
    events = [json.loads(ln) for ln in out.read_text().splitlines()]
    recorded = {(t, log_ns): data for t, _, log_ns, data in iter_raw(tmp_path / "sim")}
    messages = [e for e in events if e["op"] == "message"]
    assert len(messages) == 50 * len(TOPICS) == len(recorded)
    for e in messages:
        data = base64.b64decode(e["data"])
        decode(e["topic"], data)
        assert recorded[(e["topic"], int(e["timestamp"]))] == data
    assert [int(e["timestamp"]) for e in events if e["op"] == "time"][-1] == 49 * 20_000_000
