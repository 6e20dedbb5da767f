"""The nodes' executor (hsv_common.runtime): rclpy's EventsExecutor, spun only with a
timeout and shut down before its node is destroyed, runs the graph to the end every time.

The two properties of the Jazzy wheel that made it hang (100 % CPU, SIGTERM ignored; a
process that never exited after its last step) are shown in child processes, each next
to what the runtime does instead.
"""

import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from fahv.loop.graph import TEARDOWN_MARK, TOPICS, teardown_hung
from fahv.loop.simulate import simulate
from fahv.runs.bag import read_run, run_result_of
from fahv.sil.runner import run_sil
from fahv.sil.workspace import ensure_built, ros_env

pytestmark = pytest.mark.ros  # child processes with the built workspace sourced

SPIN = r"""
import signal, sys, time
import rclpy
from rclpy.node import Node
from hsv_common.runtime import SPIN_S, make_executor
rclpy.init(signal_handler_options=rclpy.signals.SignalHandlerOptions.NO)
stop = []
signal.signal(signal.SIGTERM, lambda s, f: stop.append(s))
node = Node("idle")
ex = make_executor()
ex.add_node(node)
print(type(ex).__name__, flush=True)
if sys.argv[1] == "unbounded":
    ex.spin_once()  # waits for steady_clock::time_point::max()
while not stop:
    ex.spin_once(timeout_sec=SPIN_S)
print("stopped by SIGTERM", flush=True)
"""

TEARDOWN = r"""
import sys, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String
from hsv_common.runtime import make_executor, teardown
rclpy.init()
node, observer = Node("node"), Node("observer")
node.create_subscription(String, "/t", lambda m: None, 10)
node.create_publisher(String, "/u", 10)
ex = make_executor()
ex.add_node(node)
watch = SingleThreadedExecutor()
watch.add_node(observer)


def counts():
    t0 = time.monotonic()
    while time.monotonic() - t0 < 1.0:  # discovery of the change
        watch.spin_once(timeout_sec=0.01)
    return observer.count_subscribers("/t"), observer.count_publishers("/u")


for _ in range(20):  # the executor takes the node's entities
    ex.spin_once(timeout_sec=0.01)
print("before", *counts())
if sys.argv[1] == "destroy_node":
    node.destroy_node()
else:
    teardown(ex, node)
print("after", *counts(), flush=True)
"""


def _child(script: str, *args, **kw) -> subprocess.Popen:
    env = ros_env()
    env.pop("HSV_EXECUTOR", None)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return subprocess.Popen(
        [sys.executable, "-c", script, *args], env=env, text=True,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, **kw,
    )  # fmt: skip


def _running_share(pid: int, seconds: float = 1.0) -> float:
    """Share of samples in which the process's main thread is running or runnable."""
    stat = Path(f"/proc/{pid}/task/{pid}/stat")
    states = []
    t_end = time.monotonic() + seconds
    while time.monotonic() < t_end:
        states.append(stat.read_text().rsplit(")", 1)[1].split()[0])
        time.sleep(0.02)
    return states.count("R") / len(states)


@pytest.mark.parametrize("spin", ["unbounded", "bounded"])
def test_only_a_bounded_spin_of_the_events_executor_sleeps_and_hears_sigterm(spin):
    """Unbounded (the wheel's cause): the main thread never sleeps and SIGTERM is not
    heard. Bounded (every node's loop): it sleeps between events and stops on SIGTERM."""
    ensure_built()
    p = _child(SPIN, spin)
    try:
        assert p.stdout.readline().strip() == "EventsExecutor"  # the default executor
        time.sleep(0.5)
        running = _running_share(p.pid)
        p.send_signal(15)
        try:
            out, _ = p.communicate(timeout=3.0)
            stopped = True
        except subprocess.TimeoutExpired:
            stopped = False
    finally:
        p.kill()
        p.wait()
    if spin == "unbounded":  # if this fails, the wheel changed: see make_executor's notes
        assert running > 0.8, running  # a busy loop in C++, the GIL released
        assert not stopped  # the Python handler only flags the main thread, which never returns
    else:
        assert running < 0.3, running
        assert stopped and "stopped by SIGTERM" in out


@pytest.mark.parametrize("how", ["destroy_node", "teardown"])
def test_the_runtime_tears_down_the_executor_before_the_node(how):
    """``destroy_node`` alone leaves the node's DDS entities alive (the EventsExecutor
    still holds them; they went away when the executor was freed, outside the teardown
    deadline); :func:`hsv_common.runtime.teardown` destroys them at once."""
    ensure_built()
    p = _child(TEARDOWN, how)
    out, err = p.communicate(timeout=60)
    assert p.returncode == 0, err[-2000:]
    lines = dict(line.split(" ", 1) for line in out.strip().splitlines())
    assert lines["before"] == "1 1"
    assert lines["after"] == ("1 1" if how == "destroy_node" else "0 0")


@pytest.mark.parametrize("executor", ["events", "single"])
def test_the_graph_equals_the_simulation_on_either_executor(
    design, tmp_path, monkeypatch, executor
):
    """A short run on each executor completes (every node exits 0 after its last step,
    none left behind) and equals the in-process simulation. ``single`` is the
    SingleThreadedExecutor (``HSV_EXECUTOR=single``); ``events``, the default, also runs
    every other graph of the suite, back to back in each test worker."""
    monkeypatch.setenv("HSV_EXECUTOR", executor)
    ref = simulate(design, "tube_mpc", duration=1.0)
    t0 = time.monotonic()
    res = run_sil(
        design, "tube_mpc", duration=1.0, out_dir=tmp_path, quiet=True,
        log=lambda _: None,
    )  # fmt: skip
    assert res.returncode == 0
    assert time.monotonic() - t0 < 120
    rec = read_run(res.bag)
    assert rec.metadata["status"] == "complete" and not rec.truncated
    assert all(rec.metadata[f"anomalies{t.replace('/', '.')}"] == "0" for t in TOPICS)
    run = run_result_of(rec)
    assert run.x.shape == ref.x.shape == (50, 9)
    np.testing.assert_allclose(run.x, ref.x, rtol=1e-9, atol=0)
    np.testing.assert_allclose(run.u, ref.u, rtol=1e-9, atol=0)
    for log in (res.bag / "logs").glob("*.log"):
        _no_hang_but_in_dds_teardown(log.read_text())


def _no_hang_but_in_dds_teardown(log: str) -> None:
    """No node's main thread hung, except in the DDS teardown after it closed with status
    0, inside rclpy's destruction of its entities: Fast DDS 2.14 can deadlock destroying
    a participant while its peers leave (hsv_common.runtime.TEARDOWN_S; seen in this test
    under a loaded suite), which the runner ends and names, the run complete."""
    if "Timeout (0:" not in log:
        return
    assert teardown_hung(log) == 0, log[-3000:]
    dump = log[log.rfind(TEARDOWN_MARK) :]
    first = dump.split("(most recent call first):", 1)[1].strip().splitlines()[0]
    assert "/rclpy/" in first and " in teardown" in dump, dump[-3000:]
