"""The SIL graph as users run it (issue 14): several graphs at once with the same exported
ROS_DOMAIN_ID, a foreign graph in the domain, Ctrl-C on `fahv sil`, and the graph started
node by node with `ros2 run` after `source ros_ws/install/setup.bash`."""

import os
import re
import signal
import subprocess
import threading

import domain_coordinator
import numpy as np
import pytest

from fahv.loop.graph import NODES, TOPICS
from fahv.loop.simulate import simulate
from fahv.runs.bag import read_run, run_result_of
from fahv.runs.latency import run_latencies
from fahv.runs.sil import run_sil
from fahv.runs.workspace import ROOT, ros_env

pytestmark = pytest.mark.ros  # every test here runs the built node graph

T = 2.0
N = 100


def assert_equals_simulate(bag, design, variant, n=N):
    rec = read_run(bag)
    assert rec.metadata["status"] == "complete"
    assert not rec.truncated
    assert all(rec.metadata[f"anomalies{t.replace('/', '.')}"] == "0" for t in TOPICS)
    run = run_result_of(rec)
    ref = simulate(design, variant, duration=n * 0.02)
    assert run.x.shape == ref.x.shape == (n, 9)
    np.testing.assert_allclose(run.x, ref.x, rtol=1e-9, atol=0)
    np.testing.assert_allclose(run.u, ref.u, rtol=1e-9, atol=0)
    np.testing.assert_allclose(run.q_f, ref.q_f, rtol=1e-9, atol=0)
    return rec


def test_two_graphs_at_once_with_the_same_exported_domain_stay_apart(design, tmp_path, monkeypatch):
    """Two variants (their q' and commands differ) at the same time, ROS_DOMAIN_ID=7
    exported: each run equals its own in-process simulation, without a stale message."""
    monkeypatch.setenv("ROS_DOMAIN_ID", "7")
    results = {}

    def one(variant):
        results[variant] = run_sil(
            design, variant, duration=T, out_dir=tmp_path / variant, quiet=True, log=lambda _: None
        )

    threads = [threading.Thread(target=one, args=(v,)) for v in ("tube_mpc", "tube_mpc_no_notch")]
    for th in threads:
        th.start()
    for th in threads:
        th.join(timeout=180)
    domains = set()
    for variant, res in results.items():
        assert res.returncode == 0, variant
        rec = assert_equals_simulate(res.bag, design, variant)
        domains.add(rec.metadata["ros_domain_id"])
        logs = "".join(p.read_text() for p in (res.bag / "logs").glob("*.log"))
        assert "stale" not in logs.replace("0 stale", "")
    assert len(domains) == 2 and "7" not in domains  # domain_coordinator, not the shell's
    q_f = [run_result_of(read_run(r.bag)).q_f for r in results.values()]
    assert np.abs(q_f[0] - q_f[1]).max() > 1e-6  # the two graphs really differ


def test_a_foreign_graph_in_the_domain_is_named(design, tmp_path, capfd):
    """Two graphs forced into one domain (`--domain-id`, as a user might): a node sees
    more publishers on a loop topic than its graph has (before step 0, or at the first
    stale or duplicate message) and stops, naming the topic, the counts and the domain."""
    results = {}
    with domain_coordinator.domain_id() as domain:

        def one(name):
            results[name] = run_sil(
                design, "tube_mpc", duration=20.0, out_dir=tmp_path / name, watchdog_s=5.0,
                quiet=True, log=lambda _: None, domain_id=domain,
            )  # fmt: skip

        threads = [threading.Thread(target=one, args=(n,)) for n in ("a", "b")]
        for th in threads:
            th.start()
        for th in threads:
            th.join(timeout=180)
    err = capfd.readouterr().err
    assert {r.returncode for r in results.values()} != {0}, "both graphs completed"
    assert "failed (foreign graph in its ROS domain)" in err
    m = re.search(
        r"(\w+): (\d+) publishers on (/hsv/\w+), but its graph has 1 \((\w+)\): another "
        r"graph is running in ROS domain (\d+) \(ROS_DOMAIN_ID=\d+\)",
        err,
    )
    assert m, err[-3000:]
    assert int(m.group(2)) >= 2 and m.group(5) == str(domain)
    for r in results.values():  # every run folder stays readable, none claims completion
        if r.returncode:
            assert read_run(r.bag).metadata["status"].startswith("interrupted")


