"""Recorded runs: the loop topics, their message types, and rosbag2/MCAP files.

A run is a rosbag2 bag (as `ros2 bag record -s mcap` writes it): a folder
`bags/<run>/` holding one `<run>.mcap` (ros2 profile: `ros2msg` schemas with the
full definition, `cdr` messages, `offered_qos_profiles` channel metadata,
summary with statistics and indexes, a `rosbag2` metadata record) and
`metadata.yaml`. Log time is simulated time. Files are written with the
`rosbags` library's rosbag2 writer, so rosbag2 (`ros2 bag info`), Foxglove and
`rosbags` open them; the run metadata (case, design hash, code version, variant,
fault, source) is in the bag's `custom_data`.

The SIL recorder writes the raw CDR bytes it receives; the in-process simulator
serialises the same dicts (`fahv.loop.cores`) with the same definitions
(`src/fahv/msg/*.msg`, also the sources of the `hsv_interfaces` package).
"""

from __future__ import annotations

import json
import math
import struct
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import yaml
from mcap.exceptions import McapError
from mcap.reader import make_reader
from mcap.records import Attachment, Channel, Footer, Message, Metadata, Schema
from mcap.stream_reader import StreamReader

from fahv.errors import RunError
from fahv.loop.graph import TOPICS
from fahv.loop.simulate import RunResult, run_result
from fahv.runs.messages import decode, decoder_of
from fahv.verdict import METADATA_KEYS

RUN_RECORD = "fahv.run"
#: Attachment: the ROS 2 parameter file of every node of the run.
PARAMS = "params.yaml"
#: Metadata keys a run gets when it ends (not part of what it was made from).
END_KEYS = ("status", "steps_recorded", "wall_time_s", "ros_domain_id", *METADATA_KEYS)


def start_metadata(meta: dict) -> dict:
    """Run metadata without what the end of the run added (status, counts, wall time).

    What a replay or a rerun of the run inherits.
    """
    return {k: v for k, v in meta.items() if k not in END_KEYS and not k.startswith("anomalies")}


def bag_paths(run: str | Path) -> tuple[Path, Path]:
    """(bag folder, .mcap file) of a run given either of them.

    A folder's file is the one its `metadata.yaml` names (rosbag2's
    `relative_file_paths`, relative to the folder), else the only `.mcap` in it,
    so a renamed or copied folder is read like the original. A folder without any
    gives `<folder>/<folder name>.mcap` (which then does not exist).

    Raises
    ------
    RunError
        If a folder holds several .mcap files and no metadata.yaml names one.
    """
    p = Path(run)
    if p.suffix == ".mcap" or not p.is_dir():
        return (p.parent, p) if p.suffix == ".mcap" else (p, p / f"{p.name}.mcap")
    try:
        info = yaml.safe_load((p / "metadata.yaml").read_text()) or {}
        info = info.get("rosbag2_bagfile_information", info)
        names = [n for n in info.get("relative_file_paths") or [] if str(n).endswith(".mcap")]
    except (OSError, yaml.YAMLError, AttributeError):
        names = []
    for n in names:
        if (p / n).is_file():
            return p, p / n
    found = sorted(p.glob("*.mcap"))
    if len(found) > 1:
        raise RunError(f"{p} holds several .mcap files {[f.name for f in found]}: name one")
    return p, found[0] if found else p / f"{p.name}.mcap"


