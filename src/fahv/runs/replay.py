"""`fahv replay`: republish a recorded run over DDS, optionally into nodes under test.

With nodes under test, the `replay` node publishes the recorded inputs of those
nodes and captures their outputs in lockstep; its output run holds the captured
topics and, for every other loop topic, the recorded messages, so it is a complete
run (metrics, `fahv compare`). `compare_outputs` then says whether every
captured message equals the recorded one, byte for byte.

Only complete steps are replayed (`recorded_steps`): a recording cut short (its
recorder killed) may hold the last steps on some topics only, and a node under test
cannot answer a step whose inputs were never recorded.
"""

from __future__ import annotations

import json
import math
import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml

from fahv.errors import RunError
from fahv.loop.graph import TOPICS
from fahv.runs.bag import (
    END_KEYS,
    PARAMS,
    TruncatedRunWarning,
    iter_raw,
    run_attachments,
    run_params,
    stored_metadata,
)
from fahv.runs.messages import decode
from fahv.sil.runner import _runner, reserve_run, run_runner
from fahv.sil.workspace import WS, ensure_built, ros_env


@dataclass
class RecordedSteps:
    """Steps of a recorded run as a replay sees them (`recorded_steps`).

    Attributes
    ----------
    complete : int
        Steps 0 .. complete - 1 hold a message on every topic in `topics`.
    recorded : int
        Steps with a message on any loop topic.
    topics : list of str
        Topics a step needs.
    missing : list of str
        Topics without a message at step `complete` (empty when every step is complete).
    file_truncated : bool
        The file ends before its summary (the recorder was killed).
    """

    complete: int
    recorded: int
    topics: list
    missing: list = field(default_factory=list)
    file_truncated: bool = False

    @property
    def truncated(self) -> bool:
        """Some recorded step is not complete: only `complete` steps can be replayed."""
        return self.complete < self.recorded

    def summary(self, name: str) -> str:
        """One line on what of recording `name` can be replayed."""
        cut = " (the file ends before its summary)" if self.file_truncated else ""
        if not self.truncated:
            return f"{name}: {self.complete} complete steps{cut}"
        return (
            f"{name}: recording truncated at step {self.complete}{cut}: step {self.complete} "
            f"has no {', '.join(self.missing)}; replaying the {self.complete} complete steps "
            f"of {self.recorded} recorded"
        )


def recorded_steps(run: str | Path, topics=None) -> RecordedSteps:
    """Count the complete steps of a recorded run: those with every needed topic.

    A step is the set of loop messages of one log time (as the `replay` node groups
    them), numbered in time order; it is complete when each needed topic has a
    message at that time. The count stops at the first step that is not.

    Parameters
    ----------
    run : path
        Bag folder or .mcap file (a file cut short is read up to its last complete chunk).
    topics : sequence of str, optional
        Topics a step needs (the replayed inputs and the captured outputs); those the
        run does not hold at all are left out (the replay reports them). Default: every
        loop topic the run holds.

    Returns
    -------
    RecordedSteps

    Raises
    ------
    RunError
        If the file is missing or not an MCAP file.
    """
    at: dict[int, set] = {}
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", TruncatedRunWarning)
        for topic, _, log_ns, _ in iter_raw(run, list(TOPICS)):
            at.setdefault(log_ns, set()).add(topic)
    cut = False
    for w in caught:  # the truncation is reported in the result, other warnings pass on
        if issubclass(w.category, TruncatedRunWarning):
            cut = True
        else:
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    return steps_of(at, topics, cut)


def steps_of(at: dict[int, set], topics=None, file_truncated: bool = False) -> RecordedSteps:
    """`RecordedSteps` of a run from the topics recorded at each log time.

    Parameters
    ----------
    at : dict of int -> set of str
        Log time [ns] -> the loop topics with a message at that time (one step each).
    topics : sequence of str, optional
        Topics a step needs; those never recorded are left out. Default: every topic
        recorded.
    file_truncated : bool
        The file ended before its summary.
    """
    recorded = set().union(*at.values()) if at else set()
    needed = [t for t in (topics or TOPICS) if t in recorded]
    steps = sorted(at)
    complete = next((i for i, ns in enumerate(steps) if not at[ns].issuperset(needed)), len(steps))
    missing = [t for t in needed if t not in at[steps[complete]]] if complete < len(steps) else []
    return RecordedSteps(complete, len(steps), needed, missing, file_truncated)


