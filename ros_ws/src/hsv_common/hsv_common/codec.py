"""ROS codec of the loop messages: typed :mod:`fahv.msg` messages <-> ROS messages.

The one conversion between the library's typed messages (one run, B = 1) and the
generated ``hsv_interfaces`` classes (and rosgraph_msgs/Clock for ``/clock``). The
recorder and the replay never convert: they move the CDR bytes.
"""

from __future__ import annotations

import array
import functools

import numpy as np

from fahv.loop.graph import TOPICS
from fahv.msg import MESSAGES, LoopMessage


@functools.cache
def msg_type_of(topic: str):
    """ROS message class of a loop topic (rosgraph_msgs/Clock for ``/clock``).

    Raises
    ------
    KeyError
        If ``topic`` is not a loop topic of :data:`fahv.loop.graph.TOPICS`.
    """
    pkg, _, name = TOPICS[topic].split("/")
    module = __import__(f"{pkg}.msg", fromlist=[name])
    return getattr(module, name)


def to_msg(topic: str, message):
    """Loop message of one run (:mod:`fahv.msg`, or the Clock's fields) -> ROS message.

    Raises
    ------
    KeyError
        If a field of the ROS message is missing from ``message``.
    """
    msg = msg_type_of(topic)()
    _fill(msg, message.lane(0) if isinstance(message, LoopMessage) else message)
    return msg


def from_msg(topic: str, msg):
    """ROS message of a loop topic -> :mod:`fahv.msg` message of one run (B = 1).

    The fields are read by the typed message's own field list (the loop messages are
    flat: no nested message to convert); arrays become float64 ndarrays in
    :meth:`~fahv.msg.LoopMessage.from_lanes`.

    Raises
    ------
    KeyError
        If ``topic`` is not a loop topic of a typed message.
    """
    cls = MESSAGES[TOPICS[topic]]
    return cls.from_lanes([{name: getattr(msg, name) for name, _, _ in cls.ros_fields()}])


def _fill(msg, fields: dict) -> None:
    for name in msg.get_fields_and_field_types():
        v = fields[name]
        if isinstance(v, dict):
            _fill(getattr(msg, name), v)
        elif isinstance(v, np.ndarray | list | tuple):
            arr = array.array("d")
            arr.frombytes(np.ascontiguousarray(v, dtype=np.float64).tobytes())
            setattr(msg, name, arr)
        elif isinstance(v, np.floating):
            setattr(msg, name, float(v))
        else:
            setattr(msg, name, v)
