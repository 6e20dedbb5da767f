"""Run files: the in-process simulator's recording, read back by us and by rosbags."""

import warnings

import numpy as np
import pytest
from rosbags.highlevel import AnyReader

from fahv.errors import RunError
from fahv.loop.graph import QOS_DEPTH, STATE_FIELDS, TOPICS
from fahv.loop.simulate import simulate
from fahv.model.vehicle import load_vehicle
from fahv.runs.bag import TruncatedRunWarning, bag_paths, read_run, run_result_of
from fahv.runs.metrics import metrics
from fahv.runs.writer import RunWriter
from fahv.sil.runner import run_metadata

#: The fields of a VehicleState message: the state, the actuator positions and rates.
STATE_MSG = (*STATE_FIELDS, "phi_a", "delta_e_a", "phi_a_rate_peak", "delta_e_a_rate_peak")
N = 150  # 3 s at Ts = 0.02


@pytest.fixture(scope="module")
def recorded(design, tmp_path_factory):
    bag = tmp_path_factory.mktemp("runs") / "sim_run"
    with RunWriter(bag, run_metadata(design, "tube_mpc", "simulate", 3.0), 0.02) as w:
        run = simulate(design, "tube_mpc", duration=3.0, writer=w)
    return bag, run


def test_round_trip_equals_the_simulation(recorded):
    bag, run = recorded
    rec = read_run(bag)
    assert not rec.truncated
    assert {t: rec.topics[t]["count"] for t in TOPICS} == dict.fromkeys(TOPICS, N)
    assert rec.metadata["status"] == "complete"
    assert rec.metadata["case"] == "case1_paper" and rec.metadata["source"] == "simulate"
    back = run_result_of(rec)
    np.testing.assert_array_equal(back.x, run.x)
    np.testing.assert_array_equal(back.u, run.u)
    np.testing.assert_array_equal(back.tube_level, run.tube_level)
    lim = load_vehicle().limits
    assert metrics(back, lim) == metrics(run, lim)
    # log time is simulated time
    assert rec.topics["/hsv/state"]["last_ns"] == (N - 1) * 20_000_000


def test_rosbags_reads_every_message_with_full_definitions(recorded):
    bag, run = recorded
    with AnyReader([bag]) as reader:
        conns = {c.topic: c for c in reader.connections}
        assert set(conns) == set(TOPICS)
        assert "builtin_interfaces/Time clock" in conns["/clock"].msgdef.data
        assert "MSG: builtin_interfaces/Time" in conns["/clock"].msgdef.data
        assert "float64 eta_2_dot" in conns["/hsv/state"].msgdef.data
        qos = conns["/hsv/state"].ext.offered_qos_profiles[0]
        assert qos.reliability.name == "RELIABLE" and qos.depth == QOS_DEPTH
        counts = dict.fromkeys(TOPICS, 0)
        h = []
        for conn, t_ns, raw in reader.messages():
            msg = reader.deserialize(raw, conn.msgtype)
            counts[conn.topic] += 1
            if conn.topic == "/hsv/state":
                assert t_ns == msg.k * 20_000_000
                h.append(msg.h)
    assert counts == dict.fromkeys(TOPICS, N)
    np.testing.assert_array_equal(h, run.x[:, 0])


