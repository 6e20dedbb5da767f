"""The SIL graph as users run it: several graphs at once with the same exported
ROS_DOMAIN_ID, a foreign graph in the domain, Ctrl-C on `fahv sil`, and the graph started
node by node with `ros2 run` after `source ros_ws/install/setup.bash` (once, twice with one
parameter file)."""

import os
import re
import signal
import subprocess
import threading
import time

import domain_coordinator
import numpy as np
import pytest

from fahv.certificate.verified import load_or_design
from fahv.loop.graph import NODES, TOPICS
from fahv.loop.simulate import simulate
from fahv.runs.bag import read_run, run_result_of
from fahv.runs.latency import run_latencies
from fahv.runs.writer import RunWriter
from fahv.sil.runner import run_sil
from fahv.sil.workspace import ROOT, ros_env

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


def _fahv(args, **kw):
    fahv = str(ROOT / ".venv" / "bin" / "fahv")
    return subprocess.Popen(
        [fahv, *map(str, args)], cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        text=True, **kw,
    )  # fmt: skip


def test_a_foreign_graph_stops_only_the_graph_that_joined_second(
    design, quick_case, tmp_path, capfd
):
    """Two graphs forced into one domain (`--domain-id`, as a user might), the second
    (`fahv sil`, about 10 s to start, its design's verification done beforehand) started
    once the first one's recorder is up (the first runs 25 s of simulated time paced at
    real time): the second stops naming the first and
    the domain, reports the real-time factor of the steps it ran, and the first one
    completes and equals `fahv simulate`."""
    case_file, art = quick_case
    load_or_design(case_file, art, log=lambda _: None)  # the verdict cached: no wait at start
    result = {}
    with domain_coordinator.domain_id() as domain:

        def first():
            result["a"] = run_sil(
                design, "tube_mpc", duration=25.0, out_dir=tmp_path / "a", watchdog_s=10.0,
                quiet=True, log=lambda _: None, domain_id=domain,
                overrides={"plant": {"rate": 1.0}},
            )  # fmt: skip

        th = threading.Thread(target=first)
        th.start()
        t0 = time.monotonic()
        while not list((tmp_path / "a").glob("*/run.json")) and time.monotonic() - t0 < 90:
            time.sleep(0.1)
        second = _fahv(
            ["sil", case_file, "--design", art, "--duration", 20, "--out", tmp_path / "b",
             "--domain-id", domain, "--quiet", "--watchdog", 10],
        )  # fmt: skip
        out, err = second.communicate(timeout=180)
        th.join(timeout=180)
    assert second.returncode == 1, out + err
    assert "failed (foreign graph in its ROS domain)" in err, err[-3000:]
    name_a = result["a"].bag.name
    m = re.search(
        rf"(\w+): another graph \(run '{re.escape(name_a)}': [\w, ]+\) is running in ROS "
        rf"domain {domain} \(ROS_DOMAIN_ID={domain}\) since [\d:]+, before this one joined at "
        r"[\d:]+: this graph stops",
        err,
    )
    assert m, err[-3000:]
    m = re.search(
        r"status (.*), (\d+) of 1000 steps, wall time [\d.]+ s, real-time factor (\S+)", out
    )
    assert m, out
    assert m.group(1).startswith("interrupted")
    steps = int(m.group(2))
    assert (m.group(3) == "-") if steps == 0 else float(m.group(3)) > 0  # not of 1000 steps
    # the first graph went on: complete, and equal to the in-process simulation
    res = result["a"]
    assert res.returncode == 0, capfd.readouterr().err[-3000:]
    rec = read_run(res.bag)
    assert rec.metadata["status"] == "complete" and not rec.truncated
    run = run_result_of(rec)
    ref = simulate(design, "tube_mpc", duration=25.0)
    assert run.x.shape == ref.x.shape == (1250, 9)
    np.testing.assert_allclose(run.x, ref.x, rtol=1e-9, atol=0)
    np.testing.assert_allclose(run.u, ref.u, rtol=1e-9, atol=0)


def test_ctrl_c_on_fahv_sil_finalises_the_run_and_exits_130(quick_case, tmp_path, interrupt_fahv):
    """Ctrl-C (SIGINT to the foreground process group, as a terminal sends it), then a
    second Ctrl-C while the graph stops."""
    case_file, art = quick_case
    out = tmp_path / "bags"
    steps, rec, _ = interrupt_fahv(
        ["sil", case_file, "--design", art, "--duration", "300", "--out", out], out,
        [signal.SIGINT, signal.SIGINT], 0.5, 90,  # the graph is stepping
    )  # fmt: skip
    assert 10 < steps < 15000
    assert rec.topics["/hsv/state"]["count"] >= steps


