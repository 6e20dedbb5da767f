"""ROS codec of the loop messages: typed :mod:`fahv.msg` messages <-> CDR bytes.

The nodes move the loop messages as CDR bytes (raw subscriptions, serialized
publication): :func:`decode` turns the bytes of one run (B = 1) into the library's typed
message, :func:`encode` the other way, without the generated ``hsv_interfaces`` Python
objects in between (half the conversion time of a hop, measured). The loop messages are
flat (int64, float64, bool, string, float64[]), so their CDR is short to write:
little-endian XCDR1 with the 4-byte encapsulation header, each primitive aligned to its
size from the start of the payload, a string or sequence led by its uint32 length
(aligned to 4, a string's with its NUL), the elements of a non-empty float64 sequence
aligned to 8; padding is written as zeros. :func:`to_msg` and :func:`from_msg` convert
to and from the generated classes (rclpy's own serialization: the reference the tests
check the CDR codec against). The recorder and the replay never convert.
"""

from __future__ import annotations

import array
import functools
import operator
import struct

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


#: Encapsulation header of little-endian CDR (XCDR1), the byte order the nodes write.
CDR_LE = b"\x00\x01\x00\x00"
#: Encapsulation kinds (second byte of the header) of little-endian CDR.
_LITTLE = (0x01, 0x03)
_K_LE, _K_BE = struct.Struct("<q"), struct.Struct(">q")
_CLOCK_LE = struct.Struct("<iI")


@functools.cache
def _layout(cls: type[LoopMessage]) -> tuple[tuple[str, str], ...]:
    """(name, ROS type) of every field of a typed message class, in CDR order."""
    return tuple((name, ros) for name, ros, _ in cls.ros_fields())


def step_of(data: bytes) -> int:
    """Step index k of a serialized loop message (its first field, ``int64 k``)."""
    return (_K_LE if data[1] in _LITTLE else _K_BE).unpack_from(data, 4)[0]


def decode(topic: str, data: bytes) -> LoopMessage:
    """CDR bytes of a loop topic -> :mod:`fahv.msg` message of one run (B = 1).

    The same values, dtypes and shapes as :func:`from_msg` of the deserialized message:
    the scalars of one ROS type are one (n, 1) array and each field a (1,) row of it,
    a float64[] field a (1, n) array, a string a 1-tuple.

    Raises
    ------
    KeyError
        If ``topic`` is not a loop topic of a typed message.
    struct.error
        If ``data`` is shorter than its message.
    """
    cls = MESSAGES[TOPICS[topic]]
    e = "<" if data[1] in _LITTLE else ">"
    values: dict = {}
    scalars: dict[str, tuple[list, list]] = {k: ([], []) for k in _SCALARS}
    pos = 0
    for name, ros in _layout(cls):
        if ros in ("float64", "int64"):
            pos += -pos % 8
            v = struct.unpack_from(e + ("d" if ros == "float64" else "q"), data, 4 + pos)[0]
            pos += 8
        elif ros == "bool":
            v = data[4 + pos] != 0
            pos += 1
        elif ros == "string":
            pos += -pos % 4
            n = struct.unpack_from(e + "I", data, 4 + pos)[0]
            values[name] = (data[8 + pos : 8 + pos + max(n - 1, 0)].decode(),)
            pos += 4 + n
            continue
        else:  # float64[]
            pos += -pos % 4
            n = struct.unpack_from(e + "I", data, 4 + pos)[0]
            pos += 4
            if n:
                pos += -pos % 8
            row = np.frombuffer(data, e + "f8", n, 4 + pos).astype(np.float64)
            values[name] = row[None, :]
            pos += 8 * n
            continue
        if name in STEP_FIELDS:
            values[name] = v
        else:
            scalars[ros][0].append(name)
            scalars[ros][1].append(v)
    for ros, (names, vals) in scalars.items():
        if names:
            values.update(zip(names, np.array(vals, dtype=_SCALARS[ros])[:, None], strict=True))
    return cls(**values)


def encode(topic: str, message) -> bytes:
    """Loop message of one run (:mod:`fahv.msg`, or the Clock's fields) -> CDR bytes.

    A typed message gives its lane 0; ``/clock`` takes the fields of
    :func:`fahv.loop.graph.clock_msg` (``{"clock": {"sec": s, "nanosec": ns}}``).

    Raises
    ------
    KeyError
        If a field of the Clock is missing from ``message``.
    """
    if not isinstance(message, LoopMessage):
        clock = message["clock"]
        return CDR_LE + _CLOCK_LE.pack(int(clock["sec"]), int(clock["nanosec"]))
    out = bytearray(CDR_LE)
    for name, ros in _layout(type(message)):
        v = getattr(message, name)
        if name not in STEP_FIELDS:
            v = v[0]
        pos = len(out) - 4
        if ros in ("float64", "int64"):
            out += bytes(-pos % 8)
            out += struct.pack("<d", float(v)) if ros == "float64" else struct.pack("<q", int(v))
        elif ros == "bool":
            out.append(1 if v else 0)
        elif ros == "string":
            text = str(v).encode() + b"\0"
            out += bytes(-pos % 4) + struct.pack("<I", len(text)) + text
        else:  # float64[]
            arr = np.ascontiguousarray(v, dtype="<f8").ravel()
            out += bytes(-pos % 4) + struct.pack("<I", arr.size)
            if arr.size:
                out += bytes(-(len(out) - 4) % 8) + arr.tobytes()
    return bytes(out)
