"""The loop topics' messages in a run file: their QoS, types and CDR encoding.

The message definitions are those of ``src/fahv/msg/*.msg`` (also the sources of the
``hsv_interfaces`` package), registered in a ``rosbags`` type store; :func:`encode`
serialises a loop message (:mod:`fahv.loop.cores`) to the CDR bytes the SIL nodes
publish, :func:`decode` reads them back, and :func:`file_typestore` reads a definition
stored in a run file. :data:`LOOP_QOS` is the channels' ``offered_qos_profiles``.
"""

from __future__ import annotations

import functools

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
from fahv.msg import MSG_DIR, PKG, LoopMessage

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


def encode(topic: str, msg) -> bytes:
    """CDR bytes of a loop-topic message: the one conversion to the wire format.

    Parameters
    ----------
    topic : str
        A loop topic (:data:`fahv.loop.graph.TOPICS`).
    msg : fahv.msg.LoopMessage or dict
        A message of one run (its lane 0 is written), or the fields as a dict (the
        lane form of :meth:`fahv.msg.LoopMessage.lane`, or the Clock).

    Raises
    ------
    KeyError
        If a field is missing.
    """
    fields = msg.lane(0) if isinstance(msg, LoopMessage) else msg
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
