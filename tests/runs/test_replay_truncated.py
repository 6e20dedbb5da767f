"""Replay of a truncated recording: only its complete steps are replayed and compared.

A recorder killed mid-run leaves a file without summary whose last steps hold some
topics only (it lags on some more than on others). Such a step cannot be replayed into
a node under test: its inputs were never recorded. The replay stops before it, says
that the recording is truncated there, and does not count the node's silence on the
steps after it as a difference.

The recording is built here from an in-process run (no ROS): ``N`` complete steps,
then ``LAG`` steps without ``/hsv/nominal`` (an input of ``tube_mpc``), the file cut
after its last chunk. The ``sil`` runner is replaced by a stand-in that writes what
a replay of the complete steps captures.
"""

import os
import shutil

import pytest
import yaml
from mcap.reader import make_reader

from fahv.loop.graph import TOPICS, replay_topics
from fahv.loop.simulate import simulate
from fahv.runs import replay
from fahv.runs.bag import bag_paths, read_run
from fahv.runs.replay import RecordedSteps, compare_outputs, recorded_steps, run_replay
from fahv.runs.writer import RunWriter
from fahv.sil.runner import recorder_metadata, run_parameter_file

N, LAG = 50, 8  # complete steps, then steps with a lagging topic
LAGGING = "/hsv/nominal"
INPUTS, OUTPUTS = replay_topics(["tube_mpc"])


class _Recording:
    """Writer of one simulation into a truncated run and a run of its complete steps."""

    def __init__(self, cut: RunWriter, complete: RunWriter):
        self.cut, self.complete = cut, complete

    def write(self, topic, k, msg):
        if k < N or topic != LAGGING:
            self.cut.write(topic, k, msg)
        if k < N:
            self.complete.write(topic, k, msg)


def _cut_after_last_chunk(run) -> None:
    """Drop the summary and footer: what a recorder killed after its last chunk leaves."""
    _, mcap = bag_paths(run)
    with open(mcap, "rb") as f:
        chunks = make_reader(f).get_summary().chunk_indexes
    os.truncate(mcap, max(c.chunk_start_offset + c.chunk_length for c in chunks))


@pytest.fixture(scope="module")
def runs(design, tmp_path_factory):
    """(truncated run, run of its N complete steps, Ts [s])."""
    root = tmp_path_factory.mktemp("truncated")
    cut = root / "case1_tube_mpc_sim_cut"
    content = run_parameter_file(design, "tube_mpc", cut, None, 10.0, source="simulate")
    Ts = float(content["tube_mpc"]["ros__parameters"]["Ts"])
    meta = recorder_metadata(content)
    with (
        RunWriter(cut, meta, Ts, params=content) as w_cut,
        RunWriter(root / "complete", meta, Ts, params=content) as w_complete,
    ):
        simulate(design, "tube_mpc", duration=(N + LAG) * Ts, writer=_Recording(w_cut, w_complete))
    _cut_after_last_chunk(cut)
    return cut, root / "complete", Ts


@pytest.fixture
def stand_in_runner(monkeypatch, tmp_path, runs):
    """Replace the built workspace and the ``sil`` runner; returns the work folder.

    The runner's output run is the run of the complete steps, as the ``replay`` node
    writes it when it replays them into a ``tube_mpc`` that answers every step.
    """
    work = tmp_path / "work"

    def reserve(name, root):
        work.mkdir()
        return name, work

    def runner(cmd, env):
        out = yaml.safe_load((work / "params.yaml").read_text())["replay"]["ros__parameters"]
        shutil.copytree(runs[1], out["out"])
        return 0, False

    monkeypatch.setattr(replay, "ensure_built", lambda log=None: None)
    monkeypatch.setattr(replay, "ros_env", dict)
    monkeypatch.setattr(replay, "reserve_run", reserve)
    monkeypatch.setattr(replay, "run_runner", runner)
    return work


@pytest.mark.filterwarnings("ignore::fahv.runs.bag.TruncatedRunWarning")
def test_the_built_recording_is_cut_short_with_a_lagging_topic(runs):
    rec = read_run(runs[0])
    assert rec.truncated
    assert {t: v["count"] for t, v in rec.topics.items() if v["count"] != N + LAG} == {LAGGING: N}