@pytest.mark.parametrize("composed", [False, True], ids=["node_by_node", "composed"])
def test_graph_started_node_by_node_with_ros2_run(design, quick_case, tmp_path, composed):
    """The README's commands: `fahv sil --write-params`, then `source
    ros_ws/install/setup.bash` and one `ros2 run` per node (the stand-in on this machine),
    or the recorder's and the one that composes the loop nodes in one process."""
    case_file, art = quick_case
    params = tmp_path / "run.yaml"
    fahv = str(ROOT / ".venv" / "bin" / "fahv")
    r = subprocess.run(
        [fahv, "sil", str(case_file), "--design", str(art), "--duration", str(T),
         "--out", str(tmp_path / "bags"), "--write-params", str(params)],
        cwd=ROOT, capture_output=True, text=True, check=True,
    )  # fmt: skip
    commands = [ln.strip() for ln in r.stdout.splitlines() if ln.strip().startswith("ros2 run")]
    loop = ["state_estimator", "notch_filter", "nominal_trajectory", "tube_mpc",
            "fault_injector", "plant"]  # fmt: skip
    assert [c.split()[3] for c in commands] == ["recorder", *loop, "loop"]
    assert commands[-1].split()[2:4 + len(loop)] == ["hsv_bringup", "loop", *loop]
    assert all(NODES[c.split()[3]].package == c.split()[2] for c in commands[:-1])
    if composed:  # the recorder in the background, the composed loop in the foreground
        commands = [commands[0], commands[-1]]
    else:
        commands = commands[:-1]
    export = re.search(
        r"^  export ROS_DOMAIN_ID=(\d+) ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST   # a domain",
        r.stdout, re.M,
    )  # fmt: skip
    assert export and 0 <= int(export.group(1)) <= 232, r.stdout
    # as typed in a shell: the first five in the background, the plant in the foreground
    # (in the domain this test holds: the printed one is free, but not reserved)
    with domain_coordinator.domain_id() as domain:
        line = export.group(0).split("#")[0].strip().replace(export.group(1), str(domain), 1)
        script = "\n".join(
            ["source ros_ws/install/setup.bash", line, *commands, "rc=$?; wait; exit $rc"]
        )
        env = {k: v for k, v in os.environ.items() if not k.startswith(("AMENT", "COLCON"))}
        env.pop("ROS_DOMAIN_ID", None)
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
        "state_estimator", "notch_filter", "nominal_trajectory", "tube_mpc", "fault_injector",
        "plant",
    ]  # fmt: skip
    assert all(h["n"] >= N - 1 for h in lat["hops"])
    assert 0.05 < lat["step"]["median_ms"] < 200.0


def test_ros2_standin_bag_info_is_fahv_inspect(design, tmp_path):

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


def _by_hand(hand_graph, quick_case, tmp_path, duration, watchdog, without=()):
    """The README's commands, each node's output in `tmp_path/logs/<node>.log`."""
    return hand_graph(quick_case, tmp_path, duration, watchdog, without, tmp_path / "logs")


def _watchdog_lines(logs, started):
    text = {n: (logs / f"{n}.log").read_text() for n in started}
    for n, log in text.items():
        assert "watchdog: " in log, f"{n}:\n{log[-2000:]}"
    return {n: log[log.index("watchdog: ") :].splitlines()[0] for n, log in text.items()}, text


def test_graph_started_by_hand_without_a_node_names_it_and_every_process_ends(
    quick_case, tmp_path, hand_graph, exit_statuses
):
    """The README's commands without `fault_injector`: every node (the recorder too)
    names fault_injector, not its neighbour, and exits by itself within its watchdog;
    the plant says whom it waits for; the run is readable with status and reason."""
    watchdog = 5.0
    lines, started, env, _ = _by_hand(
        hand_graph, quick_case, tmp_path, 2, watchdog, ["fault_injector"]
    )
    with domain_coordinator.domain_id() as domain:
        env["ROS_DOMAIN_ID"] = str(domain)
        t0 = time.monotonic()
        done = subprocess.run(
            ["bash", "-c", "\n".join(lines)], cwd=ROOT, env=env, capture_output=True,
            text=True, timeout=120,
        )  # fmt: skip
        elapsed = time.monotonic() - t0
    assert started == ["recorder", "state_estimator", "notch_filter", "nominal_trajectory",
                       "tube_mpc", "plant"]  # fmt: skip
    # every node process has ended, each with the watchdog's exit status
    # (a hung DDS teardown after the node closed counts with the status it closed with)
    assert exit_statuses(done.stdout, tmp_path / "logs") == dict.fromkeys(started, 3), \
        done.stdout  # fmt: skip
    verdicts, text = _watchdog_lines(tmp_path / "logs", started)
    for n, verdict in verdicts.items():
        assert verdict.startswith(f"watchdog: {n}: "), verdict
        head = verdict.removeprefix(f"watchdog: {n}: ")
        assert head.startswith(("graph not ready", "missing fault_injector")), f"{n}: {verdict}"
        assert "fault_injector (never started)" in verdict, f"{n}: {verdict}"
        assert "from plant" not in verdict and "plant (" not in verdict, f"{n}: {verdict}"
    assert "waiting for /hsv/actuator_command (from fault_injector)" in text["plant"]
    # start-up (imports, discovery) plus the watchdog, not minutes
    assert elapsed < 30.0 + watchdog, elapsed
    bag = next((tmp_path / "bags").iterdir())
    rec = read_run(bag)
    assert not rec.truncated
    assert rec.metadata["status"] == "interrupted (exit status 3)"
    assert "fault_injector (never started)" in rec.metadata["reason"]
    assert rec.topics["/hsv/state"]["count"] == 0