@dataclass
class OutputCheck:
    """Captured outputs of a replay against the recorded ones (`compare_outputs`).

    Attributes
    ----------
    topics : list of str
        Topics compared.
    compared : int
        Recorded messages of those topics (the steps replayed).
    equal : int
        Captured messages whose CDR bytes equal the recorded ones.
    first_difference : str
        The first difference in step order ("" when none): topic, step, and the first
        field that differs with both values, or the message that is missing.
    truncated_at : int or None
        The step at which the recording is truncated (its later steps were neither
        replayed nor compared); None for a complete recording.
    """

    topics: list
    compared: int
    equal: int
    first_difference: str = ""
    truncated_at: int | None = None

    @property
    def identical(self) -> bool:
        """Every recorded output was captured with the same bytes."""
        return self.compared > 0 and self.equal == self.compared

    def summary(self) -> str:
        """One line: `outputs identical: ...` or `outputs differ: ...`."""
        where = ", ".join(self.topics)
        cut = "" if self.truncated_at is None else (
            f" (recording truncated at step {self.truncated_at}: later steps not compared)"
        )  # fmt: skip
        if self.identical:
            return (
                f"outputs identical: {self.equal} of {self.compared} messages on {where} "
                f"equal the recorded ones byte for byte{cut}"
            )
        return (
            f"outputs differ: {self.compared - self.equal} of {self.compared} messages on "
            f"{where} are not the recorded ones; first: {self.first_difference or '-'}{cut}"
        )


def _first_field(topic: str, a: bytes, b: bytes) -> str:
    """The first field in which two messages of a loop topic differ, with both values."""
    try:
        da, db = decode(topic, a), decode(topic, b)
    except Exception:  # noqa: BLE001 - undecodable: report the bytes only
        return f"bytes differ ({len(a)} recorded, {len(b)} replayed)"

    def same(x, y) -> bool:
        if isinstance(x, dict):
            return isinstance(y, dict) and all(same(x[k], y.get(k)) for k in x)
        return bool(np.array_equal(np.asarray(x), np.asarray(y)))

    for k, va in da.items():
        vb = db.get(k)
        if not same(va, vb):
            return f"field '{k}': recorded {va!r}, replayed {vb!r}"
    return "bytes differ (the decoded fields are equal)"


def compare_outputs(recorded: str | Path, replayed: str | Path, topics, steps: int = 0):
    """Compare the captured outputs of a replay with the recorded messages.

    Parameters
    ----------
    recorded : path
        The run that was replayed.
    replayed : path
        The replay's output run.
    topics : sequence of str
        Captured topics.
    steps : int
        Steps replayed (0: all of the recorded run).

    Returns
    -------
    OutputCheck

    Raises
    ------
    RunError
        If a run cannot be read.
    """
    topics = list(topics)
    rec: dict = {t: {} for t in topics}
    rep: dict = {t: {} for t in topics}
    for run, into in ((recorded, rec), (replayed, rep)):
        for topic, _, log_ns, data in iter_raw(run, topics):
            into[topic].setdefault(log_ns, data)
    compared = equal = 0
    first = (math.inf, "")
    for t in topics:
        times = sorted(rec[t])[: steps or None]
        for i, log_ns in enumerate(times):
            compared += 1
            new = rep[t].get(log_ns)
            if new == rec[t][log_ns]:
                equal += 1
                continue
            if log_ns < first[0]:
                what = "not captured" if new is None else _first_field(t, rec[t][log_ns], new)
                first = (log_ns, f"{t} at step {i}: {what}")
    return OutputCheck(topics, compared, equal, first[1])


@dataclass
class ReplayRun:
    """Outcome of one replay (`run_replay`).

    Attributes
    ----------
    out : Path or None
        Run folder written by the replay node (None when not recorded).
    returncode : int
        Exit status of the `sil` runner: 0 when the replay and every node finished.
    wall_s : float
        Wall time of the whole replay, start-up included [s].
    log_dir : Path
        Folder with the parameter file and the node logs.
    interrupted : bool
        Stopped by SIGINT / SIGTERM (the output run, if any, is finalised).
    outputs : OutputCheck or None
        The captured outputs against the recorded ones (None without captured topics
        or when the replay did not finish).
    recorded : RecordedSteps or None
        The complete steps of the replayed run (`recorded_steps`).
    """

    out: Path | None
    returncode: int
    wall_s: float
    log_dir: Path
    interrupted: bool = False
    outputs: OutputCheck | None = field(default=None)
    recorded: RecordedSteps | None = field(default=None)


def _ros_list(values) -> list[str]:
    """A string-array parameter; [""] stands for empty (a YAML [] has no type)."""
    return list(values) or [""]


