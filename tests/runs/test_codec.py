"""The ROS codec of the nodes (hsv_common.codec): typed message -> ROS message -> typed
message gives back every field exactly (values, dtypes, shapes), for every loop topic.

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
from hsv_common.codec import from_msg, msg_type_of, to_msg
from fahv.loop.graph import TOPICS
from fahv.msg import MESSAGES

rng = np.random.default_rng(7)
n = 0
for topic, ros_type in TOPICS.items():
    if ros_type not in MESSAGES:  # /clock: not a typed message
        continue
    cls = MESSAGES[ros_type]
    values = {}
    for name, ros, _ in cls.ros_fields():
        if name == "k":
            values[name] = 12345
        elif name == "t":
            values[name] = 246.9
        elif ros == "float64":
            values[name] = rng.normal(size=1) * 1e3
        elif ros == "int64":
            values[name] = rng.integers(-(2**40), 2**40, size=1)
        elif ros == "bool":
            values[name] = rng.integers(0, 2, size=1).astype(bool)
        elif ros == "string":
            values[name] = ("tube_mpc",)
        else:  # float64[]
            values[name] = rng.normal(size=(1, int(rng.integers(0, 12))))
    typed = cls(**values)
    back = from_msg(topic, to_msg(topic, typed))
    assert type(back) is cls, (topic, type(back))
    for name, _, _ in cls.ros_fields():
        a, b = getattr(typed, name), getattr(back, name)
        if isinstance(a, np.ndarray):
            assert isinstance(b, np.ndarray) and b.dtype == a.dtype, (topic, name, b)
            assert b.shape == a.shape and np.array_equal(a, b), (topic, name, a, b)
        else:
            assert type(b) is type(a) and b == a, (topic, name, a, b)
    n += 1
print("round trips", n)
"""


def test_every_loop_message_round_trips_exactly():
    ensure_built()
    r = subprocess.run(
        [sys.executable, "-c", SCRIPT], env=ros_env(), capture_output=True, text=True, timeout=120
    )
    assert r.returncode == 0, r.stderr[-3000:]
    assert r.stdout.strip() == "round trips 7"
