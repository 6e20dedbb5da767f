"""``recorder`` node: every loop topic, raw (no deserialisation), into one rosbag2/MCAP run.

Raw subscriptions hand over the CDR bytes as received; the recorder reads only the
step index k at the head of each message (or the /clock stamp) to set the log time to
simulated time t_k = k Ts, and writes through :class:`fahv.runs.bag.RunWriter` (ros2
profile, full message definitions, offered QoS, summary with statistics and indexes,
run metadata, the ROS domain of the graph as ``ros_domain_id``). With every message it
keeps the DDS source timestamp (wall clock when the producing node published it) and
its own receive time, attached to the run file when it closes (``timestamps.npz``,
:func:`fahv.runs.latency.timestamps_npz`): the per-hop latency breakdown of
``fahv inspect`` comes from them. The parameter file the graph was started with
(``params_file``) is attached when the run starts, so the run file alone can be
replayed and rerun. It stops by itself once every topic holds ``duration / Ts``
steps; on SIGINT/SIGTERM, a lost graph (watchdog) or an error it still closes the
file, with the reason in the run metadata (``status``).

Parameters: ``bag`` (folder to create), ``Ts``, ``duration``, ``watchdog_s``,
``metadata_json`` (JSON object of run metadata: case, design_hash, variant, ...),
``params_file`` (the run's parameter file, attached to the run).
"""

from __future__ import annotations

import struct
import sys
import time
from array import array

from hsv_common.lockstep import (
    LOOP_QOS,
    READY_QOS,
    WatchdogError,
    declare_validated,
    end_reason,
    main,
    msg_type_of,
    run_metadata_param,
)
from rclpy.node import Node
from std_msgs.msg import String

from fahv.errors import ParameterError, RunError
from fahv.loop.graph import TOPICS
from fahv.runs.bag import RunWriter
from fahv.runs.latency import TIMESTAMPS_FILE, timestamps_npz
from fahv.runs.nodes import RECORDER


def step_of(topic: str, data: bytes, Ts_ns: int) -> int:
    """Step index k of a serialised loop message (little- or big-endian CDR).

    Every hsv_interfaces message starts with ``int64 k``; /clock carries t_k.
    """
    endian = "<" if data[1] == 1 else ">"
    if topic == "/clock":
        sec, nsec = struct.unpack_from(f"{endian}iI", data, 4)
        return int(round((sec * 1_000_000_000 + nsec) / Ts_ns))
    return struct.unpack_from(f"{endian}q", data, 4)[0]


class Recorder(Node):
    """Raw recorder of the loop topics."""

    ROLE = "recorder"
    #: Subscription callbacks get the message info (DDS timestamps), see make_executor.
    MESSAGE_INFO = True

    def __init__(self) -> None:
        super().__init__("recorder")
        get = declare_validated(self, RECORDER)
        meta = run_metadata_param("recorder", get["metadata_json"])
        meta.setdefault("source", "sil")
        meta["ros_domain_id"] = self.context.get_domain_id()
        self.Ts_ns = int(round(get["Ts"] * 1e9))
        self.n_steps = int(round(get["duration"] / get["Ts"]))
        self.watchdog_s = get["watchdog_s"]
        try:
            self.writer = RunWriter(get["bag"], meta, get["Ts"], params=get["params_file"] or None)
        except RunError as exc:
            raise ParameterError(f"recorder: parameter 'bag' or 'params_file': {exc}") from None
        self.next_k = dict.fromkeys(TOPICS, 0)
        self.anomalies = dict.fromkeys(TOPICS, 0)
        # per topic: k, DDS source timestamp [ns], receive time [ns] of every message
        self.stamps = {t: array("q") for t in TOPICS}
        self.subs = [
            self.create_subscription(
                msg_type_of(t),
                t,
                lambda data, info, t=t: self._record(t, data, info),
                LOOP_QOS,
                raw=True,
            )
            for t in TOPICS
        ]
        self.ready_pub = self.create_publisher(String, "/hsv/ready", READY_QOS)
        self.ready = False
        self.done = False
        self.k = 0
        self.last_msg = time.monotonic()
        self.started = False
        self.t0 = time.monotonic()

    def _record(self, topic: str, data: bytes, info: dict) -> None:
        k = step_of(topic, data, self.Ts_ns)
        self.stamps[topic].extend((k, info["source_timestamp"], info["received_timestamp"]))
        if k != self.next_k[topic]:
            self.anomalies[topic] += 1
            self.get_logger().warning(
                f"{topic}: step {k} received, step {self.next_k[topic]} expected"
            )
        self.next_k[topic] = max(self.next_k[topic], k + 1)
        self.writer.write_raw(topic, k, data)
        self.last_msg = time.monotonic()
        self.started = True
        done = min(self.writer.counts.values())
        if done > self.k:
            self.k = done
            if self.k % 500 == 0:
                print(f"progress {self.k} {self.n_steps}", flush=True)
        if self.n_steps and done >= self.n_steps:
            self.done = True

    def poll(self) -> None:
        """Readiness and the watchdog of a silent graph."""
        if not self.ready:
            if all(s.get_publisher_count() >= 1 for s in self.subs):
                self.ready = True
                self.ready_pub.publish(String(data="recorder"))
                self.get_logger().info(f"recording {len(self.subs)} topics to {self.writer.path}")
            return
        idle = time.monotonic() - (self.last_msg if self.started else self.t0)
        limit = self.watchdog_s if self.started else max(60.0, self.watchdog_s)
        if idle > limit:
            behind = min(self.writer.counts, key=self.writer.counts.get)
            raise WatchdogError(
                f"recorder: no message for {limit:g} s at step {self.k} ({behind} is behind)"
            )

    def close(self, status: int) -> None:
        """Finish the file with the run status and the anomaly counts."""
        for t, n in self.anomalies.items():
            self.writer.set_metadata(f"anomalies{t.replace('/', '.')}", n)
        self.writer.set_metadata("wall_time_s", f"{time.monotonic() - self.t0:.3f}")
        reason = end_reason(self.done, status)
        self.writer.close(reason, {TIMESTAMPS_FILE: timestamps_npz(self.stamps)})
        print(f"closed {self.writer.path} ({reason}, {self.k} steps)", flush=True)


def run(args=None) -> None:
    """Entry point ``ros2 run hsv_bringup recorder``."""
    sys.exit(main(Recorder, args, linger_s=0.0))
