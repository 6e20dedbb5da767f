"""ROS codec of the loop messages: typed :mod:`fahv.msg` messages <-> ROS messages.

The one conversion between the library's typed messages (one run, B = 1) and the
generated ``hsv_interfaces`` classes (and rosgraph_msgs/Clock for ``/clock``). The
recorder and the replay never convert: they move the CDR bytes.
"""

from __future__ import annotations

import array
import functools
import operator

import numpy as np

from fahv.loop.graph import TOPICS
from fahv.msg import MESSAGES, STEP_FIELDS, LoopMessage


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


#: numpy dtype of each scalar ROS type of the loop messages.
_SCALARS = {"float64": np.float64, "int64": np.int64, "bool": np.bool_}


@functools.cache
def _plan(cls: type[LoopMessage]) -> dict[str, tuple[str, ...]]:
    """Field names of a typed message class by conversion (cached per class).

    Keys: step, float64, int64, bool, string, float64[].
    """
    plan: dict[str, list[str]] = {k: [] for k in ("step", *_SCALARS, "string", "float64[]")}
    for name, ros, _ in cls.ros_fields():
        plan["step" if name in STEP_FIELDS else ros].append(name)
    return {k: tuple(v) for k, v in plan.items()}


@functools.cache
def _getters(cls: type[LoopMessage]) -> tuple:
    """(kind, names, getter) per non-empty kind of :func:`_plan` (cached per class).

    The getter reads all of the kind's fields of an object at once (a tuple, also for
    one field).
    """
    out = []
    for kind, names in _plan(cls).items():
        if names:
            get = operator.attrgetter(*names)
            out.append((kind, names, get if len(names) > 1 else lambda m, g=get: (g(m),)))
    return tuple(out)


def to_msg(topic: str, message):
    """Loop message of one run (:mod:`fahv.msg`, or the Clock's fields) -> ROS message.

    A typed message gives its lane 0 (the nodes' messages hold one run, B = 1); values
    are converted to the Python types the ROS message expects (float, int, bool, str,
    array('d') for float64[]).

    Raises
    ------
    KeyError
        If a field of the ROS message is missing from ``message`` (Clock fields).
    """
    msg = msg_type_of(topic)()
    if not isinstance(message, LoopMessage):
        _fill(msg, message)
        return msg
    plan = _plan(type(message))
    for name in plan["step"]:
        setattr(msg, name, getattr(message, name))
    for kind, py in (("float64", float), ("int64", int), ("bool", bool)):
        for name in plan[kind]:
            setattr(msg, name, py(getattr(message, name)[0]))
    for name in plan["string"]:
        setattr(msg, name, str(getattr(message, name)[0]))
    for name in plan["float64[]"]:  # bytes: the generated setter builds its array('d') from them
        setattr(msg, name, np.ascontiguousarray(getattr(message, name)[0], np.float64).tobytes())
    return msg


def from_msg(topic: str, msg):
    """ROS message of a loop topic -> :mod:`fahv.msg` message of one run (B = 1).

    The fields are read by the typed message's own field list (the loop messages are
    flat: no nested message to convert). The scalars of one ROS type are read at once
    into one array and each field is a (1,) view of its row; a float64[] field becomes a
    (1, n) copy.

    Raises
    ------
    KeyError
        If ``topic`` is not a loop topic of a typed message.
    """
    cls = MESSAGES[TOPICS[topic]]
    values: dict = {}
    for kind, names, get in _getters(cls):
        got = get(msg)
        if kind == "step":
            pairs = zip(names, got, strict=True)
        elif kind == "string":
            pairs = ((name, (str(v),)) for name, v in zip(names, got, strict=True))
        elif kind == "float64[]":
            rows = (np.array(v, np.float64)[None, :] for v in got)
            pairs = zip(names, rows, strict=True)
        else:  # scalars of one type: one (n, 1) array, a (1,) row view per field
            pairs = zip(names, np.array(got, dtype=_SCALARS[kind])[:, None], strict=True)
        values.update(pairs)
    return cls(**values)


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