def test_graph_started_by_hand_names_a_node_killed_mid_run(
    quick_case, tmp_path, hand_graph, exit_statuses
):
    """A node of a hand-started graph killed (SIGKILL) mid-run: every other node, the
    recorder included, names it as lost and exits within its watchdog; the run keeps
    every step recorded so far."""
    watchdog = 5.0
    lines, started, env, params = _by_hand(hand_graph, quick_case, tmp_path, 300, watchdog)
    with domain_coordinator.domain_id() as domain:
        env["ROS_DOMAIN_ID"] = str(domain)
        shell = subprocess.Popen(
            ["bash", "-c", "\n".join(lines)], cwd=ROOT, env=env, stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL, text=True,
        )  # fmt: skip
        t0 = time.monotonic()
        while "progress 500" not in _read(tmp_path / "logs" / "recorder.log"):
            assert time.monotonic() - t0 < 90 and shell.poll() is None, "the graph did not run"
            time.sleep(0.1)
        pids = subprocess.run(
            ["pgrep", "-f", f"lib/hsv_ctrl/tube_mpc .*{params}"], capture_output=True, text=True
        ).stdout.split()
        assert len(pids) == 1
        t_kill = time.monotonic()
        os.kill(int(pids[0]), signal.SIGKILL)
        out, _ = shell.communicate(timeout=120)
        elapsed = time.monotonic() - t_kill
    # the killed node by its signal (128 + 9), every other one by its watchdog
    statuses = exit_statuses(out, tmp_path / "logs")  # a hung teardown: the closing status
    assert statuses == {n: 137 if n == "tube_mpc" else 3 for n in started}, out
    verdicts, _ = _watchdog_lines(tmp_path / "logs", [n for n in started if n != "tube_mpc"])
    for n, verdict in verdicts.items():  # the lost node first, not the neighbour
        assert verdict.startswith(f"watchdog: {n}: missing tube_mpc (lost: no status for"), (
            f"{n}: {verdict}"
        )
    assert elapsed < watchdog + 15.0, elapsed
    rec = read_run(next((tmp_path / "bags").iterdir()))
    assert not rec.truncated and rec.metadata["status"] == "interrupted (exit status 3)"
    assert "tube_mpc (lost" in rec.metadata["reason"]
    assert 500 <= rec.topics["/hsv/state"]["count"] < 15000


def test_the_graph_started_twice_by_hand_with_one_parameter_file_records_two_runs(
    quick_case, tmp_path, hand_graph, exit_statuses
):
    """The README's commands twice with the same parameter file: the second recorder finds
    the run folder taken, says so and records to `<run>-2`; every node of both graphs
    exits 0 and both runs are complete, with the same states."""
    lines, started, env, _ = _by_hand(hand_graph, quick_case, tmp_path, T, None)
    with domain_coordinator.domain_id() as domain:
        env["ROS_DOMAIN_ID"] = str(domain)
        for _ in range(2):
            done = subprocess.run(
                ["bash", "-c", "\n".join(lines)], cwd=ROOT, env=env, capture_output=True,
                text=True, timeout=180,
            )  # fmt: skip
            statuses = exit_statuses(done.stdout, tmp_path / "logs")
            assert statuses == dict.fromkeys(started, 0), done.stdout
    first, second = sorted((tmp_path / "bags").iterdir())
    assert second.name == f"{first.name}-2"
    log = _read(tmp_path / "logs" / "recorder.log")  # the second start's
    assert f"run folder {first} exists already: recording to {second}" in log, log[-2000:]
    runs = [read_run(b) for b in (first, second)]
    for rec in runs:
        assert not rec.truncated and rec.metadata["status"] == "complete"
        assert rec.topics["/hsv/state"]["count"] == N
    a, b = (run_result_of(rec) for rec in runs)
    assert np.array_equal(a.x, b.x) and a.x.shape == (N, 9)


def _read(path):
    return path.read_text() if path.exists() else ""
