"""The generated ROS message class of each loop topic.

The nodes publish and receive the loop messages as CDR bytes, converted by the library's
one codec (`fahv.sil.wire.encode`, `fahv.sil.wire.decode_message`);
rclpy still needs each topic's generated class to create its publishers and
subscriptions, and this module names it.
"""

from __future__ import annotations

import functools

from fahv.loop.graph import TOPICS


@functools.cache
def msg_type_of(topic: str):
    """ROS message class of a loop topic (rosgraph_msgs/Clock for `/clock`).

    Raises
    ------
    KeyError
        If `topic` is not a loop topic of `fahv.loop.graph.TOPICS`.
    ImportError
        If the message package is not built (`bash scripts/build_ros.sh`).
    """
    pkg, _, name = TOPICS[topic].split("/")
    module = __import__(f"{pkg}.msg", fromlist=[name])
    return getattr(module, name)
