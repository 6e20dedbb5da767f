"""The node process runtime (hsv_common.runtime): a main thread stuck in a C call ends
with status 1 and every thread's traceback (the hang guard), a beating loop does not,
and the executor choice names a bad ``HSV_EXECUTOR``.

Runs in a child process with the built workspace sourced, like the nodes themselves.
"""

import subprocess
import sys
import time

import pytest

from fahv.sil.workspace import ensure_built, ros_env

pytestmark = pytest.mark.ros  # imports hsv_common from the built workspace

STUCK = r"""
import time
from hsv_common.runtime import HangGuard
g = HangGuard()
g.arm(1.5)
time.sleep(30)  # the main thread never comes back to the loop
print("not reached")
"""

BEATING = r"""
import time
from hsv_common.runtime import HangGuard
g = HangGuard()
g.arm(1.5)
t0 = time.monotonic()
while time.monotonic() - t0 < 4.0:  # 4 s > the deadline, but re-armed every 0.1 s
    g.beat()
    time.sleep(0.1)
g.cancel()
time.sleep(2.0)  # no deadline any more
print("done")
"""

EXECUTOR = r"""
import os
import rclpy
from hsv_common.runtime import make_executor
from fahv.errors import ParameterError
rclpy.init()
print(type(make_executor()).__name__)
os.environ["HSV_EXECUTOR"] = "single"
print(type(make_executor()).__name__, type(make_executor(message_info=True)).__name__)
os.environ["HSV_EXECUTOR"] = "fast"
try:
    make_executor()
except ParameterError as exc:
    print("error:", exc)
rclpy.shutdown()
"""


def _run(script: str, timeout: float = 60.0):
    env = ros_env()
    env.pop("HSV_EXECUTOR", None)
    t0 = time.monotonic()
    r = subprocess.run(
        [sys.executable, "-c", script], env=env, capture_output=True, text=True, timeout=timeout
    )
    return r, time.monotonic() - t0


def test_a_stuck_main_thread_ends_with_status_1_and_its_traceback():
    ensure_built()
    r, wall = _run(STUCK)
    assert r.returncode == 1, (r.returncode, r.stderr[-2000:])
    assert "not reached" not in r.stdout
    assert "Timeout (0:00:01" in r.stderr and "<string>" in r.stderr, r.stderr[-2000:]
    assert wall < 15.0  # ended by the 1.5 s deadline, not by the 30 s sleep


def test_a_beating_loop_is_not_ended_and_cancel_removes_the_deadline():
    ensure_built()
    r, _ = _run(BEATING)
    assert r.returncode == 0, r.stderr[-2000:]
    assert r.stdout.strip() == "done"


def test_the_executor_is_the_events_executor_unless_asked():
    ensure_built()
    r, _ = _run(EXECUTOR)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.strip().splitlines()
    assert lines[0] == "EventsExecutor"
    assert lines[1] == "SingleThreadedExecutor SingleThreadedExecutor"
    assert lines[2].startswith("error: HSV_EXECUTOR = 'fast'"), lines
