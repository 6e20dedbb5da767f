"""The rules a node applies to its peers' statuses (fahv.sil.peers), without a graph."""

import json
import time

import pytest

from fahv.loop.graph import DEFAULT_GRAPH, STATUS_LOST_S
from fahv.sil.peers import Peers, parse_status, status

T0 = 1_000_000.0


def st(node, pid, run="run-a", start=T0, state="ready", stamp=T0 + 5, **kw):
    return parse_status(status(node, pid, run, start, state, stamp=stamp, **kw))


def table(node="notch_filter", run="run-a", start=T0 + 1):
    return Peers(node, 100, run, start, list(DEFAULT_GRAPH))


def test_a_status_round_trips_and_other_texts_are_not_statuses():
    s = st("plant", 7, state="exited", exit_status=3, reason="plant: x", k=12)
    assert (s["node"], s["pid"], s["state"], s["exit"], s["k"]) == ("plant", 7, "exited", 3, 12)
    assert parse_status("plant") is None  # the old plain-name readiness message
    assert parse_status(json.dumps({"node": "plant"})) is None
    with pytest.raises(ValueError, match="node state must be one of"):
        status("plant", 1, "", T0, "sleeping")


def test_missing_peers_are_named_never_started_exited_or_lost():
    p = table()
    now = T0 + 6
    for i, n in enumerate(["recorder", "state_estimator", "nominal_trajectory", "tube_mpc",
                           "plant"]):  # fmt: skip
        p.update(st(n, 10 + i))
    assert p.missing(now) == ["fault_injector (never started)"]
    assert p.ready("plant") and not p.ready("fault_injector")
    assert p.failed() == []  # asked before the exit: the answer must follow the new status
    p.update(st("tube_mpc", 12, state="exited", exit_status=2, reason="tube_mpc: bad F", k=0,
                stamp=T0 + 5.5))  # fmt: skip
    assert "tube_mpc (exited with status 2 at step 0: tube_mpc: bad F)" in p.missing(now)
    assert p.failed() == ["tube_mpc (exited with status 2 at step 0: tube_mpc: bad F)"]
    lost = p.missing(T0 + 5 + STATUS_LOST_S + 1.5)
    assert "plant (lost: no status for 5.5 s, last at step 0)" in lost
    p.update(st("plant", 13, stamp=T0 + 4))  # an older status of the same instance: ignored
    assert p.own("plant")["stamp"] == T0 + 5


def test_a_peer_that_stopped_for_the_same_missing_node_is_not_named_as_the_cause():
    """Without fault_injector, the plant's watchdog may fire before the recorder's: the
    recorder names fault_injector and only lists the plant, without its reason; a peer
    that failed for its own reason is described."""
    p = table("recorder")
    now = T0 + 6
    for i, n in enumerate(["state_estimator", "notch_filter", "nominal_trajectory", "tube_mpc"]):
        p.update(st(n, 10 + i, state="starting"))
    assert p.failed_verdict(now) is None
    why = "plant: graph not ready: missing fault_injector (never started); waiting for x"
    p.update(st("plant", 14, state="exited", exit_status=3, reason=why))
    assert p.failed_verdict(now) == (
        "missing fault_injector (never started); stopped with plant, which exited for it too"
    )
    p.update(st("tube_mpc", 13, state="exited", exit_status=2, reason="tube_mpc: bad F"))
    verdict = p.failed_verdict(now)
    assert verdict == (
        "missing fault_injector (never started); "
        "peer tube_mpc (exited with status 2 at step 0: tube_mpc: bad F)"
    )


def test_a_starting_peer_is_not_missing_and_says_what_it_waits_for():
    p = table("plant")
    p.update(st("tube_mpc", 3, state="starting", waiting=["/hsv/control_command (to x)"]))
    assert p.missing(T0 + 6)[0] != "tube_mpc (never started)"
    assert p.not_ready(T0 + 6) == ["tube_mpc (starting, waits for /hsv/control_command (to x))"]


def test_the_graph_that_joined_second_stops_and_the_first_goes_on():
    first = table(run="run-a", start=T0 + 1)
    second = table(run="run-b", start=T0 + 30)
    for n, pid in (("plant", 1), ("tube_mpc", 2)):
        first.update(st(n, pid, run="run-a", start=T0, stamp=T0 + 31))
        second.update(st(n, pid, run="run-a", start=T0, stamp=T0 + 31))
        first.update(st(n, 50 + pid, run="run-b", start=T0 + 29, stamp=T0 + 31))
        second.update(st(n, 50 + pid, run="run-b", start=T0 + 29, stamp=T0 + 31))
    action, text = second.foreign_verdict(7, now=T0 + 31)
    assert action == "stop"
    assert "another graph (run 'run-a': plant, tube_mpc) is running in ROS domain 7" in text
    assert "this graph stops" in text
    action, text = first.foreign_verdict(7, now=T0 + 31)
    assert action == "stay" and "joined ROS domain 7" in text and "this run goes on" in text
    assert first.explains("plant", now=T0 + 31) and not second.explains("plant", now=T0 + 31)
    # once the later graph's nodes have exited, nothing is left to explain or to stop
    for n, pid in (("plant", 51), ("tube_mpc", 52)):
        first.update(st(n, pid, run="run-b", start=T0 + 29, state="exited", stamp=T0 + 32))
    assert first.foreign_verdict(7, now=T0 + 33) is None


def test_the_same_run_twice_cannot_be_told_apart():
    p = table("plant", run="run-a")
    p.update(st("plant", 555, run="run-a", start=T0 - 100, stamp=T0 + 5))
    action, text = p.foreign_verdict(3, now=T0 + 6)
    assert action == "stop" and "a second plant of the same run 'run-a'" in text


def test_a_peer_that_ended_the_run_with_a_verdict_is_no_failure():
    from fahv.verdict import Verdict

    v = Verdict("nominal_out_of_domain", "nominal_trajectory", 275, 5.5, "the nominal left")
    p = table("plant")
    assert p.run_verdict() is None
    p.update(st("nominal_trajectory", 9, state="exited", exit_status=6, k=275,
                reason=v.text(), verdict=v.as_dict()))  # fmt: skip
    assert p.run_verdict() == v
    assert p.failed() == [] and p.failed_verdict() is None  # the run ended, nobody failed
    # announced before the exit: a node lingering for its last messages' delivery
    early = table("plant")
    early.update(st("nominal_trajectory", 9, state="running", k=275, verdict=v.as_dict()))
    assert early.run_verdict() == v
    # another run's verdict is not this run's
    other = table("plant")
    other.update(st("nominal_trajectory", 9, run="run-b", state="running", verdict=v.as_dict()))
    assert other.run_verdict() is None


def test_no_verdict_is_taken_while_the_same_run_runs_twice():
    """A node of the run lingering with its verdict beside a second instance of it (the
    run started again from the same parameter file): the verdict may be the old one's, so
    none is taken; the foreign-graph check stops both."""
    from fahv.verdict import Verdict

    v = Verdict("nominal_out_of_domain", "nominal_trajectory", 275, 5.5, "the nominal left")
    now = time.time()
    p = table("plant")
    p.update(st("nominal_trajectory", 9, state="running", stamp=now, verdict=v.as_dict()))
    assert p.run_verdict() == v
    p.update(st("nominal_trajectory", 10, state="ready", stamp=now))
    assert p.twins() == ["nominal_trajectory"] and p.run_verdict() is None
    p.update(st("tube_mpc", 10, state="exited", exit_status=3, k=275, reason="tube_mpc: x"))
    assert p.failed() == ["tube_mpc (exited with status 3 at step 275: tube_mpc: x)"]
