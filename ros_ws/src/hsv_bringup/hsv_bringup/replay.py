"""`replay` node: republish recorded loop topics (raw CDR) from a run file.

Reads a run (rosbag2 folder or .mcap; a truncated file up to its last complete
chunk) and publishes the selected topics step by step, exactly the bytes that were
recorded, with the loop QoS. Timing: `rate` 1.0 follows the recorded simulated
time in wall time, r > 0 is r times faster, 0 is as fast as possible.

Regression use: with `capture` topics (the outputs of the node(s) under test),
the replay runs in lockstep: step k + 1 is published only after every captured topic
that has a publisher delivered step k, so nothing is dropped however slow the node
is. With `out` the captured messages and the recorded ones of every other loop
topic are written to a new run (same format as the recorder's, with the replayed
run's parameter file), a complete run to compare with the original.

Parameters: `run` (file to replay), `topics` (default every loop topic of the
run), `rate`, `capture`, `out`, `wait_for` (nodes that must say they are
ready on /hsv/node_status before step 0), `steps` (0: all), `watchdog_s`.
"""

from __future__ import annotations

import sys
import time
import warnings
from pathlib import Path

from hsv_common.graph_status import GraphStatus
from hsv_common.parameters import declare_graph, declare_validated, run_metadata_param
from hsv_common.runtime import LOOP_QOS, WatchdogError, end_reason, main, node_options
from hsv_common.topics import msg_type_of
from rclpy.node import Node

from fahv.errors import ParameterError, RunError
from fahv.loop.graph import TOPICS
from fahv.runs.bag import TruncatedRunWarning, iter_raw
from fahv.runs.replay import output_attachments, steps_of
from fahv.runs.writer import RunWriter
from fahv.sil.tool_nodes import REPLAY
from fahv.sil.wire import step_of


def load_steps(
    run: str, topics: list[str] | None, steps: int, capture: list[str] = ()
) -> tuple[list, float, list]:
    """Recorded messages grouped by step, complete steps only.

    Parameters
    ----------
    run : str
        Bag folder or .mcap file.
    topics : list of str or None
        Topics to load; None: every loop topic present in the run.
    steps : int
        Number of steps to keep (0: every complete step).
    capture : list of str
        Topics captured from the nodes under test (a step needs their recorded
        messages too, to compare with).

    Returns
    -------
    ([(log_ns, [(topic, data), ...]), ...], Ts [s], topics selected)
        The steps hold every loop topic of the run (the output run copies the ones
        that are neither published nor captured). A recording cut short keeps its
        complete steps (`fahv.runs.replay.steps_of`), and says so.

    Raises
    ------
    ParameterError
        If the run cannot be read, lacks a selected topic or holds fewer than 2 steps.
    """
    cut = False
    try:
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            groups: dict[int, list] = {}
            for topic, _, log_ns, data in iter_raw(run, list(TOPICS)):
                groups.setdefault(log_ns, []).append((topic, data))
        for w in caught:
            cut = cut or issubclass(w.category, TruncatedRunWarning)
            print(f"[replay] warning: {w.message}", file=sys.stderr)
    except RunError as exc:
        raise ParameterError(f"replay: parameter 'run': {exc}") from None
    at = {ns: {t for t, _ in msgs} for ns, msgs in groups.items()}
    seen = set().union(*at.values()) if at else set()
    topics = topics or [t for t in TOPICS if t in seen]
    missing = [t for t in topics if t not in seen]
    if missing:
        raise ParameterError(f"replay: parameter 'topics': {missing} not in the run {run}")
    have = steps_of(at, [*topics, *capture], cut)
    if have.truncated:
        print(f"[replay] {have.summary(run)}", file=sys.stderr)
    times = sorted(groups)
    if len(times) < 2:
        raise ParameterError(f"replay: parameter 'run': {run} holds fewer than 2 steps")
    Ts = min(b - a for a, b in zip(times, times[1:], strict=False)) * 1e-9  # a step may be missing
    times = times[: have.complete]
    if steps:
        times = times[:steps]
    return [(t, groups[t]) for t in times], Ts, topics


