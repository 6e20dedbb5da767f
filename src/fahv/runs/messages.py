"""The loop topics' messages in a run file: their QoS, types and CDR encoding.

The message definitions are those of ``src/fahv/msg/*.msg`` (also the sources of the
``hsv_interfaces`` package), registered in a ``rosbags`` type store; :func:`encode`
serialises a loop message (:mod:`fahv.loop.cores`) to the CDR bytes the SIL nodes
publish, :func:`decode` reads them back, and :func:`file_typestore` reads a definition
stored in a run file. :data:`LOOP_QOS` is the channels' ``offered_qos_profiles``.
"""

from __future__ import annotations

import functools
import struct

import numpy as np
from mcap.records import Schema
from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from fahv.errors import RunError
from fahv.loop import graph
from fahv.loop.graph import TOPICS
from fahv.msg import MESSAGES, MSG_DIR, PKG, STEP_FIELDS, LoopMessage

_INF = QosTime(2147483647, 4294967295)


def offered_qos(q: graph.QoS) -> Qos:
    """rosbag2 ``offered_qos_profiles`` entry of a :class:`fahv.loop.graph.QoS`."""
    return Qos(
        QosHistory.KEEP_LAST,
        q.depth,
        QosReliability.RELIABLE if q.reliable else QosReliability.BEST_EFFORT,
        QosDurability.TRANSIENT_LOCAL if q.transient_local else QosDurability.VOLATILE,
        _INF,
        _INF,
        QosLiveliness.AUTOMATIC,
        _INF,
        False,
    )


#: The loop topics' QoS (:data:`fahv.loop.graph.LOOP_QOS`) as the channels offer it.
LOOP_QOS = offered_qos(graph.LOOP_QOS)


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


#: MCAP metadata record of the run metadata (written when the run starts, again at its end).
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

    ``kind`` is ``step`` for k and t, else the field's ROS type.
    """
    cls = MESSAGES[msgtype]
    fields = tuple(
        (name, "step" if name in STEP_FIELDS else ros) for name, ros, _ in cls.ros_fields()
    )
    return cls, typestore().types[msgtype], fields


def encode(topic: str, msg) -> bytes:
    """CDR bytes of a loop-topic message: the one conversion to the wire format.

    The nodes publish these bytes, the recorder writes them, and the in-process
    writer (:mod:`fahv.runs.writer`) writes the same bytes for the same message.

    Parameters
    ----------
    topic : str
        A loop topic (:data:`fahv.loop.graph.TOPICS`).
    msg : fahv.msg.LoopMessage or dict
        A message of one run (its lane 0 is written), or the fields as a dict (the
        lane form of :meth:`fahv.msg.LoopMessage.lane`, or the Clock's fields of
        :func:`fahv.loop.graph.clock_msg`).

    Raises
    ------
    KeyError
        If ``topic`` is not a loop topic, or a field is missing from a dict.
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
    """CDR bytes of a loop topic -> its :mod:`fahv.msg` message of one run (B = 1).

    The inverse of :func:`encode` for a typed message: ``k`` an int, ``t`` a float,
    a scalar field a (1,) array of its dtype, a float64[] field a (1, n) float array,
    a string a 1-tuple. Little- and big-endian CDR are read (the header says which).

    Raises
    ------
    KeyError
        If ``topic`` is not a loop topic of a typed message (``/clock`` is not).
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

    Every ``hsv_interfaces`` loop message starts with ``int64 k`` (aligned at the start
    of the payload, after the 4-byte CDR header); ``/clock`` carries t_k = k Ts. The
    recorder stores the bytes undecoded, so it reads k alone.

    Parameters
    ----------
    topic : str
        A loop topic.
    data : bytes
        The message's CDR bytes (little- or big-endian).
    Ts_ns : int
        Sample time Ts [ns] (only ``/clock`` needs it).
    """
    endian = "<" if data[1] & 1 else ">"
    if topic == "/clock":
        sec, nsec = struct.unpack_from(f"{endian}iI", data, 4)
        return int(round((sec * 1_000_000_000 + nsec) / Ts_ns))
    return struct.unpack_from(f"{endian}q", data, 4)[0]


def _to_dict(obj) -> dict:
    out = {}
    for name in obj.__dataclass_fields__:
        if name == "__msgtype__":
            continue
        v = getattr(obj, name)
        out[name] = _to_dict(v) if hasattr(v, "__dataclass_fields__") else v
    return out


def decode(topic: str, data: bytes, ts=None) -> dict:
    """Message dict of CDR bytes on a loop topic (inverse of :func:`encode`).

    ``ts``: typestore to decode with (default :func:`typestore`; a run written with
    an older definition is decoded with its own, see :func:`file_typestore`).
    """
    ts = typestore() if ts is None else ts
    return _to_dict(ts.deserialize_cdr(bytes(data), TOPICS[topic]))


@functools.cache
def file_typestore(msgtype: str, msgdef: str):
    """Typestore that decodes ``msgtype`` with the definition stored in a run file.

    Runs keep the full definition of every schema, so a run recorded before a
    message gained a field still decodes (the missing field is then absent from
    the message dicts).

    Raises
    ------
    RunError
        If the stored definition does not parse.
    """
    ts = get_typestore(Stores.ROS2_JAZZY)
    try:
        ts.register(get_types_from_msg(msgdef, msgtype))
    except Exception as exc:  # rosbags raises several parser errors
        raise RunError(f"the stored definition of {msgtype} does not parse: {exc}") from None
    return ts


def decoder_of(schema: Schema | None):
    """Typestore for a loop-topic schema: ours when the definitions agree."""
    if schema is None:
        return typestore()
    text = schema.data.decode(errors="replace")
    if schema.name in typestore().types and text == typestore().generate_msgdef(schema.name)[0]:
        return typestore()
    return file_typestore(schema.name, text)
