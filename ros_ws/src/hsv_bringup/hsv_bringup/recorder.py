"""`recorder` node: every loop topic, raw (no deserialisation), into one rosbag2/MCAP run.

Raw subscriptions hand over the CDR bytes as received; the recorder reads only the
step index k at the head of each message (or the /clock stamp) to set the log time to
simulated time t_k = k Ts, and writes through `fahv.runs.writer.RunWriter` (ros2
profile, full message definitions, offered QoS, summary with statistics and indexes,
run metadata, the ROS domain of the graph as `ros_domain_id`). With every message it
keeps the DDS source timestamp (wall clock when the producing node published it) and
its own receive time, attached to the run file when it closes (`timestamps.npz`,
`fahv.runs.latency.timestamps_npz`): the per-hop latency breakdown of
`fahv inspect` comes from them. The parameter file the graph was started with
(`params_file`) is attached when the run starts, so the run file alone can be
replayed and rerun. It stops by itself once every topic holds `duration / Ts`
steps, or once a peer ended the run with a verdict (`fahv.verdict`) and the steps
before it are recorded (the file then holds the verdict); on SIGINT/SIGTERM, a lost
graph (watchdog) or an error it still closes the file, with the reason in the run
metadata (`status`).

With `live_port` >= 0 it also serves every message it records, the same CDR bytes,
on a Foxglove WebSocket server (`fahv.runs.live.LiveView`): the live view costs
the loop no extra DDS reader. Messages of a step already recorded on a topic (another
graph's, later in the same domain) are counted as anomalies and not recorded.

Parameters: `bag` (folder to create; if it exists, a recorder started again with the
same parameter file records to the first free `<bag>-2`, `<bag>-3` ...,
`fahv.runs.writer.free_run_folder`), `Ts`, `duration`, `watchdog_s`,
`metadata_json` (JSON object of run metadata: case, design_hash, variant, ...),
`params_file` (the run's parameter file, attached to the run); `live_port`;
`graph_nodes` and `run_id` like every node of the graph.
"""

from __future__ import annotations

import sys
import time
from array import array
from pathlib import Path

from hsv_common.graph_status import GraphStatus
from hsv_common.parameters import declare_graph, declare_validated, run_metadata_param
from hsv_common.runtime import LOOP_QOS, WatchdogError, end_reason, main, node_options
from hsv_common.topics import msg_type_of
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node

from fahv.errors import ParameterError, RunError
from fahv.loop.graph import TOPICS
from fahv.runs.latency import TIMESTAMPS_FILE, timestamps_npz
from fahv.runs.live import LiveView, live_hint
from fahv.runs.writer import RunWriter, free_run_folder
from fahv.sil.tool_nodes import RECORDER
from fahv.sil.wire import step_of

#: Pause of the recorder after a spin that recorded messages [s wall time]: the
#: messages that arrive meanwhile are taken together at the next wake-up. Its lag stays
#: a few steps (QOS_DEPTH steps are kept for it), and it gives the loop nodes the CPU
#: (10 ms rather than 2 ms: a fifth less recorder CPU over a 60 s run, measured).
DRAIN_PAUSE_S = 0.01
#: Longest wait of the recorder, once a peer ended the run with a verdict, for the
#: messages of the steps before it still on their way [s wall time without a message].
VERDICT_DRAIN_S = 2.0