def _legacy_folder(mcap: Path) -> Path | None:
    """The run folder of an earlier version's file (sidecar files there), else None.

    Earlier versions kept params.yaml, timestamps.npz and run.json beside the .mcap;
    they count only in the file's own run folder (its metadata.yaml names the file,
    or the folder is named after it), never for a bare file in any folder.
    """
    folder = mcap.parent
    if folder.name == mcap.stem:
        return folder
    try:
        return folder if mcap.name in (folder / "metadata.yaml").read_text() else None
    except OSError:
        return None


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
        Decoded messages of each loop topic (`TOPICS`), in file order.
    topics : dict[str, dict]
        Every topic of the file: `type`, `count`, `first_ns`, `last_ns`
        (unknown topics included, not decoded).
    truncated : bool
        The file ended before its footer; what was complete was read.
    schemas : dict[str, str]
        Stored message definition of each topic's type.
    attachments : dict[str, bytes]
        Attachments of the file by name (`params.yaml`, `timestamps.npz` ...).
    """

    path: Path
    metadata: dict = field(default_factory=dict)
    records: dict = field(default_factory=dict)
    topics: dict = field(default_factory=dict)
    truncated: bool = False
    schemas: dict = field(default_factory=dict)
    attachments: dict = field(default_factory=dict)

    def attachment(self, name: str) -> bytes | None:
        """An attachment of the run file (None if it has none of that name).

        For a run of an earlier version, the file of that name in its run folder.
        """
        if name in self.attachments:
            return self.attachments[name]
        folder = _legacy_folder(self.path)
        try:
            return None if folder is None else (folder / name).read_bytes()
        except OSError:
            return None

    def params(self) -> dict | None:
        """The run's ROS 2 parameter file (`{node: {"ros__parameters": ...}}`), or None.

        Raises
        ------
        RunError
            If the stored file is not a YAML mapping.
        """
        return _parse_params(self.attachment(PARAMS), self.path)

    @property
    def sim_span(self) -> tuple[float, float]:
        """(first, last) log time [s] over every topic; (nan, nan) when empty."""
        ts = [
            v for t in self.topics.values() for v in (t["first_ns"], t["last_ns"]) if v is not None
        ]
        return (min(ts) * 1e-9, max(ts) * 1e-9) if ts else (math.nan, math.nan)


def _bag_custom_data(serialized: str) -> dict:
    try:
        info = yaml.safe_load(serialized) or {}
    except yaml.YAMLError:
        return {}
    if "rosbag2_bagfile_information" in info:
        info = info["rosbag2_bagfile_information"]
    return {str(k): str(v) for k, v in (info.get("custom_data") or {}).items()}


class _Stream:
    """MCAP records of a run file in file order; `complete` once the footer was read.

    A file that ends early stops the iteration at its last complete record.

    Raises
    ------
    RunError
        If the file is missing or is not an MCAP file.
    """

    MAGIC = b"\x89MCAP0\r\n"

    def __init__(self, run: str | Path) -> None:
        _, self.path = bag_paths(run)
        if not self.path.is_file():
            raise RunError(f"run file {self.path} does not exist")
        with open(self.path, "rb") as f:
            if f.read(8) != self.MAGIC:
                raise RunError(f"{self.path} is not an MCAP file (bad magic bytes)")
        self.complete = False

    def __iter__(self):
        with open(self.path, "rb") as f:
            try:
                for r in StreamReader(f).records:
                    if isinstance(r, Footer):
                        self.complete = True
                    yield r
            except (McapError, EOFError, ValueError, KeyError, struct.error):
                return  # truncated: keep what was complete, the caller warns

    def warn_if_truncated(self, n: int, stacklevel: int = 3) -> None:
        """TruncatedRunWarning if the footer was not reached (`n` messages read)."""
        if not self.complete:
            warnings.warn(
                f"{self.path} is truncated (recorder stopped before closing it): read {n} "
                "messages up to the last complete chunk",
                TruncatedRunWarning,
                stacklevel=stacklevel,
            )


def _legacy_metadata(mcap: Path) -> dict:
    """run.json of an earlier version's run folder (metadata of a file cut short)."""
    folder = _legacy_folder(mcap)
    try:
        data = json.loads((folder / "run.json").read_text()) if folder else {}
        return {k: str(v) for k, v in data.items()}
    except (OSError, ValueError, AttributeError):
        return {}


def _parse_params(data: bytes | None, where) -> dict | None:
    if data is None:
        return None
    try:
        params = yaml.safe_load(data.decode())
    except (yaml.YAMLError, UnicodeDecodeError) as exc:
        raise RunError(f"{where}: the stored {PARAMS} does not parse: {exc}") from None
    if not isinstance(params, dict):
        raise RunError(f"{where}: the stored {PARAMS} is not a ROS 2 parameter file")
    return params


def _file_extras(run: str | Path) -> tuple[dict, dict]:
    """(metadata, attachments) of a run file without decoding its messages.

    From the summary's indexes when the file has one; a file cut short is scanned.
    """
    stream = _Stream(run)
    meta: dict = {}
    atts: dict = {}
    try:
        with open(stream.path, "rb") as f:
            reader = make_reader(f)
            summary = reader.get_summary()
            if summary is not None and (summary.metadata_indexes or summary.attachment_indexes):
                for m in reader.iter_metadata():
                    if m.name == "rosbag2":
                        meta.update(_bag_custom_data(m.metadata.get("serialized_metadata", "")))
                    elif m.name == RUN_RECORD:
                        meta.update(m.metadata)
                for a in reader.iter_attachments():
                    atts[a.name] = bytes(a.data)
                return meta, atts
    except (McapError, EOFError, ValueError, KeyError, struct.error, OSError):
        pass
    for r in stream:
        if isinstance(r, Metadata) and r.name == "rosbag2":
            meta.update(_bag_custom_data(r.metadata.get("serialized_metadata", "")))
        elif isinstance(r, Metadata) and r.name == RUN_RECORD:
            meta.update(r.metadata)
        elif isinstance(r, Attachment):
            atts[r.name] = bytes(r.data)
    return meta, atts


def stored_metadata(run: str | Path) -> dict:
    """Run metadata without decoding the messages.

    From the run file's metadata records; for a run of an earlier version without
    them, its folder's metadata.yaml or run.json. Empty when none is readable.

    Raises
    ------
    RunError
        If the file is missing or not an MCAP file.
    """
    _, mcap = bag_paths(run)
    meta, _ = _file_extras(mcap)
    if meta:
        return meta
    folder = _legacy_folder(mcap)
    if folder is not None:
        try:
            meta = _bag_custom_data((folder / "metadata.yaml").read_text())
        except OSError:
            meta = {}
    return meta or _legacy_metadata(mcap)