def test_only_steps_with_every_needed_topic_are_complete(runs):
    got = recorded_steps(runs[0], INPUTS + OUTPUTS)
    assert got == RecordedSteps(N, N + LAG, INPUTS + OUTPUTS, [LAGGING], file_truncated=True)
    assert got.summary("cut.mcap") == (
        f"cut.mcap: recording truncated at step {N} (the file ends before its summary): "
        f"step {N} has no {LAGGING}; replaying the {N} complete steps of {N + LAG} recorded"
    )
    # a step needs only the topics given: /hsv/state was recorded at every step
    assert recorded_steps(runs[0], ["/hsv/state"]).complete == N + LAG
    assert recorded_steps(runs[1]) == RecordedSteps(N, N, list(TOPICS))


@pytest.mark.filterwarnings("ignore::fahv.runs.bag.TruncatedRunWarning")
def test_replay_of_a_truncated_run_stops_at_the_truncation(runs, stand_in_runner, tmp_path):
    cut, _, Ts = runs
    lines = []
    res = run_replay(cut, nodes=["tube_mpc"], out=tmp_path / "out", rate=0.0, log=lines.append)
    params = yaml.safe_load((stand_in_runner / "params.yaml").read_text())
    assert params["replay"]["ros__parameters"]["steps"] == N
    assert params["tube_mpc"]["ros__parameters"]["duration"] == pytest.approx(N * Ts)
    assert f"recording truncated at step {N}" in lines[0]
    assert res.recorded.complete == N and res.recorded.recorded == N + LAG
    assert (res.outputs.compared, res.outputs.equal) == (2 * N, 2 * N)
    assert res.outputs.identical and res.outputs.truncated_at == N
    assert res.outputs.summary() == (
        f"outputs identical: {2 * N} of {2 * N} messages on {', '.join(OUTPUTS)} equal the "
        f"recorded ones byte for byte (recording truncated at step {N}: later steps not compared)"
    )
    # the steps after the truncation, compared too, would blame the node under test
    blamed = compare_outputs(cut, res.out, OUTPUTS)
    assert (blamed.compared, blamed.equal) == (2 * (N + LAG), 2 * N)
    assert blamed.first_difference == f"{OUTPUTS[0]} at step {N}: not captured"


@pytest.mark.filterwarnings("ignore::fahv.runs.bag.TruncatedRunWarning")
def test_fewer_steps_than_the_complete_ones_are_replayed_as_asked(runs, stand_in_runner, tmp_path):
    lines = []
    res = run_replay(runs[0], nodes=["tube_mpc"], out=tmp_path / "out", steps=20, rate=0.0,
                     log=lines.append)  # fmt: skip
    params = yaml.safe_load((stand_in_runner / "params.yaml").read_text())
    assert params["replay"]["ros__parameters"]["steps"] == 20
    assert not any("truncated" in line for line in lines)
    assert res.outputs.compared == 40 and res.outputs.truncated_at is None


@pytest.mark.ros  # imports the replay node (rclpy, the built workspace)
def test_the_replay_node_by_hand_keeps_the_complete_steps_too(runs):
    """``ros2 run hsv_bringup replay`` with ``steps: 0`` (every step) loads the N
    complete steps of the cut recording, not the N + LAG recorded, and says why."""
    import subprocess
    import sys

    from fahv.sil.workspace import ensure_built, ros_env

    ensure_built()
    code = (
        "import sys\n"
        "from hsv_bringup.replay import load_steps\n"
        f"steps, Ts, topics = load_steps(sys.argv[1], {INPUTS!r}, 0, {OUTPUTS!r})\n"
        "print(len(steps), round(Ts, 6))\n"
    )
    r = subprocess.run([sys.executable, "-c", code, str(runs[0])], env=ros_env(),
                       capture_output=True, text=True, timeout=120)  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.split() == [str(N), str(round(runs[2], 6))]
    assert f"recording truncated at step {N}" in r.stderr