def _node_parameters(mcap: Path, nodes, params, steps: int) -> dict:
    """Parameter file sections of the nodes under test: the run's, for `steps` steps.

    From `params` (a parameter file) if given, else from the run file.

    Raises
    ------
    RunError
        If the parameter file is unreadable or has no section for a node.
    """
    if not nodes:
        return {}
    if params is not None:
        try:
            recorded = yaml.safe_load(Path(params).read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise RunError(f"parameter file {params}: {exc}") from None
        source = str(params)
    else:
        recorded, source = run_params(mcap), f"{mcap} ({PARAMS})"
        if recorded is None:
            raise RunError(
                f"{mcap} holds no node parameters (a run of an earlier version started "
                "by hand): pass the parameter file it was started with, --params FILE"
            )
    if not isinstance(recorded, dict):
        raise RunError(f"{source} is not a ROS 2 parameter file")
    content = {}
    for n in nodes:
        if n not in recorded:
            raise RunError(f"{source} has no parameters for node '{n}'")
        p = dict(recorded[n]["ros__parameters"])
        if steps:
            p["duration"] = steps * float(p["Ts"])
        content[n] = {"ros__parameters": p}
    return content


def run_replay(
    run: str | Path,
    nodes=(),
    topics=None,
    capture=None,
    out: str | Path | None = None,
    rate: float = 1.0,
    steps: int = 0,
    watchdog_s: float = 10.0,
    quiet: bool = False,
    log=print,
    params: str | Path | None = None,
) -> ReplayRun:
    """Republish a recorded run (`replay` node), optionally into nodes under test.

    Parameters
    ----------
    run : path
        Run folder (or its .mcap file, alone or in a renamed folder).
    nodes : sequence of str
        Nodes to start against the replay (e.g. `["tube_mpc"]`), with the
        parameters the run was made with (the parameter file in the run file).
    topics : sequence of str, optional
        Topics to republish; default: the inputs of `nodes` they do not produce
        (`fahv.loop.replay_topics`), or every loop topic without nodes.
    capture : sequence of str, optional
        Topics to capture (lockstep on them); default: the outputs of `nodes`.
    out : path, optional
        Run folder to write: the captured topics and the recorded messages of every
        other loop topic. With captured topics and no `out`, the run is written to
        the replay's log folder (the comparison needs it).
    rate : float
        1: recorded timing, r: r times faster, 0: as fast as possible.
    steps : int
        Steps to replay (0: all); the nodes under test run that many steps. Never more
        than the complete steps of the run (`recorded_steps`): of a truncated
        recording, the steps before the truncation, which `log` names.
    watchdog_s : float
        Wall-clock watchdog of every node [s].
    quiet : bool
        No progress lines.
    log : callable
        Receives the line naming the log folder, and the one naming the step at which
        a truncated recording ends.
    params : path, optional
        Parameter file of the nodes under test, for a run recorded without one (runs of
        earlier versions started by hand); by default the one in the run file.

    Returns
    -------
    ReplayRun
        `returncode` 0 when the replay (and every node) finished; `outputs` compares
        the captured messages with the recorded ones.

    Raises
    ------
    RunError
        If the run is missing, holds no complete step, a node is unknown, no parameters
        are known for a node under test, or the workspace cannot be built.
    """
    from fahv.loop.graph import replay_topics
    from fahv.runs.bag import bag_paths

    folder, mcap = bag_paths(run)
    if not mcap.is_file():
        raise RunError(f"run file {mcap} does not exist")
    inputs, outputs = replay_topics(nodes)
    if topics is None:
        topics = inputs if nodes else []  # []: the replay node takes every loop topic
    topics, capture = list(topics), list(outputs if capture is None else capture)
    have = recorded_steps(mcap, [*topics, *capture] if topics else None)
    if have.complete == 0:
        raise RunError(f"{mcap} holds no complete step of {have.topics}: nothing to replay")
    capped = have.truncated and not 0 < steps <= have.complete
    if capped:
        log(have.summary(mcap.name))
        steps = have.complete
    content = _node_parameters(mcap, nodes, params, steps)
    meta = {k: v for k, v in stored_metadata(mcap).items() if k not in END_KEYS}
    meta.pop("source", None)
    ensure_built(log=log)
    env = ros_env()
    _, work = reserve_run(time.strftime("%Y%m%d-%H%M%S"), WS / "log" / "replay")
    if out is None and capture:
        out = work / f"{mcap.stem}_replay"
    content["replay"] = {
        "ros__parameters": {
            "run": str(mcap.resolve()),
            "topics": _ros_list(topics),
            "rate": float(rate),
            "capture": _ros_list(capture),
            "out": "" if out is None else str(Path(out).resolve()),
            "wait_for": _ros_list(nodes),
            "steps": int(steps),
            "watchdog_s": float(watchdog_s),
            "metadata_json": json.dumps(meta),
        }
    }
    content["/**"] = {
        "ros__parameters": {
            "use_sim_time": "/clock" in topics or not topics,
            "graph_nodes": ["replay", *nodes],
        }
    }
    (work / "params.yaml").write_text(yaml.safe_dump(content, sort_keys=False, width=120))
    cmd = _runner(work, ["--nodes", "replay", *nodes], quiet)
    log(f"replay of {mcap.name} into {list(nodes) or 'the graph'}: logs in {work}")
    t0 = time.monotonic()
    rc, interrupted = run_runner(cmd, env)
    res = ReplayRun(
        None if out is None else Path(out), rc, time.monotonic() - t0, work, interrupted,
        recorded=have,
    )  # fmt: skip
    if rc == 0 and capture and res.out is not None and res.out.exists():
        res.outputs = compare_outputs(mcap, res.out, capture, steps)
        if capped:
            res.outputs.truncated_at = have.complete
    return res


def output_attachments(run: str | Path) -> dict[str, bytes]:
    """Attachments of a replay's output run: the replayed run's parameter file.

    So the output is a run every tool takes (inspect, compare, replay again); the
    recorded DDS timestamps are not copied, they belong to the original graph.
    """
    return {k: v for k, v in run_attachments(run).items() if k == PARAMS}
