"""The one wire codec of the loop messages (fahv.sil.wire.encode / decode_message).

In process: every loop message round-trips exactly (values, dtypes, shapes), with empty
and non-empty arrays and strings, and the typed path writes the same bytes as the lane
form the in-process writer uses. In a child process with the built workspace sourced
(the generated classes live there, as for the nodes): rclpy reads the bytes we write as
the message we meant, and we read the bytes rclpy writes as the message it meant.
"""

import inspect
import subprocess
import sys

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from fahv.loop.graph import TOPICS, clock_msg
from fahv.msg import MESSAGES, PKG
from fahv.sil.wire import STANDARD_TYPES, decode_message, encode, step_of, typestore
from fahv.sil.workspace import ensure_built, ros_env


def random_message(cls, rng):
    """A message of one run of ``cls`` with random values (random array/string lengths)."""
    values = {}
    for name, ros, _ in cls.ros_fields():
        if name == "k":
            values[name] = int(rng.integers(0, 2**40))
        elif name == "t":
            values[name] = float(rng.normal() * 100)
        elif ros == "float64":
            values[name] = rng.normal(size=1) * 1e3
        elif ros == "int64":
            values[name] = rng.integers(-(2**40), 2**40, size=1)
        elif ros == "bool":
            values[name] = rng.integers(0, 2, size=1).astype(bool)
        elif ros == "string":
            values[name] = ("tube_mpc"[: int(rng.integers(0, 9))],)
        else:  # float64[]
            values[name] = rng.normal(size=(1, int(rng.integers(0, 12))))
    return cls(**values)


def assert_same(a_msg, b_msg):
    """Every field equal, with the same type, dtype and shape."""
    assert type(b_msg) is type(a_msg)
    for name, _, _ in type(a_msg).ros_fields():
        a, b = getattr(a_msg, name), getattr(b_msg, name)
        if isinstance(a, np.ndarray):
            assert isinstance(b, np.ndarray) and b.dtype == a.dtype, (name, b)
            assert b.shape == a.shape and np.array_equal(a, b), (name, a, b)
        else:
            assert type(b) is type(a) and b == a, (name, a, b)


LOOP_TOPICS = [t for t, ros_type in TOPICS.items() if ros_type in MESSAGES]


@pytest.mark.parametrize("topic", LOOP_TOPICS)
def test_every_loop_message_round_trips_exactly(topic):
    rng = np.random.default_rng(7)
    for _ in range(40):
        typed = random_message(MESSAGES[TOPICS[topic]], rng)
        data = encode(topic, typed)
        assert step_of(topic, data, 20_000_000) == typed.k
        assert encode(topic, typed.lane(0)) == data  # the writer's lane form: same bytes
        assert_same(typed, decode_message(topic, data))


def test_the_clock_carries_its_step():
    data = encode("/clock", clock_msg(14999, 0.02))
    assert step_of("/clock", data, 20_000_000) == 14999


SCRIPT = (
    "import numpy as np\n"
    "from rclpy.serialization import deserialize_message, serialize_message\n"
    "from hsv_common.topics import msg_type_of\n"
    "from fahv.loop.graph import TOPICS, clock_msg\n"
    "from fahv.msg import MESSAGES\n"
    "from fahv.sil.wire import decode_message, encode\n"
    + inspect.getsource(random_message)
    + inspect.getsource(assert_same)
    + r"""
def generated(topic, lane):
    msg = msg_type_of(topic)()
    for name, v in lane.items():
        if isinstance(v, dict):
            for sub, w in v.items():
                setattr(getattr(msg, name), sub, w)
        else:
            setattr(msg, name, v.tolist() if isinstance(v, np.ndarray) else v)
    return msg

rng = np.random.default_rng(11)
n = 0
for trial in range(50):
    for topic, ros_type in TOPICS.items():
        if ros_type not in MESSAGES:
            continue
        typed = random_message(MESSAGES[ros_type], rng)
        reference = generated(topic, typed.lane(0))
        ours = encode(topic, typed)
        assert deserialize_message(ours, msg_type_of(topic)) == reference
        # rclpy's serialize_message leaves padding bytes unset and gives the buffer its
        # estimated size (8-16 bytes longer after an empty sequence); DDS carries the
        # exact length, so its first len(ours) bytes are the message on the wire
        theirs = serialize_message(reference)
        assert len(ours) <= len(theirs) <= len(ours) + 16, topic
        assert_same(typed, decode_message(topic, theirs[: len(ours)]))
        n += 1
clock = clock_msg(1234, 0.02)
assert encode("/clock", clock) == serialize_message(generated("/clock", clock))
print("checked", n)
"""
)


@pytest.mark.ros  # imports the built hsv_interfaces messages
def test_the_codec_agrees_with_rclpy_both_ways():
    ensure_built()
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=ros_env(), capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr[-3000:]
    typed_topics = [t for t, ros_type in TOPICS.items() if ros_type in MESSAGES]
    assert r.stdout.strip() == f"checked {50 * len(typed_topics)}"  # 50 draws of each topic


def test_the_loop_types_are_those_of_ros_2_jazzy():
    """The codec's store (an empty store, the two standard types of `STANDARD_TYPES` and
    the hsv_interfaces messages) gives every loop topic's type the definition (what a run
    file stores as its schema) and the type hash (RIHS01) of rosbags' ROS 2 Jazzy store."""
    jazzy = get_typestore(Stores.ROS2_JAZZY)
    jazzy.register({t: typestore().fielddefs[t] for t in set(TOPICS.values()) if t.startswith(PKG)})
    for msgtype in sorted(set(TOPICS.values())):
        assert typestore().generate_msgdef(msgtype) == jazzy.generate_msgdef(msgtype), msgtype
        assert typestore().hash_rihs01(msgtype) == jazzy.hash_rihs01(msgtype), msgtype
    assert set(STANDARD_TYPES) <= set(jazzy.types)


def test_a_run_recorded_before_the_servo_rates_existed_reads_them_as_nan():
    """/hsv/state of an older run has no `*_rate_peak` fields: they read as NaN, and any
    other missing field is still an error naming it."""
    from fahv.msg import VehicleState

    x, u_a = np.arange(9.0)[None], np.array([[0.2, 0.1]])
    lane = VehicleState.of(3, 0.06, x, u_a, np.array([[0.5, 1.0]])).lane(0)
    assert (lane["phi_a_rate_peak"], lane["delta_e_a_rate_peak"]) == (0.5, 1.0)
    old = {k: v for k, v in lane.items() if not k.endswith("_rate_peak")}
    msg = VehicleState.from_lanes([old])
    assert np.array_equal(msg.x(), x) and np.array_equal(msg.u_a(), u_a)
    assert np.isnan(msg.rate_peak()).all() and msg.rate_peak().shape == (1, 2)
    with pytest.raises(KeyError, match="delta_e_a"):
        VehicleState.from_lanes([{k: v for k, v in old.items() if k != "delta_e_a"}])
