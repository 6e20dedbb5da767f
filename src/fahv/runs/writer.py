"""Writing a run file: the rosbag2 folder with one MCAP file, in the ros2 profile.

`RunWriter` writes the loop topics of one run (the SIL recorder's raw CDR bytes or
the in-process simulator's serialised messages) with their `ros2msg` schemas, the
channels' `offered_qos_profiles`, log time = simulated time, the run metadata as a
metadata record and the bag's `custom_data`, and the parameter files as attachments;
closing finishes the file (summary, statistics, indexes) and the folder's
`metadata.yaml`. Reading is `fahv.runs.bag`.
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

import yaml
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.rosbag2 import StoragePlugin, Writer

from fahv.errors import RunError
from fahv.interrupt import deferred
from fahv.loop.graph import TOPICS
from fahv.runs.bag import PARAMS, RUN_RECORD
from fahv.runs.messages import LOOP_QOS
from fahv.sil.wire import encode, typestore
from fahv.verdict import RunEnded, Verdict, completed
from fahv.version import code_version


class _McapStorage:
    """rosbag2 storage of `RunWriter`: the MCAP file, written with the `mcap` package.

    The storage protocol of `rosbags.rosbag2.Writer` (which keeps the connections,
    message definitions, QoS and `metadata.yaml`) on `mcap.writer.Writer`, so
    the run file can also hold metadata records and attachments. ros2 profile,
    `ros2msg` schemas, `cdr` messages, `offered_qos_profiles` channel metadata,
    uncompressed 1 MiB chunks, summary with statistics and indexes, and the
    `rosbag2` metadata record at the end, as rosbag2's MCAP plugin writes them.
    """

    def __init__(self, path: Path, compression) -> None:
        self.path = path / f"{path.name}.mcap"
        self._file = self.path.open("xb")
        self._mcap = McapWriter(self._file, chunk_size=1 << 20, compression=CompressionType.NONE)
        self._mcap.start(profile="ros2", library=f"fahv {code_version()} (mcap)")
        self._schemas: dict[str, int] = {}
        self._channels: dict[int, int] = {}

    def add_msgtype(self, connection) -> None:
        """Register the schema of a connection's message type (called by rosbags' writer)."""
        fmt = "ros2msg" if connection.msgdef.format.name == "MSG" else "ros2idl"
        self._schemas[connection.msgtype] = self._mcap.register_schema(
            connection.msgtype, fmt, connection.msgdef.data.encode()
        )

    def add_connection(self, connection, offered_qos_profiles: str) -> None:
        """Register a channel with its offered QoS profiles."""
        self._channels[connection.id] = self._mcap.register_channel(
            connection.topic,
            connection.ext.serialization_format,
            self._schemas[connection.msgtype],
            {"offered_qos_profiles": offered_qos_profiles},
        )

    def write(self, connection, timestamp: int, data) -> None:
        """Append one message (log and publish time: `timestamp`)."""
        self._mcap.add_message(self._channels[connection.id], timestamp, bytes(data), timestamp)

    def add_metadata(self, name: str, data: dict) -> None:
        """A metadata record (string map)."""
        self._mcap.add_metadata(name, {str(k): str(v) for k, v in data.items()})

    def add_attachment(self, name: str, data: bytes, media_type: str) -> None:
        """An attachment (log time 0, created now)."""
        self._mcap.add_attachment(time.time_ns(), 0, name, media_type, bytes(data))

    def close(self, version: int, metadata: str) -> None:
        """The `rosbag2` record (bag metadata as YAML), summary and footer."""
        self._mcap.add_metadata("rosbag2", {"serialized_metadata": metadata})
        self._mcap.finish()
        self._file.close()

    def abort(self) -> None:
        """Close without summary (called by rosbags' writer when a write fails)."""
        self._file.close()


class _Bag(Writer):
    """rosbags' rosbag2 writer with `_McapStorage` as its MCAP storage."""

    STORAGE_PLUGINS = {StoragePlugin.MCAP: _McapStorage}


#: Media types of the attachments a run file holds.
MEDIA_TYPES = {".yaml": "application/yaml", ".json": "application/json",
               ".npz": "application/octet-stream"}  # fmt: skip


def _media_type(name: str) -> str:
    return MEDIA_TYPES.get(Path(name).suffix, "application/octet-stream")


def free_run_folder(path: str | Path) -> Path:
    """`path`, or the first of `<path>-2`, `<path>-3` ... that does not exist.

    The name a run started again with the same parameter file records to (the recorder
    started by hand), as `fahv.sil.runner.reserve_run` names two runs started in the
    same second.

    Raises
    ------
    RunError
        If none of `<path>-2` ... `<path>-9999` is free.
    """
    path = Path(path)
    for i in range(1, 10_000):
        cand = path if i == 1 else path.with_name(f"{path.name}-{i}")
        if not cand.exists():
            return cand
    raise RunError(f"no free run folder {path}-N")


class RunWriter:
    """Writer of one run: a rosbag2 bag with one MCAP file that holds everything of the run.

    The file holds every loop topic, the run metadata (the bag's `custom_data` and
    an MCAP metadata record `RUN_RECORD`, written when the run starts, so a file
    cut short still has it, and again when it closes) and the run's attachments: the
    parameter file of every node (`PARAMS`), and what the writer adds at the end
    (the recorder: `timestamps.npz`). The folder can be renamed or copied, or the
    `.mcap` used alone: nothing else is needed.

    Parameters
    ----------
    path : str or Path
        Bag folder to create (must not exist); the file is `<path>/<name>.mcap`.
    metadata : dict[str, str]
        Run metadata (case, design_hash, code_version, variant, source, fault ...);
        values are converted to str.
    Ts : float
        Control period [s]: message log time is k Ts in nanoseconds.
    params : dict, str, Path or None
        The run's ROS 2 parameter file: its content (`{node: {"ros__parameters":
        ...}}`) or the path of the file (the recorder gets it as a parameter).
    attachments : dict[str, bytes], optional
        Further attachments by name.

    Raises
    ------
    RunError
        If the folder exists or cannot be created, or the parameter file is unreadable.

    Notes
    -----
    Use as a context manager or call `close`; `close(status=...)` records
    how the run ended in the metadata (complete, ended: <verdict>, interrupted,
    failed: ...), and `set_verdict` its verdict (`fahv.verdict`; the
    context manager records a `fahv.verdict.RunEnded` that leaves it).
    """

    def __init__(
        self,
        path: str | Path,
        metadata: dict,
        Ts: float,
        params: dict | str | Path | None = None,
        attachments: dict | None = None,
    ) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise RunError(f"run folder {self.path} exists already")
        atts = dict(attachments or {})
        if isinstance(params, dict):
            atts[PARAMS] = yaml.safe_dump(params, sort_keys=False, width=120).encode()
        elif params is not None:
            try:
                atts[PARAMS] = Path(params).read_bytes()
            except OSError as exc:
                raise RunError(f"parameter file of the run {params}: {exc}") from None
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.Ts_ns = int(round(Ts * 1e9))
        try:
            with deferred():  # a stop while the file is set up is raised once it is whole
                self._open(metadata, atts)
        except KeyboardInterrupt:  # the caller never gets the writer: close it here
            self.close("interrupted")
            raise

    def _open(self, metadata: dict, atts: dict) -> None:
        self._ts = typestore()
        self._writer = _Bag(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self.metadata = {k: str(v) for k, v in metadata.items()}
        for key, value in self.metadata.items():
            self._writer.set_custom_data(key, value)
        try:
            self._writer.open()
        except OSError as exc:
            raise RunError(f"cannot create run {self.path}: {exc}") from None
        self._conns = {
            topic: self._writer.add_connection(
                topic, msgtype, typestore=self._ts, offered_qos_profiles=[LOOP_QOS]
            )
            for topic, msgtype in TOPICS.items()
        }
        storage = self._writer.storage
        storage.add_metadata(RUN_RECORD, {**self.metadata, "status": "running"})
        for name, data in atts.items():
            storage.add_attachment(name, data, _media_type(name))
        self.counts = dict.fromkeys(TOPICS, 0)
        self._closed = False
        self._write_sidecar(status="running")

    def _write_sidecar(self, **extra) -> None:
        """run.json: the metadata beside the file, for tools that look before it closes."""
        tmp = self.path / ".run.json.tmp"
        tmp.write_text(json.dumps({**self.metadata, **extra}, indent=1))
        os.replace(tmp, self.path / "run.json")

    def log_time(self, k: int) -> int:
        """Log time [ns] of step k: k Ts."""
        return k * self.Ts_ns

    def write_raw(self, topic: str, k: int, data: bytes) -> None:
        """Append serialised CDR bytes of step k on a loop topic.

        A stop (`fahv.interrupt`) during the write is raised after it, so the
        file never holds half a record.
        """
        with deferred():
            self._writer.write(self._conns[topic], self.log_time(k), bytes(data))
            self.counts[topic] += 1

    def write(self, topic: str, k: int, fields: dict) -> None:
        """Serialise a message dict (`fahv.loop.cores` field names) and append it."""
        self.write_raw(topic, k, encode(topic, fields))

    def set_metadata(self, key: str, value) -> None:
        """Add or replace one metadata entry before the run is closed."""
        self.metadata[key] = str(value)
        self._writer.set_custom_data(key, str(value))

    def set_verdict(self, verdict: Verdict) -> None:
        """Record how the run ended, before the run is closed.

        The metadata `verdict`, `verdict_node` ... of
        `fahv.verdict.Verdict.metadata`.

        Parameters
        ----------
        verdict : fahv.verdict.Verdict
        """
        for key, value in verdict.metadata().items():
            self.set_metadata(key, value)

    def close(self, status: str = "complete", attachments: dict | None = None) -> None:
        """Finish the file (attachments, final metadata, summary, indexes, metadata.yaml).

        Parameters
        ----------
        status : str
            How the run ended (metadata `status`). A `complete` run without a
            verdict gets `completed` (`set_verdict`).
        attachments : dict[str, bytes], optional
            Attachments known only at the end (the recorder's timestamps).

        Notes
        -----
        Idempotent: a second call does nothing.
        """
        if self._closed:
            return
        with deferred():  # a stop while closing: raised once the file is complete
            self._close(status, attachments)

    def _close(self, status: str, attachments: dict | None) -> None:
        self._closed = True
        steps = min(self.counts.values())
        if status == "complete" and "verdict" not in self.metadata:
            self.set_verdict(completed(steps, self.Ts_ns * 1e-9))
        self.set_metadata("status", status)
        self.set_metadata("steps_recorded", steps)
        storage = self._writer.storage
        for name, data in (attachments or {}).items():
            storage.add_attachment(name, data, _media_type(name))
        storage.add_metadata(RUN_RECORD, self.metadata)
        self._writer.close()
        self._write_sidecar()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        if exc_type is None:
            self.close("complete")
        elif issubclass(exc_type, KeyboardInterrupt):  # Ctrl-C or SIGTERM (fahv.cli)
            self.close("interrupted")
        elif isinstance(exc, RunEnded):  # the run ended early with its verdict
            self.set_verdict(exc.verdict)
            self.close(exc.verdict.status)
        else:
            self.close(f"failed: {exc_type.__name__}: {exc}")
