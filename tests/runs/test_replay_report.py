"""Replay that reports: a graph started by hand with `ros2 run` records a run
whose file holds its parameter file, so `fahv replay` works on it (renamed or bare too),
says whether every captured output equals the recorded one, and writes a run that the
other tools accept."""

import re
import shutil
import subprocess

import domain_coordinator
import numpy as np
import pytest
import yaml

from fahv.cli import main
from fahv.loop.graph import TOPICS
from fahv.runs.bag import bag_paths, iter_raw, read_run, run_result_of
from fahv.runs.replay import run_replay
from fahv.sil.workspace import ROOT

pytestmark = pytest.mark.ros  # every test here runs the built node graph

T, N = 2.0, 100


#: Case 1 (scenario case1_paper, first variant tube_mpc) and its shipped design: what
#: `fahv sil CASE --design DIR` runs (loaded and verified, not designed).
SHIPPED_CASE = (ROOT / "offline_design" / "scenarios" / "case1_paper.yaml",
                ROOT / "offline_design" / "designs" / "cm_paper")  # fmt: skip


@pytest.fixture(scope="module")
def hand_run(tmp_path_factory, hand_graph, exit_statuses):
    """The README's graph by hand: `fahv sil --write-params`, then one `ros2 run` per node."""
    tmp = tmp_path_factory.mktemp("hand")
    lines, started, env, params = hand_graph(SHIPPED_CASE, tmp, T, logs=tmp / "logs")
    with domain_coordinator.domain_id() as domain:
        env["ROS_DOMAIN_ID"] = str(domain)
        done = subprocess.run(
            ["bash", "-c", "\n".join(lines)], cwd=ROOT, env=env, capture_output=True,
            text=True, timeout=180,
        )  # fmt: skip
    assert exit_statuses(done.stdout, tmp / "logs") == dict.fromkeys(started, 0), done.stdout
    bag = next((tmp / "bags").iterdir())
    return bag, params


def _cli(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


def test_the_hand_started_recorder_puts_the_parameter_file_in_the_run(hand_run):
    bag, params = hand_run
    assert not (bag / "params.yaml").exists()  # nothing beside the file is needed
    rec = read_run(bag)
    assert rec.metadata["status"] == "complete" and rec.metadata["source"] == "sil"
    assert rec.params() == yaml.safe_load(params.read_text())
    assert rec.attachment("timestamps.npz") is not None


def test_replay_of_a_hand_started_run_reports_outputs_identical(hand_run, tmp_path, capsys):
    bag, _ = hand_run
    out = tmp_path / "replay_check"
    rc, text, err = _cli(capsys, "replay", bag, "--node", "tube_mpc", "--fast", "--quiet",
                         "--out", out)  # fmt: skip
    assert rc == 0, text + err
    m = re.search(r"outputs identical: (\d+) of (\d+) messages on (\S+), (\S+) equal", text)
    assert m, text
    assert (int(m.group(1)), int(m.group(2))) == (2 * N, 2 * N)
    assert (m.group(3), m.group(4)) == ("/hsv/control_command", "/hsv/tube_status")
    # the replay's folder is a complete run: every loop topic, metrics, fahv compare
    rec = read_run(out)
    assert rec.metadata["source"] == "replay" and rec.metadata["status"] == "complete"
    assert {t: rec.topics[t]["count"] for t in TOPICS} == dict.fromkeys(TOPICS, N)
    assert rec.params() == read_run(bag).params()
    np.testing.assert_array_equal(run_result_of(rec).u, run_result_of(read_run(bag)).u)
    rc, text, err = _cli(capsys, "compare", bag, out)
    assert rc == 0, err
    assert re.search(r"max \|alpha - alpha_r\| \[deg\]\s+\S+\s+\S+\s+0\.000", text), text


def test_replay_names_the_first_output_that_differs(hand_run, tmp_path, capsys):
    """A tube_mpc with a feedback F 1 % stronger (parameter file given by hand) is caught."""
    bag, params = hand_run
    content = yaml.safe_load(params.read_text())
    p = content["tube_mpc"]["ros__parameters"]
    p["F"] = [1.01 * v for v in p["F"]]
    changed = tmp_path / "changed.yaml"
    changed.write_text(yaml.safe_dump(content))
    rc, text, err = _cli(capsys, "replay", bag, "--node", "tube_mpc", "--fast", "--quiet",
                         "--params", changed)  # fmt: skip
    assert rc == 1, text + err
    m = re.search(r"outputs differ: (\d+) of (\d+) messages .* first: (\S+) at step (\d+): "
                  r"field '(\w+)'", text)  # fmt: skip
    assert m, text
    assert 0 < int(m.group(1)) <= 2 * N and int(m.group(2)) == 2 * N
    assert m.group(3) in ("/hsv/control_command", "/hsv/tube_status")


def test_renamed_and_bare_hand_started_runs_replay_and_rerun(hand_run, tmp_path, capsys):
    bag, _ = hand_run
    renamed = tmp_path / "renamed"
    shutil.copytree(bag, renamed)
    bare = tmp_path / "alone.mcap"
    shutil.copy(bag_paths(bag)[1], bare)
    res = run_replay(bare, nodes=["tube_mpc"], rate=0.0, quiet=True, log=lambda *_: None)
    assert res.returncode == 0 and res.outputs is not None and res.outputs.identical
    assert res.outputs.compared == 2 * N
    orig = [d for *_, d in iter_raw(bag, ["/hsv/control_command"])]
    assert [d for *_, d in iter_raw(res.out, ["/hsv/control_command"])] == orig
    # rerun from the bare file alone: in process, equal to the graph (SIL equals simulate)
    rc, text, err = _cli(capsys, "campaign", "rerun", bare, "--out", tmp_path / "re")
    assert rc == 0 and "metrics identical to the recorded run's" in text, text + err
    # and through the graph again, from the file alone
    rc, text, err = _cli(capsys, "campaign", "rerun", renamed, "--sil", "--quiet",
                         "--out", tmp_path / "re_sil")  # fmt: skip
    assert rc == 0 and "metrics identical to the recorded run's" in text, text + err
    [new] = (tmp_path / "re_sil").iterdir()
    assert new.name.startswith(f"{bag_paths(bag)[1].stem}_rerun_sil_")
    assert read_run(new).metadata["source"] == "sil"
