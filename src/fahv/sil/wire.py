"""The wire codec of the loop topics: typed messages <-> CDR bytes, one codec for all.

The message definitions are those of `src/fahv/msg/*.msg` (also the sources of the
`hsv_interfaces` package), registered in a `rosbags` type store. `encode`
serialises a loop message (`fahv.msg`) to the CDR bytes (little-endian XCDR1) the
SIL nodes publish and the run files hold, `decode_message` reads them back into the
typed message of one run, and `step_of` reads a message's step index alone (for the
recorder, which stores bytes undecoded). rclpy reads these bytes as the generated
messages, and the nodes read the bytes rclpy writes (a test checks both ways).
"""

from __future__ import annotations

import functools
import struct

import numpy as np
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from fahv.errors import RunError
from fahv.loop.graph import TOPICS
from fahv.msg import MESSAGES, MSG_DIR, PKG, STEP_FIELDS, LoopMessage

#: Definitions of the standard message types the loop topics use (ROS 2 Jazzy's
#: rosgraph_msgs/Clock and builtin_interfaces/Time): with them an empty store holds every
#: loop type without loading rosbags' whole Jazzy store (0.12 s of CPU in each node
#: process, measured); a test checks the definitions and type hashes against that store.
STANDARD_TYPES = {
    "builtin_interfaces/msg/Time": "int32 sec\nuint32 nanosec",
    "rosgraph_msgs/msg/Clock": "builtin_interfaces/Time clock",
}


@functools.cache
def typestore():
    """Typestore (rosbags) of the loop topics: `STANDARD_TYPES` and `hsv_interfaces`.

    Raises
    ------
    RunError
        If a message definition file is missing.
    """
    ts = get_typestore(Stores.EMPTY)
    types = {}
    for name, text in STANDARD_TYPES.items():
        types.update(get_types_from_msg(text, name))
    for name in sorted({t for t in TOPICS.values() if t.startswith(PKG)}):
        path = MSG_DIR / f"{name.rsplit('/', 1)[1]}.msg"
        try:
            types.update(get_types_from_msg(path.read_text(), name))
        except OSError as exc:
            raise RunError(f"message definition {path} is unreadable: {exc}") from None
    ts.register(types)
    return ts


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


#: numpy dtype of each scalar ROS type of the loop messages (their (B,) fields).
_SCALARS = {"float64": np.float64, "int64": np.int64, "bool": np.bool_}


@functools.cache
def _layout(msgtype: str) -> tuple:
    """(typed class, rosbags class, ((name, kind), ...)) of a loop message type.

    `kind` is `step` for k and t, else the field's ROS type.
    """
    cls = MESSAGES[msgtype]
    fields = tuple(
        (name, "step" if name in STEP_FIELDS else ros) for name, ros, _ in cls.ros_fields()
    )
    return cls, typestore().types[msgtype], fields


def encode(topic: str, msg) -> bytes:
    """CDR bytes of a loop-topic message: the one conversion to the wire format.

    The nodes publish these bytes, the recorder writes them, and the in-process
    writer (`fahv.runs.writer`) writes the same bytes for the same message.

    Parameters
    ----------
    topic : str
        A loop topic (`fahv.loop.graph.TOPICS`).
    msg : fahv.msg.LoopMessage or dict
        A message of one run (its lane 0 is written), or the fields as a dict (the
        lane form of `fahv.msg.LoopMessage.lane`, or the Clock's fields of
        `fahv.loop.graph.clock_msg`).

    Raises
    ------
    KeyError
        If `topic` is not a loop topic, or a field is missing from a dict.
    """
    ts = typestore()
    msgtype = TOPICS[topic]
    if not isinstance(msg, LoopMessage):
        return bytes(ts.serialize_cdr(_to_ros(ts, msgtype, msg), msgtype))
    _, wire, fields = _layout(msgtype)
    values = {}
    for name, kind in fields:
        v = getattr(msg, name)
        if kind == "float64[]":
            values[name] = np.ascontiguousarray(v[0], dtype=np.float64)
        else:
            values[name] = v if kind == "step" else v[0]
    return bytes(ts.serialize_cdr(wire(**values), msgtype))


def decode_message(topic: str, data: bytes):
    """CDR bytes of a loop topic -> its `fahv.msg` message of one run (B = 1).

    The inverse of `encode` for a typed message: `k` an int, `t` a float,
    a scalar field a (1,) array of its dtype, a float64[] field a (1, n) float array,
    a string a 1-tuple. Little- and big-endian CDR are read (the header says which).

    Raises
    ------
    KeyError
        If `topic` is not a loop topic of a typed message (`/clock` is not).
    """
    cls, _, fields = _layout(TOPICS[topic])
    wire = typestore().deserialize_cdr(data, TOPICS[topic])
    values = {}
    for name, kind in fields:
        v = getattr(wire, name)
        if kind == "step":
            values[name] = v
        elif kind == "string":
            values[name] = (v,)
        elif kind == "float64[]":
            values[name] = np.array(v, dtype=np.float64)[None, :]
        else:
            values[name] = np.array((v,), dtype=_SCALARS[kind])
    return cls(**values)


def step_of(topic: str, data: bytes, Ts_ns: int) -> int:
    """Step index k of a serialised loop message, without decoding the rest of it.

    Every `hsv_interfaces` loop message starts with `int64 k` (aligned at the start
    of the payload, after the 4-byte CDR header); `/clock` carries t_k = k Ts. The
    recorder stores the bytes undecoded, so it reads k alone.

    Parameters
    ----------
    topic : str
        A loop topic.
    data : bytes
        The message's CDR bytes (little- or big-endian).
    Ts_ns : int
        Sample time Ts [ns] (only `/clock` needs it).
    """
    endian = "<" if data[1] & 1 else ">"
    if topic == "/clock":
        sec, nsec = struct.unpack_from(f"{endian}iI", data, 4)
        return int(round((sec * 1_000_000_000 + nsec) / Ts_ns))
    return struct.unpack_from(f"{endian}q", data, 4)[0]
