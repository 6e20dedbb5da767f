"""Recorded runs: the loop topics, their message types, and rosbag2/MCAP files.

A run is a rosbag2 bag (as ``ros2 bag record -s mcap`` writes it): a folder
``bags/<run>/`` holding one ``<run>.mcap`` (ros2 profile: ``ros2msg`` schemas with the
full definition, ``cdr`` messages, ``offered_qos_profiles`` channel metadata,
summary with statistics and indexes, a ``rosbag2`` metadata record) and
``metadata.yaml``. Log time is simulated time. Files are written with the
``rosbags`` library's rosbag2 writer, so rosbag2 (``ros2 bag info``), Foxglove and
``rosbags`` open them; the run metadata (case, design hash, code version, variant,
fault, source) is in the bag's ``custom_data``.

The SIL recorder writes the raw CDR bytes it receives; the in-process simulator
serialises the same dicts (:mod:`fahv.loop`) with the same definitions
(``src/fahv/msg/*.msg``, also the sources of the ``hsv_interfaces`` package).
"""

from __future__ import annotations

import functools
import json
import math
import os
import subprocess
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import yaml
from mcap.exceptions import McapError
from mcap.records import Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

import fahv
from fahv.errors import RunError

MSG_DIR = Path(__file__).parent / "msg"
PKG = "hsv_interfaces"

#: Loop topics -> ROS 2 message type, in the order of one control step.
TOPICS = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/hsv/state": f"{PKG}/msg/VehicleState",
    "/hsv/q_filtered": f"{PKG}/msg/FilteredPitchRate",
    "/hsv/nominal": f"{PKG}/msg/NominalTrajectory",
    "/hsv/control_command": f"{PKG}/msg/ControlCommand",
    "/hsv/tube_status": f"{PKG}/msg/TubeStatus",
    "/hsv/actuator_command": f"{PKG}/msg/ControlCommand",
    "/hsv/fault_status": f"{PKG}/msg/FaultStatus",
}

#: QoS of every loop topic: reliable, keep-last, volatile (ARCHITECTURE.md).
QOS_DEPTH = 50
_INF = QosTime(2147483647, 4294967295)
LOOP_QOS = Qos(
    QosHistory.KEEP_LAST,
    QOS_DEPTH,
    QosReliability.RELIABLE,
    QosDurability.VOLATILE,
    _INF,
    _INF,
    QosLiveliness.AUTOMATIC,
    _INF,
    False,
)


@functools.cache
def typestore():
    """Typestore (rosbags) of ROS 2 Jazzy plus the ``hsv_interfaces`` messages.

    Raises
    ------
    RunError
        If a message definition file is missing.
    """
    ts = get_typestore(Stores.ROS2_JAZZY)
    types = {}
    for name in sorted({t for t in TOPICS.values() if t.startswith(PKG)}):
        path = MSG_DIR / f"{name.rsplit('/', 1)[1]}.msg"
        try:
            types.update(get_types_from_msg(path.read_text(), name))
        except OSError as exc:
            raise RunError(f"message definition {path} is unreadable: {exc}") from None
    ts.register(types)
    return ts


def code_version() -> str:
    """``fahv <version>`` plus the git commit (``+dirty`` when modified), if in a repository."""
    v = f"fahv {fahv.__version__}"
    try:
        here = Path(__file__).resolve().parent
        rev = subprocess.run(
            ["git", "describe", "--always", "--dirty"],
            cwd=here,
            capture_output=True,
            text=True,
            timeout=5,
            check=True,
        ).stdout.strip()
        return f"{v} ({rev})" if rev else v
    except (OSError, subprocess.SubprocessError):
        return v


def bag_paths(run: str | Path) -> tuple[Path, Path]:
    """(bag folder, .mcap file) of a run given either of them."""
    p = Path(run)
    if p.suffix == ".mcap":
        return p.parent, p
    return p, p / f"{p.name}.mcap"