def run_attachments(run: str | Path) -> dict[str, bytes]:
    """Attachments of a run file by name (a run of an earlier version: none).

    Raises
    ------
    RunError
        If the file is missing or not an MCAP file.
    """
    return _file_extras(bag_paths(run)[1])[1]


def run_params(run: str | Path) -> dict | None:
    """The ROS 2 parameter file a run was made with, or None if it holds none.

    From the run file (attachment `params.yaml`); for a run of an earlier version,
    the `params.yaml` in its run folder.

    Raises
    ------
    RunError
        If the file is missing, not an MCAP file, or the parameter file does not parse.
    """
    _, mcap = bag_paths(run)
    data = run_attachments(mcap).get(PARAMS)
    if data is None:
        folder = _legacy_folder(mcap)
        try:
            data = None if folder is None else (folder / PARAMS).read_bytes()
        except OSError:
            data = None
    return _parse_params(data, mcap)


def read_run(run: str | Path) -> Recording:
    """Read a run (bag folder or .mcap file) in one pass.

    A file that ends early (recorder killed) is read up to its last complete
    chunk and a `TruncatedRunWarning` says so. Topics that are not loop
    topics are listed with their counts, not decoded; a loop topic recorded with
    an older definition is decoded with the stored one.

    Raises
    ------
    RunError
        If the file is missing, not an MCAP file, or a loop-topic message does not
        decode with its definition; the message names the file.
    """
    stream = _Stream(run)
    path = stream.path
    rec = Recording(path)
    schemas: dict[int, Schema] = {}
    channels: dict[int, Channel] = {}
    records = {t: [] for t in TOPICS}
    decoders = {}
    for r in stream:
        if isinstance(r, Schema):
            schemas[r.id] = r
        elif isinstance(r, Channel):
            channels[r.id] = r
            schema = schemas.get(r.schema_id)
            if schema is not None:
                rec.schemas[r.topic] = schema.data.decode(errors="replace")
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
                    ts = decoders.get(ch.id)
                    if ts is None:
                        ts = decoders[ch.id] = decoder_of(schemas.get(ch.schema_id))
                    records[ch.topic].append(decode(ch.topic, r.data, ts))
                except Exception as exc:  # rosbags raises several types
                    raise RunError(
                        f"{path}: a message on {ch.topic} does not decode: {exc}"
                    ) from None
        elif isinstance(r, Metadata) and r.name == "rosbag2":
            rec.metadata.update(_bag_custom_data(r.metadata.get("serialized_metadata", "")))
        elif isinstance(r, Metadata) and r.name == RUN_RECORD:
            rec.metadata.update(r.metadata)
        elif isinstance(r, Attachment):
            rec.attachments[r.name] = bytes(r.data)
    rec.truncated = not stream.complete
    if not rec.metadata:
        rec.metadata = _legacy_metadata(path)
    stream.warn_if_truncated(sum(t["count"] for t in rec.topics.values()))
    rec.records = records
    return rec


def iter_raw(run: str | Path, topics=None):
    """Raw messages of a run in file order, for replay.

    Parameters
    ----------
    run : path
        Bag folder or .mcap file.
    topics : iterable of str, optional
        Only these topics (default: every topic).

    Yields
    ------
    (topic, msgtype, log_time_ns, data) : (str, str, int, bytes)
        `data` is the CDR payload as recorded.

    Raises
    ------
    RunError
        If the file is missing or not an MCAP file. A truncated file ends the
        iteration early with a `TruncatedRunWarning`.
    """
    stream = _Stream(run)
    wanted = None if topics is None else set(topics)
    schemas, channels, n = {}, {}, 0
    for r in stream:
        if isinstance(r, Schema):
            schemas[r.id] = r.name
        elif isinstance(r, Channel):
            channels[r.id] = (r.topic, schemas.get(r.schema_id, ""))
        elif isinstance(r, Message) and r.channel_id in channels:
            topic, msgtype = channels[r.channel_id]
            if wanted is None or topic in wanted:
                n += 1
                yield topic, msgtype, r.log_time, bytes(r.data)
    stream.warn_if_truncated(n, stacklevel=2)


def step_anomalies(rec: Recording) -> dict[str, dict[str, int]]:
    """Step-index anomalies of each loop topic, from the messages themselves.

    Returns
    -------
    dict
        Per loop topic: `duplicate` (a step index seen again), `out_of_order`
        (a step index lower than one already seen) and `missing` (indices absent
        between 0 and the highest seen).
    """
    out = {}
    for topic, msgs in rec.records.items():
        ks = [i for i, _ in enumerate(msgs)] if topic == "/clock" else [int(m["k"]) for m in msgs]
        seen, dup, ooo, top = set(), 0, 0, -1
        for k in ks:
            dup += k in seen
            ooo += k < top and k not in seen
            seen.add(k)
            top = max(top, k)
        out[topic] = {"duplicate": dup, "out_of_order": ooo, "missing": top + 1 - len(seen)}
    return out


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


def run_result_of(rec: Recording) -> RunResult:
    """`RunResult` of a recorded run (complete steps only)."""
    n, aligned = step_arrays(rec)
    return run_result(aligned, {**rec.metadata, "steps": n})