def test_truncated_file_is_read_up_to_the_last_chunk(tmp_path):
    """A recorder killed mid-run: the complete 1 MiB chunks are read, with a warning."""
    n_msgs = 20000  # about 2.4 MB of VehicleState: several chunks
    with RunWriter(tmp_path / "long", {"case": "synthetic"}, 0.02) as w:
        for k in range(n_msgs):
            w.write("/hsv/state", k, {"k": k, "t": 0.02 * k, **dict.fromkeys(STATE_MSG, 1.0)})
    _, mcap = bag_paths(tmp_path / "long")
    data = mcap.read_bytes()
    cut = tmp_path / "cut" / "cut.mcap"
    cut.parent.mkdir()
    cut.write_bytes(data[: len(data) * 2 // 3])
    with pytest.warns(TruncatedRunWarning, match="truncated"):
        rec = read_run(cut)
    assert rec.truncated
    n = rec.topics["/hsv/state"]["count"]
    assert 0.3 * n_msgs < n < 0.7 * n_msgs
    assert [m["k"] for m in rec.records["/hsv/state"]] == list(range(n))
    # a file cut inside its first chunk: no message, still no exception
    (tmp_path / "cut2").mkdir()
    (tmp_path / "cut2" / "c.mcap").write_bytes(data[:5000])
    with pytest.warns(TruncatedRunWarning):
        assert read_run(tmp_path / "cut2" / "c.mcap").topics == {}


def test_corrupt_and_missing_files_give_clear_errors(tmp_path):
    bad = tmp_path / "x.mcap"
    bad.write_bytes(b"not an mcap file at all")
    with pytest.raises(RunError, match="not an MCAP file"):
        read_run(bad)
    with pytest.raises(RunError, match="does not exist"):
        read_run(tmp_path / "nope.mcap")


def test_writer_refuses_to_overwrite_a_run(recorded, design):
    with pytest.raises(RunError, match="exists already"):
        RunWriter(recorded[0], {}, 0.02)


def test_run_from_another_program_lists_unknown_topics(tmp_path):
    from mcap.writer import Writer

    path = tmp_path / "other.mcap"
    with open(path, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2", library="test")
        sid = w.register_schema("std_msgs/msg/String", "ros2msg", b"string data")
        cid = w.register_channel("/chatter", "cdr", sid)
        w.add_message(
            cid, log_time=1, publish_time=1, data=b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00"
        )
        w.finish()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        rec = read_run(path)
    assert rec.topics["/chatter"] == {
        "type": "std_msgs/msg/String",
        "count": 1,
        "first_ns": 1,
        "last_ns": 1,
    }
    assert all(len(v) == 0 for v in rec.records.values())
    with pytest.raises(RunError, match="no complete step"):
        metrics(run_result_of(rec), load_vehicle().limits)


def test_paper_style_figures_of_a_recorded_run(recorded, tmp_path):
    from fahv.runs.plots import GROUPS, plot_group

    run = run_result_of(read_run(recorded[0]))
    for group in GROUPS:
        path = plot_group(group, [("a", run), ("b", run)], tmp_path / f"{group}.png")
        assert path.stat().st_size > 10_000
    with pytest.raises(ValueError, match="no run"):
        plot_group("trajectory", [], tmp_path / "x.png")


def test_a_stop_inside_a_chunk_write_ends_the_run_whole(tmp_path):
    """A stop (SIGTERM in `fahv`) arriving while a 1 MiB chunk is written to the file is
    raised after the write: the run closes as interrupted, complete, every message read.

    Before the deferral it was raised between the two halves of the chunk record and the
    file read as truncated (3 of 16 interrupted `fahv simulate` runs)."""
    from fahv import interrupt

    w = RunWriter(tmp_path / "run", {"case": "synthetic"}, 0.02)
    storage = w._writer.storage
    real = storage._file

    class StopInsideWrite:
        """The file, with a stop requested half-way through its first large write."""

        stopped = False

        def write(self, b):
            if len(b) < 100_000 or self.stopped:
                return real.write(b)
            self.stopped = True
            n = real.write(b[: len(b) // 2])
            interrupt.request()  # without the deferral: KeyboardInterrupt here
            return n + real.write(b[len(b) // 2 :])

        def __getattr__(self, name):
            return getattr(real, name)

    storage._file = storage._mcap._Writer__stream = StopInsideWrite()  # noqa: SLF001
    written = 0
    with pytest.raises(KeyboardInterrupt), w:
        for k in range(20000):
            w.write("/hsv/state", k, {"k": k, "t": 0.02 * k, **dict.fromkeys(STATE_MSG, 1.0)})
            written += 1
    interrupt.clear()
    assert storage._file.stopped and 5000 < written < 20000
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a truncated file warns
        rec = read_run(tmp_path / "run")
    assert not rec.truncated and rec.metadata["status"] == "interrupted"
    # the stop is raised after the write it arrived in: that message is in the file
    assert rec.topics["/hsv/state"]["count"] == written + 1
    assert [m["k"] for m in rec.records["/hsv/state"]] == list(range(written + 1))