class RunWriter:
    """Writer of one run: a rosbag2 bag with one MCAP file and every loop topic.

    Parameters
    ----------
    path : str or Path
        Bag folder to create (must not exist); the file is ``<path>/<name>.mcap``.
    metadata : dict[str, str]
        Run metadata stored as the bag's custom data (case, design_hash,
        code_version, variant, source, fault ...); values are converted to str.
    Ts : float
        Control period [s]: message log time is k Ts in nanoseconds.

    Raises
    ------
    RunError
        If the folder exists or cannot be created.

    Notes
    -----
    Use as a context manager or call :meth:`close`; ``close(status=...)`` records
    how the run ended in the metadata (complete, interrupted, failed: ...).
    """

    def __init__(self, path: str | Path, metadata: dict, Ts: float) -> None:
        self.path = Path(path)
        if self.path.exists():
            raise RunError(f"run folder {self.path} exists already")
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._ts = typestore()
        self.Ts_ns = int(round(Ts * 1e9))
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        for key, value in metadata.items():
            self._writer.set_custom_data(key, str(value))
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
        self.counts = dict.fromkeys(TOPICS, 0)
        self._closed = False
        self.metadata = {k: str(v) for k, v in metadata.items()}
        self._write_sidecar(status="running")

    def _write_sidecar(self, **extra) -> None:
        """run.json: the metadata, readable even if the process dies before close."""
        tmp = self.path / ".run.json.tmp"
        tmp.write_text(json.dumps({**self.metadata, **extra}, indent=1))
        os.replace(tmp, self.path / "run.json")

    def log_time(self, k: int) -> int:
        """Log time [ns] of step k: k Ts."""
        return k * self.Ts_ns

    def write_raw(self, topic: str, k: int, data: bytes) -> None:
        """Append serialised CDR bytes of step k on a loop topic."""
        self._writer.write(self._conns[topic], self.log_time(k), bytes(data))
        self.counts[topic] += 1

    def write(self, topic: str, k: int, fields: dict) -> None:
        """Serialise a message dict (:mod:`fahv.loop` field names) and append it."""
        self.write_raw(topic, k, encode(topic, fields))

    def set_metadata(self, key: str, value) -> None:
        """Add or replace one metadata entry before the run is closed."""
        self.metadata[key] = str(value)
        self._writer.set_custom_data(key, str(value))

    def close(self, status: str = "complete") -> None:
        """Finish the file (summary, indexes, metadata.yaml); idempotent."""
        if self._closed:
            return
        self._closed = True
        self.set_metadata("status", status)
        self.set_metadata("steps_recorded", min(self.counts.values()))
        self._writer.close()
        self._write_sidecar()

    def __enter__(self):
        return self

    def __exit__(self, exc_type, exc, tb):
        self.close("complete" if exc_type is None else f"failed: {exc_type.__name__}: {exc}")


def _to_ros(ts, msgtype: str, fields: dict):
    cls = ts.types[msgtype]
    kwargs = {}
    for name in cls.__dataclass_fields__:
        if name == "__msgtype__":
            continue
        v = fields[name]
        if isinstance(v, dict):
            sub = ts.fielddefs[msgtype][1]
            subtype = dict(sub)[name][1]
            v = _to_ros(ts, subtype, v)
        elif isinstance(v, np.ndarray) or isinstance(v, list | tuple):
            v = np.asarray(v, dtype=np.float64)
        kwargs[name] = v
    return cls(**kwargs)


def encode(topic: str, fields: dict) -> bytes:
    """CDR bytes of a loop-topic message given as a dict.

    Raises
    ------
    KeyError
        If a field is missing.
    """
    ts = typestore()
    msgtype = TOPICS[topic]
    return bytes(ts.serialize_cdr(_to_ros(ts, msgtype, fields), msgtype))


def _to_dict(obj) -> dict:
    out = {}
    for name in obj.__dataclass_fields__:
        if name == "__msgtype__":
            continue
        v = getattr(obj, name)
        out[name] = _to_dict(v) if hasattr(v, "__dataclass_fields__") else v
    return out


def decode(topic: str, data: bytes) -> dict:
    """Message dict of CDR bytes on a loop topic (inverse of :func:`encode`)."""
    ts = typestore()
    return _to_dict(ts.deserialize_cdr(bytes(data), TOPICS[topic]))


class TruncatedRunWarning(UserWarning):
    """A run file ends before its summary (the recorder was killed): read up to there."""


@dataclass
class Recording:
    """Content of a run file.

    Attributes
    ----------
    path : Path
        The .mcap file.
    metadata : dict[str, str]
        Run metadata (bag custom data, or run.json for a file without summary).
    records : dict[str, list[dict]]
        Decoded messages of each loop topic (:data:`TOPICS`), in file order.
    topics : dict[str, dict]
        Every topic of the file: ``type``, ``count``, ``first_ns``, ``last_ns``
        (unknown topics included, not decoded).
    truncated : bool
        The file ended before its footer; what was complete was read.
    """

    path: Path
    metadata: dict = field(default_factory=dict)
    records: dict = field(default_factory=dict)
    topics: dict = field(default_factory=dict)
    truncated: bool = False


