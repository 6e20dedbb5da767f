"""A run file stands alone: metadata, the parameter file of every node and the
recorder's timestamps live in the .mcap, so a renamed folder, a copy and the bare file
open in every tool; runs written by earlier versions (sidecar files) still open."""

import json
import re
import shutil

import numpy as np
import pytest
import yaml
from mcap.reader import make_reader
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin, Writer

from fahv.cli import main
from fahv.loop.graph import TOPICS
from fahv.loop.simulate import simulate
from fahv.model.vehicle import load_vehicle
from fahv.runs.bag import (
    PARAMS,
    RUN_RECORD,
    bag_paths,
    read_run,
    run_params,
    run_result_of,
    stored_metadata,
)
from fahv.runs.latency import TIMESTAMPS_FILE, load_timestamps, run_latencies, save_timestamps
from fahv.runs.messages import LOOP_QOS
from fahv.runs.metrics import metrics
from fahv.runs.writer import RunWriter
from fahv.sil.runner import recorder_metadata, run_parameter_file
from fahv.sil.wire import encode, typestore

T, N = 2.0, 100


def _cli(capsys, *argv):
    rc = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return rc, out, err


@pytest.fixture(scope="module")
def design(paper_scenario_design):
    """Case 1 (scenario case1_paper) on its shipped design, as `fahv simulate` runs it: a
    run file needs a design, not a new one (loaded, not designed)."""
    return paper_scenario_design


@pytest.fixture(scope="module")
def run(design, tmp_path_factory):
    """A run of `fahv simulate` (its writer as the command uses it), with timestamps."""
    bag = tmp_path_factory.mktemp("runs") / "case1_tube_mpc_sim_x"
    content = run_parameter_file(design, "tube_mpc", bag, T, 10.0, source="simulate")
    stamps = {t: np.arange(3 * N, dtype=np.int64) for t in TOPICS}
    with RunWriter(bag, recorder_metadata(content), 0.02, params=content) as w:
        res = simulate(design, "tube_mpc", duration=T, writer=w)
        w.close("complete", {TIMESTAMPS_FILE: _npz(stamps)})
    return bag, res, content


def _npz(stamps):
    from fahv.runs.latency import timestamps_npz

    return timestamps_npz(stamps)


