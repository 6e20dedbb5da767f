"""Parameters of the tool nodes around the loop: the recorder and the replay.

Declared in the configuration language like every loop node's parameters, so the
nodes generate their ROS descriptors from here and validate once at start-up.
"""

from __future__ import annotations

from fahv.config import Field
from fahv.loop.graph import NODES, TOPICS
from fahv.spec.schema import DURATION, TS

_WATCHDOG = Field("watchdog_s", "float", "wall time without any message that ends the run",
                  unit="s", lo=0.1, hi=3600.0, default=10.0)  # fmt: skip
_METADATA = Field("metadata_json", "str", "run metadata as a JSON object", default="{}")

#: Parameters of the `recorder` node.
RECORDER = (
    Field("bag", "str", "run folder to create (bags/<run>; if it exists, the first free "
          "<run>-2, <run>-3 ...)"),
    TS,
    DURATION,
    _WATCHDOG,
    _METADATA,
    Field("params_file", "str", "the run's parameter file, attached to the run file "
          "(empty: none)", default=""),
    Field("live_port", "int", "port of the live view (Foxglove WebSocket server on 127.0.0.1; "
          "0: any free port, -1: no live view)", lo=-1, hi=65535, default=-1),
)  # fmt: skip

#: Parameters of the `replay` node.
REPLAY = (
    Field("run", "str", "run to replay (bag folder or .mcap)"),
    Field("topics", "strs", "topics to republish (default: every loop topic of the run)",
          choices=tuple(TOPICS), default=()),
    Field("rate", "float", "1: recorded timing, r: r times faster, 0: as fast as possible",
          lo=0.0, default=1.0),
    Field("capture", "strs", "topics to capture from the graph (lockstep on them)",
          choices=tuple(TOPICS), default=()),
    Field("out", "str", "run folder to write (replayed + captured); empty: none", default=""),
    Field("wait_for", "strs", "nodes that must be ready (/hsv/node_status) before step 0",
          choices=tuple(NODES), default=()),
    Field("steps", "int", "steps to replay (0: all)", lo=0, default=0),
    _WATCHDOG,
    _METADATA,
)  # fmt: skip
