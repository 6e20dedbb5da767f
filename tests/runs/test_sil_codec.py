"""The nodes' wire codec (hsv_common.codec.encode / decode): the CDR bytes the nodes write
are read back by rclpy's own deserialization, and the bytes rclpy writes are decoded by
the nodes, both into exactly the typed message (values, dtypes, shapes), for every loop
topic, with empty and non-empty arrays and strings.

Runs in a child process with the built workspace sourced (the generated message
classes live there), like the nodes themselves.
"""

import subprocess
import sys

import pytest

from fahv.runs.workspace import ensure_built, ros_env

pytestmark = pytest.mark.ros  # imports the built hsv_interfaces messages

SCRIPT = r"""
import numpy as np
from rclpy.serialization import deserialize_message, serialize_message
from hsv_common.codec import decode, encode, from_msg, msg_type_of, step_of, to_msg
from fahv.loop.graph import TOPICS, clock_msg
from fahv.msg import MESSAGES

rng = np.random.default_rng(11)
n = 0
for trial in range(50):
    for topic, ros_type in TOPICS.items():
        if ros_type not in MESSAGES:  # /clock: below
            continue
        cls = MESSAGES[ros_type]
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
        typed = cls(**values)
        ours = encode(topic, typed)
        theirs = serialize_message(to_msg(topic, typed))
        assert step_of(ours) == step_of(theirs) == typed.k
        for back in (from_msg(topic, deserialize_message(ours, msg_type_of(topic))),
                     decode(topic, theirs)):
            assert type(back) is cls, (topic, type(back))
            for name, _, _ in cls.ros_fields():
                a, b = getattr(typed, name), getattr(back, name)
                if isinstance(a, np.ndarray):
                    assert isinstance(b, np.ndarray) and b.dtype == a.dtype, (topic, name, b)
                    assert b.shape == a.shape and np.array_equal(a, b), (topic, name, a, b)
                else:
                    assert type(b) is type(a) and b == a, (topic, name, a, b)
        n += 1
clock = clock_msg(1234, 0.02)
assert encode("/clock", clock) == serialize_message(to_msg("/clock", clock))
print("checked", n)
"""


def test_the_wire_codec_agrees_with_rclpy_both_ways():
    ensure_built()
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=ros_env(), capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.strip() == "checked 350"