def test_the_file_holds_metadata_parameters_and_timestamps(run):
    bag, res, content = run
    assert sorted(p.name for p in bag.iterdir()) == ["case1_tube_mpc_sim_x.mcap", "metadata.yaml",
                                                     "run.json"]  # fmt: skip
    with open(bag_paths(bag)[1], "rb") as f:
        reader = make_reader(f)
        records = [m for m in reader.iter_metadata() if m.name == RUN_RECORD]
        atts = {a.name: a for a in reader.iter_attachments()}
    # written at the start (a file cut short keeps it) and again at the end
    assert [m.metadata["status"] for m in records] == ["running", "complete"]
    assert records[-1].metadata["case"] == "case1_paper"
    fault = content["fault_injector"]["ros__parameters"]
    assert records[-1].metadata["fault_rho_f"] == str(fault["rho_f"])
    assert yaml.safe_load(atts[PARAMS].data) == content
    assert atts[PARAMS].media_type == "application/yaml"
    assert set(load_timestamps(atts[TIMESTAMPS_FILE].data)) == set(TOPICS)
    # rosbag2's view is unchanged: metadata.yaml names the file relative to the folder
    info = yaml.safe_load((bag / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info["relative_file_paths"] == ["case1_tube_mpc_sim_x.mcap"]
    assert info["custom_data"]["status"] == "complete"
    with AnyReader([bag]) as reader:
        assert {c.topic for c in reader.connections} == set(TOPICS)
        assert sum(1 for _ in reader.messages()) == N * len(TOPICS)


@pytest.fixture(scope="module")
def moved(run, tmp_path_factory):
    """The run as a renamed folder, a copy under another name, and the bare .mcap."""
    bag, _, _ = run
    root = tmp_path_factory.mktemp("moved")
    renamed = root / "myrun"
    shutil.copytree(bag, renamed)
    copy = root / "copy_of_it"
    shutil.copytree(bag, copy)
    (copy / "run.json").unlink()
    bare = root / "alone" / "x.mcap"
    bare.parent.mkdir()
    shutil.copy(bag_paths(bag)[1], bare)
    return {"renamed": renamed, "copy": copy, "bare": bare}


@pytest.mark.parametrize("kind", ["renamed", "copy", "bare"])
def test_renamed_copied_and_bare_runs_read_like_the_original(run, moved, kind):
    bag, res, content = run
    path = moved[kind]
    rec = read_run(path)
    assert rec.metadata["status"] == "complete" and rec.metadata["source"] == "simulate"
    np.testing.assert_array_equal(run_result_of(rec).x, res.x)
    assert rec.params() == content and run_params(path) == content
    assert stored_metadata(path)["design_hash"] == rec.metadata["design_hash"]
    lat = run_latencies(rec.attachment(TIMESTAMPS_FILE), rec.params())
    assert lat is not None and [h["node"] for h in lat["hops"]][3] == "tube_mpc"


def test_inspect_plot_compare_and_rerun_take_renamed_and_bare_runs(run, moved, tmp_path, capsys):
    bag, res, _ = run
    lim = load_vehicle().limits
    ref = metrics(res, lim)
    for kind in ("renamed", "bare"):
        path = moved[kind]
        rc, out, err = _cli(capsys, "inspect", path)
        assert rc == 0, err
        row = re.search(r"max \|alpha - alpha_r\| \[deg\]\s+(\S+)", out).group(1)
        assert float(row) == pytest.approx(ref["alpha_err_max_deg"], abs=5e-4)
        assert "wall-clock latency per hop" in out  # the timestamps come from the file
        rc, out, err = _cli(capsys, "plot", path, "--out", tmp_path / kind)
        assert rc == 0 and (tmp_path / kind / "tube.png").stat().st_size > 10_000
        rc, out, err = _cli(capsys, "compare", bag, path)
        assert rc == 0, err
        assert re.search(r"max \|alpha - alpha_r\| \[deg\]\s+\S+\s+\S+\s+0\.000", out), out
        rc, out, err = _cli(capsys, "campaign", "rerun", path, "--out", tmp_path / f"re_{kind}")
        assert rc == 0, out + err
        m = re.search(r"metrics identical to the recorded run's \((\d+) metrics\)", out)
        assert m and int(m.group(1)) == len(ref), out
        new = read_run(next((tmp_path / f"re_{kind}").iterdir()))
        assert new.metadata["source"] == "rerun" and new.metadata["rerun_of"].endswith(".mcap")
        np.testing.assert_array_equal(run_result_of(new).x, res.x)  # bit for bit


def _old_layout_run(design, folder):
    """A run as earlier versions wrote it: rosbags' own MCAP writer, the metadata only in
    the bag's custom data, params.yaml, timestamps.npz and run.json beside the file."""
    bag = folder / "old_run"
    content = run_parameter_file(design, "tube_mpc", bag, 0.2, 10.0, source="simulate")
    meta = recorder_metadata(content)
    ts = typestore()
    with Writer(bag, version=9, storage_plugin=StoragePlugin.MCAP) as w:
        for k, v in {**meta, "status": "complete"}.items():
            w.set_custom_data(k, str(v))
        conns = {t: w.add_connection(t, m, typestore=ts, offered_qos_profiles=[LOOP_QOS])
                 for t, m in TOPICS.items()}  # fmt: skip

        class Sink:
            def write(self, topic, k, msg):
                w.write(conns[topic], k * 20_000_000, encode(topic, msg))

        res = simulate(design, "tube_mpc", duration=0.2, writer=Sink())
    (bag / "params.yaml").write_text(yaml.safe_dump(content, sort_keys=False))
    save_timestamps(bag, {t: np.arange(30, dtype=np.int64) for t in TOPICS})
    (bag / "run.json").write_text(json.dumps({**meta, "status": "complete"}))
    return bag, res, content


def test_runs_of_earlier_versions_still_open(design, tmp_path, capsys):
    bag, res, content = _old_layout_run(design, tmp_path)
    with open(bag_paths(bag)[1], "rb") as f:
        assert list(make_reader(f).iter_attachments()) == []  # really the old layout
    rec = read_run(bag)
    assert rec.metadata["status"] == "complete" and rec.metadata["case"] == "case1_paper"
    assert rec.params() == content and run_params(bag) == content
    assert stored_metadata(bag)["design_hash"] == content["plant"]["ros__parameters"]["design_hash"]
    assert load_timestamps(rec.attachment(TIMESTAMPS_FILE))["/hsv/state"].shape == (10, 3)
    np.testing.assert_array_equal(run_result_of(rec).x, res.x)
    rc, out, err = _cli(capsys, "inspect", bag)
    assert rc == 0 and "status        complete" in out
    # renamed, an old folder still finds its file through metadata.yaml and its sidecars
    renamed = tmp_path / "renamed_old"
    shutil.copytree(bag, renamed)
    assert read_run(renamed).params() == content
    # the bare old file has no parameter file: rerun says so, naming the way out
    bare = tmp_path / "bare_old.mcap"
    shutil.copy(bag_paths(bag)[1], bare)
    assert read_run(bare).params() is None
    rc, out, err = _cli(capsys, "campaign", "rerun", bare, "--out", tmp_path / "re")
    assert rc == 2 and "holds no parameter file" in err and "Traceback" not in err
