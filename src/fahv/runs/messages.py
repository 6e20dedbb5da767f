"""The loop topics' messages in a run file: their QoS and their decoding to dicts.

The CDR bytes in a run file are those of the wire codec `fahv.sil.wire` (the bytes
the nodes publish); `decode` reads them back as message dicts, and
`file_typestore` reads a definition stored in a run file (a run recorded before a
message changed). `LOOP_QOS` is the channels' `offered_qos_profiles`.
"""

from __future__ import annotations

import functools

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
from fahv.sil.wire import typestore

_INF = QosTime(2147483647, 4294967295)


def offered_qos(q: graph.QoS) -> Qos:
    """rosbag2 `offered_qos_profiles` entry of a `fahv.loop.graph.QoS`."""
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


#: The loop topics' QoS (`fahv.loop.graph.LOOP_QOS`) as the channels offer it.
LOOP_QOS = offered_qos(graph.LOOP_QOS)


def _to_dict(obj) -> dict:
    out = {}
    for name in obj.__dataclass_fields__:
        if name == "__msgtype__":
            continue
        v = getattr(obj, name)
        out[name] = _to_dict(v) if hasattr(v, "__dataclass_fields__") else v
    return out


def decode(topic: str, data: bytes, ts=None) -> dict:
    """Message dict of CDR bytes on a loop topic (inverse of `encode`).

    `ts`: typestore to decode with (default `typestore`; a run written with
    an older definition is decoded with its own, see `file_typestore`).
    """
    ts = typestore() if ts is None else ts
    return _to_dict(ts.deserialize_cdr(bytes(data), TOPICS[topic]))


@functools.cache
def file_typestore(msgtype: str, msgdef: str):
    """Typestore that decodes `msgtype` with the definition stored in a run file.

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