def _bag_custom_data(serialized: str) -> dict:
    try:
        info = yaml.safe_load(serialized) or {}
    except yaml.YAMLError:
        return {}
    if "rosbag2_bagfile_information" in info:
        info = info["rosbag2_bagfile_information"]
    return {str(k): str(v) for k, v in (info.get("custom_data") or {}).items()}


def read_run(run: str | Path) -> Recording:
    """Read a run (bag folder or .mcap file) in one pass.

    A file that ends early (recorder killed) is read up to its last complete
    chunk and a :class:`TruncatedRunWarning` says so. Topics that are not loop
    topics are listed with their counts, not decoded.

    Raises
    ------
    RunError
        If the file is missing, not an MCAP file, or a loop-topic message does not
        decode with its definition; the message names the file.
    """
    _, path = bag_paths(run)
    if not path.is_file():
        raise RunError(f"run file {path} does not exist")
    rec = Recording(path)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    records = {t: [] for t in TOPICS}
    complete = False
    with open(path, "rb") as f:
        head = f.read(8)
        if head != b"\x89MCAP0\r\n":
            raise RunError(f"{path} is not an MCAP file (bad magic bytes)")
        f.seek(0)
        try:
            for r in StreamReader(f).records:
                if isinstance(r, Schema):
                    schemas[r.id] = r
                elif isinstance(r, Channel):
                    channels[r.id] = r
                    schema = schemas.get(r.schema_id)
                    rec.topics.setdefault(
                        r.topic,
                        {
                            "type": schema.name if schema else "",
                            "count": 0,
                            "first_ns": None,
                            "last_ns": None,
                        },
                    )
                elif isinstance(r, Message):
                    ch = channels.get(r.channel_id)
                    if ch is None:
                        continue
                    info = rec.topics[ch.topic]
                    info["count"] += 1
                    info["first_ns"] = r.log_time if info["first_ns"] is None else info["first_ns"]
                    info["last_ns"] = r.log_time
                    if ch.topic in TOPICS and info["type"] == TOPICS[ch.topic]:
                        try:
                            records[ch.topic].append(decode(ch.topic, r.data))
                        except Exception as exc:  # rosbags raises several types
                            raise RunError(
                                f"{path}: a message on {ch.topic} does not decode: {exc}"
                            ) from None
                elif isinstance(r, Metadata) and r.name == "rosbag2":
                    rec.metadata.update(_bag_custom_data(r.metadata.get("serialized_metadata", "")))
                elif isinstance(r, Footer):
                    complete = True
        except (McapError, EOFError, ValueError, KeyError):
            pass  # truncated: keep what was complete, warn below
    rec.truncated = not complete
    if not rec.metadata:
        side = path.parent / "run.json"
        if side.is_file():
            try:
                rec.metadata = {k: str(v) for k, v in json.loads(side.read_text()).items()}
            except (OSError, ValueError):
                pass
    if rec.truncated:
        n = sum(t["count"] for t in rec.topics.values())
        warnings.warn(
            f"{path} is truncated (recorder stopped before closing it): read {n} messages "
            "up to the last complete chunk",
            TruncatedRunWarning,
            stacklevel=2,
        )
    rec.records = records
    return rec


def step_arrays(rec: Recording) -> tuple[int, dict]:
    """Steps present on every loop topic, and the records aligned by step index k.

    Returns
    -------
    n : int
        Number of consecutive steps 0..n-1 present on all loop topics.
    aligned : dict[str, list[dict]]
        Per topic, the message of each step 0..n-1 (the first one if duplicated).
    """
    aligned = {}
    n = math.inf
    for topic, msgs in rec.records.items():
        by_k = {}
        for i, m in enumerate(msgs):
            k = i if topic == "/clock" else int(m["k"])
            by_k.setdefault(k, m)
        m = 0
        while m in by_k:
            m += 1
        n = min(n, m)
        aligned[topic] = by_k
    n = 0 if n == math.inf else int(n)
    return n, {t: [v[k] for k in range(n)] for t, v in aligned.items()}


__all__ = [
    "MSG_DIR",
    "TOPICS",
    "LOOP_QOS",
    "QOS_DEPTH",
    "typestore",
    "code_version",
    "bag_paths",
    "RunWriter",
    "encode",
    "decode",
    "TruncatedRunWarning",
    "Recording",
    "read_run",
    "step_arrays",
]