class Replay(Node):
    """Publisher of a recorded run, optionally in lockstep with captured topics."""

    ROLE = "replay"

    def __init__(self) -> None:
        super().__init__("replay", **node_options())
        graph_nodes, run_id = declare_graph(self)
        get = declare_validated(self, REPLAY)
        self.steps, Ts, self.topics = load_steps(
            get["run"], get["topics"] or None, get["steps"], list(get["capture"])
        )
        self.Ts_ns = int(round(Ts * 1e9))
        self.rate = float(get["rate"])
        self.watchdog_s = float(get["watchdog_s"])
        self.wait_for = set(get["wait_for"])
        self.pubs = {t: self.create_publisher(msg_type_of(t), t, LOOP_QOS) for t in self.topics}
        self.capture = [t for t in get["capture"] if t not in self.topics]
        self.got = dict.fromkeys(self.capture, -1)
        self.subs = {
            t: self.create_subscription(
                msg_type_of(t), t, lambda data, t=t: self._capture(t, data), LOOP_QOS, raw=True
            )
            for t in self.capture
        }
        self.status = GraphStatus(self, graph_nodes, run_id, self.watchdog_s, self.wait_for)
        self.status.attach(self.subs, self.pubs if self.wait_for else {})
        self.status.waiting = []
        self.writer = None
        if get["out"]:
            meta = run_metadata_param("replay", get["metadata_json"])
            meta.update(
                source="replay",
                replayed_from=str(Path(get["run"]).resolve()),
                replayed_topics=",".join(self.topics),
                captured_topics=",".join(self.capture),
            )
            try:
                self.writer = RunWriter(
                    get["out"], meta, Ts, attachments=output_attachments(get["run"])
                )
            except RunError as exc:
                raise ParameterError(f"replay: parameter 'out': {exc}") from None
        self.lockstep: list[str] = []
        self.started = False
        self.done = False
        self.k = 0  # next step to publish
        self.t0 = 0.0
        self.last_progress = time.monotonic()

    def _capture(self, topic: str, data: bytes) -> None:
        k = step_of(topic, data, self.Ts_ns)
        self.got[topic] = max(self.got[topic], k)
        if self.writer is not None:
            self.writer.write_raw(topic, k, data)
        self.last_progress = time.monotonic()

    def poll(self) -> None:
        """Start when the peers are ready; publish what the lockstep and timing allow."""
        if not self.started:
            if not self.status.poll_ready():
                return
            self.lockstep = [t for t, s in self.subs.items() if s.get_publisher_count() >= 1]
            self.get_logger().info(
                f"replaying {len(self.steps)} steps of {self.topics}; lockstep on {self.lockstep}"
            )
            self.started = True
            self.t0 = time.monotonic()
            self.last_progress = self.t0
        log0 = self.steps[0][0]
        for _ in range(200):  # then let the executor deliver callbacks
            if self.k >= len(self.steps):
                break
            if self.lockstep and min(self.got[t] for t in self.lockstep) < self.k - 1:
                break
            log_ns, msgs = self.steps[self.k]
            if self.rate > 0 and time.monotonic() < self.t0 + (log_ns - log0) * 1e-9 / self.rate:
                break
            for topic, data in msgs:
                if topic in self.pubs:
                    self.pubs[topic].publish(data)
                if self.writer is not None and topic not in self.got:
                    self.writer.write_raw(topic, step_of(topic, data, self.Ts_ns), data)
            self.k += 1
            self.last_progress = time.monotonic()
            if self.k % 500 == 0:
                print(f"progress {self.k} {len(self.steps)}", flush=True)
        last = len(self.steps) - 1
        if self.k >= len(self.steps) and all(self.got[t] >= last for t in self.lockstep):
            self.done = True
            return
        if time.monotonic() - self.last_progress > self.watchdog_s:
            behind = [t for t in self.lockstep if self.got[t] < self.k - 1]
            raise WatchdogError(
                f"replay: no {behind} for step {self.k - 1} within {self.watchdog_s:g} s "
                "(node under test dead or silent)"
            )

    def close(self, status: int, reason: str = "") -> None:
        """Finish the output run with its status."""
        self.status.close(status, reason)
        if self.writer is None:
            return
        reason = end_reason(self.done, status)
        self.writer.close(reason)
        print(f"closed {self.writer.path} ({reason}, {self.k} steps replayed)", flush=True)


def run(args=None) -> None:
    """Entry point `ros2 run hsv_bringup replay`."""
    sys.exit(main(Replay, args, linger_s=0.5))