class Recorder(Node):
    """Raw recorder of the loop topics."""

    ROLE = "recorder"
    #: Subscription callbacks get the message info (DDS timestamps), see make_executor.
    MESSAGE_INFO = True

    def __init__(self) -> None:
        super().__init__("recorder", **node_options())
        graph_nodes, run_id = declare_graph(self)
        get = declare_validated(self, RECORDER)
        meta = run_metadata_param("recorder", get["metadata_json"])
        meta.setdefault("source", "sil")
        meta["ros_domain_id"] = self.context.get_domain_id()
        self.Ts_ns = int(round(get["Ts"] * 1e9))
        self.n_steps = int(round(get["duration"] / get["Ts"]))
        self.watchdog_s = get["watchdog_s"]
        self.status = GraphStatus(self, graph_nodes, run_id, self.watchdog_s)
        self.live = None
        bag = free_run_folder(get["bag"])  # started again: <bag>-2, -3 ...
        if bag != Path(get["bag"]):
            self.get_logger().info(f"run folder {get['bag']} exists already: recording to {bag}")
        if get["live_port"] >= 0:  # served from here: no extra DDS reader on the loop
            try:
                name = f"fahv {bag.name}"
                self.live = LiveView(get["live_port"], get["Ts"], name=name)
            except RunError as exc:
                raise ParameterError(f"recorder: parameter 'live_port': {exc}") from None
            print(f"live view on {self.live.url} ({live_hint()})", flush=True)
        try:
            self.writer = RunWriter(bag, meta, get["Ts"], params=get["params_file"] or None)
        except RunError as exc:
            raise ParameterError(f"recorder: parameter 'bag' or 'params_file': {exc}") from None
        self.next_k = dict.fromkeys(TOPICS, 0)
        self.anomalies = dict.fromkeys(TOPICS, 0)
        # per topic: k, DDS source timestamp [ns], receive time [ns] of every message
        self.stamps = {t: array("q") for t in TOPICS}
        self.subs = {
            t: self.create_subscription(
                msg_type_of(t),
                t,
                lambda data, info, t=t: self._on_message(t, data, info),
                LOOP_QOS,
                raw=True,
                # no QoS-event handlers: rclpy adds two per subscription by default
                # (incompatible QoS / type warnings), and the SingleThreadedExecutor
                # this node needs polls them at every spin (recorder CPU -18 %, graph
                # real-time factor +5 %, measured); the loop nodes still warn
                event_callbacks=SubscriptionEventCallbacks(use_default_callbacks=False),
            )
            for t in TOPICS
        }
        self.status.attach(self.subs, {})
        self.status.waiting = []
        self.done = False
        self.verdict = None  # the verdict a peer ended the run with (fahv.verdict)
        self.k = 0
        self.dropped = 0
        self.last_msg = time.monotonic()
        self.started = False
        self.t0 = time.monotonic()

    def _on_message(self, topic: str, data: bytes, info: dict) -> None:
        """Subscription callback: record the message, then every one queued on any topic.

        The executor rebuilds its wait set for each ready entity it hands out, which
        costs far more than a take: draining every topic's queue here (and pausing
        `DRAIN_PAUSE_S` between spins, `poll`) records the messages of one
        or more whole steps per wake-up (the loop's writers keep up to QOS_DEPTH steps
        for a lagging reader). Each topic is taken in order, so its steps stay in order.
        """
        self._record(topic, data, info)
        for t, sub in self.subs.items():
            with sub.handle:
                while not self.done:
                    got = sub.handle.take_message(sub.msg_type, sub.raw)
                    if got is None:
                        break
                    self._record(t, *got)

    def _record(self, topic: str, data: bytes, info: dict) -> None:
        k = step_of(topic, data, self.Ts_ns)
        if k < self.next_k[topic]:  # a step already recorded: another sender (a later graph)
            self.anomalies[topic] += 1
            self.dropped += 1
            if self.dropped == 1 or self.dropped % 1000 == 0:
                self.get_logger().warning(
                    f"{topic}: step {k} received after step {self.next_k[topic] - 1}: not "
                    f"recorded ({self.dropped} so far)"
                )
            return
        self.stamps[topic].extend((k, info["source_timestamp"], info["received_timestamp"]))
        if k != self.next_k[topic]:
            self.anomalies[topic] += 1
            self.get_logger().warning(
                f"{topic}: step {k} received, step {self.next_k[topic]} expected"
            )
        self.next_k[topic] = k + 1
        self.writer.write_raw(topic, k, data)
        if self.live is not None:
            self.live.log(topic, k, data)
        self.last_msg = time.monotonic()
        if not self.started:
            self.started = True
            self.status.set_state("running")
        done = min(self.writer.counts.values())
        if done > self.k:
            self.k = self.status.k = done
            if self.k % 500 == 0:
                print(f"progress {self.k} {self.n_steps}", flush=True)
        if self.n_steps and done >= self.n_steps:
            self.done = True
            self.status.set_state("done", self.k)  # the loop nodes need not wait any more

    def poll(self) -> None:
        """Readiness, failed or missing peers, foreign graphs, the watchdog.

        Raises
        ------
        WatchdogError
            If the graph does not start, a peer failed, or no message came for
            `watchdog_s` (naming the missing peers).
        ForeignGraphError
            If another graph that joined first runs in the domain.
        """
        if not self.status.ready:
            if self.status.poll_ready():
                self.t_ready = time.monotonic()
                self.get_logger().info(f"recording {len(self.subs)} topics to {self.writer.path}")
            return
        if self._ending():
            return
        self.status.check_failed_peer()
        self.status.check_foreign(force=False)
        if not self.started:  # the graph's step 0 is still to come
            stalled = self.status.stalled(self.t_ready)
            if stalled is not None:
                raise WatchdogError(
                    f"recorder: {stalled}; no message of step 0"
                    if stalled
                    else "recorder: no message of step 0 (every peer ready)"
                )
            return
        idle = time.monotonic() - self.last_msg
        if not self.done and idle < DRAIN_PAUSE_S:  # recording: let messages queue up
            time.sleep(DRAIN_PAUSE_S)
        if idle > self.watchdog_s:
            behind = min(self.writer.counts, key=self.writer.counts.get)
            missing = self.status.missing_text()
            if missing:  # the missing peer first, as every node says it
                raise WatchdogError(
                    f"recorder: missing {missing}; no message for {self.watchdog_s:g} s at "
                    f"step {self.k}"
                )
            raise WatchdogError(
                f"recorder: no message for {self.watchdog_s:g} s at step {self.k} ({behind} "
                "is behind; every peer alive)"
            )

    def _ending(self) -> bool:
        """True once a peer ended the run with a verdict (then the recorder drains).

        The messages of the steps before the verdict's are recorded (or none came for
        `VERDICT_DRAIN_S`), then the recorder is done and closes the file with
        the verdict.
        """
        if self.verdict is None:
            self.verdict = self.status.peers.run_verdict()
            if self.verdict is None:
                return False
            self.get_logger().warning(f"run ended: {self.verdict.text()}")
        idle = time.monotonic() - self.last_msg
        if min(self.writer.counts.values()) >= self.verdict.step or idle > VERDICT_DRAIN_S:
            self.done = True
        return True

    def close(self, status: int, reason: str = "") -> None:
        """Finish the file with the run status (or verdict), the reason and the anomaly counts."""
        if status != 0 and not self.done:  # a peer's own reason is the better one
            failed = self.status.peers.failed()
            if failed and not reason.startswith("recorder: peer"):
                reason = f"{reason}; {failed[0]}" if reason else failed[0]
        self.status.close(status, reason)
        for t, n in self.anomalies.items():
            self.writer.set_metadata(f"anomalies{t.replace('/', '.')}", n)
        self.writer.set_metadata("wall_time_s", f"{time.monotonic() - self.t0:.3f}")
        if reason:
            self.writer.set_metadata("reason", reason)
        status_text = end_reason(self.done, status)
        if self.verdict is not None:
            self.writer.set_verdict(self.verdict)
            status_text = self.verdict.status
        self.writer.close(status_text, {TIMESTAMPS_FILE: timestamps_npz(self.stamps)})
        if self.live is not None:
            self.live.close()
        print(f"closed {self.writer.path} ({status_text}, {self.k} steps)", flush=True)


def run(args=None) -> None:
    """Entry point `ros2 run hsv_bringup recorder`."""
    sys.exit(main(Recorder, args, linger_s=0.0))