def test_ctrl_c_on_fahv_sil_finalises_the_run_and_exits_130(quick_case, tmp_path, interrupt_fahv):
    """Ctrl-C (SIGINT to the foreground process group, as a terminal sends it), then a
    second Ctrl-C while the graph stops."""
    case_file, art = quick_case
    out = tmp_path / "bags"
    steps, rec, _ = interrupt_fahv(
        ["sil", case_file, "--design", art, "--duration", "300", "--out", out], out,
        [signal.SIGINT, signal.SIGINT], 6.0, 90,  # 6 s: the graph is up and stepping
    )  # fmt: skip
    assert 10 < steps < 15000
    assert rec.topics["/hsv/state"]["count"] >= steps


def test_graph_started_node_by_node_with_ros2_run(design, quick_case, tmp_path):
    """The README's commands: `fahv sil --write-params`, then `source
    ros_ws/install/setup.bash` and one `ros2 run` per node (the stand-in on this machine)."""
    case_file, art = quick_case
    params = tmp_path / "run.yaml"
    fahv = str(ROOT / ".venv" / "bin" / "fahv")
    r = subprocess.run(
        [fahv, "sil", str(case_file), "--design", str(art), "--duration", str(T),
         "--out", str(tmp_path / "bags"), "--write-params", str(params)],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )  # fmt: skip
    commands = [ln.strip() for ln in r.stdout.splitlines() if ln.strip().startswith("ros2 run")]
    assert [c.split()[3] for c in commands] == [
        "recorder", "notch_filter", "nominal_trajectory", "tube_mpc", "fault_injector", "plant"
    ]  # fmt: skip
    assert all(NODES[c.split()[3]].package == c.split()[2] for c in commands)
    # as typed in a shell: the first five in the background, the plant in the foreground
    script = "\n".join(["source ros_ws/install/setup.bash", *commands, "rc=$?; wait; exit $rc"])
    with domain_coordinator.domain_id() as domain:
        env = {k: v for k, v in os.environ.items() if not k.startswith(("AMENT", "COLCON"))}
        env["ROS_DOMAIN_ID"] = str(domain)
        env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
        done = subprocess.run(
            ["bash", "-c", script], cwd=ROOT, env=env, capture_output=True, text=True, timeout=180
        )
    assert done.returncode == 0, done.stderr[-2000:]
    bag = next((tmp_path / "bags").iterdir())
    assert "complete, 100 steps" in done.stdout, done.stdout[-3000:] + done.stderr[-3000:]
    rec = assert_equals_simulate(bag, design, "tube_mpc")
    assert rec.metadata["ros_domain_id"] == str(domain)
    lat = run_latencies(bag)
    assert [h["node"] for h in lat["hops"]] == [
        "notch_filter", "nominal_trajectory", "tube_mpc", "fault_injector", "plant"
    ]  # fmt: skip
    assert all(h["n"] >= N - 1 for h in lat["hops"])
    assert 0.05 < lat["step"]["median_ms"] < 200.0


def test_ros2_standin_bag_info_is_fahv_inspect(design, tmp_path):
    from fahv.runs.bag import RunWriter

    bag = tmp_path / "sim"
    with RunWriter(bag, {"case": "case1", "variant": "tube_mpc", "source": "simulate"}, 0.02) as w:
        simulate(design, "tube_mpc", duration=0.2, writer=w)
    env = ros_env()
    r = subprocess.run(
        ["bash", "-c", f"ros2 bag info {bag}"], env=env, capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    assert "/hsv/state" in r.stdout and "status        complete" in r.stdout
    r = subprocess.run(
        ["bash", "-c", "ros2 run hsv_plant no_such_node"], env=env, capture_output=True, text=True
    )
    assert r.returncode == 1
    expected = "No executable 'no_such_node' in package 'hsv_plant' (it has: fault_injector, plant)"
    assert expected in r.stderr
