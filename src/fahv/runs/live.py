"""Live view: the loop topics on a Foxglove WebSocket server while a run runs.

`fahv sil --live` (in the recorder process, which receives every loop message anyway,
so the server adds no DDS reader and stays out of the lockstep) and `fahv simulate
--live` (in process) serve every loop topic through the `foxglove-sdk` server on
localhost: one channel per topic with the `ros2msg` schema (the full definition, as
in the run's MCAP file) and `cdr` message encoding, so the bytes sent are exactly
those recorded. Message timestamps and the server's broadcast time are simulated time
(t_k = k Ts), the log time of the recorded run. Open `ws://localhost:PORT` in
Foxglove ("Open connection", "Foxglove WebSocket") and import the layout
`ros_ws/src/hsv_bringup/config/foxglove_layout.json`.
"""

from __future__ import annotations

from fahv.errors import RunError
from fahv.loop.graph import TOPICS
from fahv.sil.workspace import WS

#: Foxglove's default port for a WebSocket connection.
DEFAULT_PORT = 8765
#: The layout for the loop topics (import it in Foxglove).
LAYOUT = WS / "src" / "hsv_bringup" / "config" / "foxglove_layout.json"


def schema_text(topic: str) -> str:
    """The `ros2msg` schema of a loop topic's type, as the run writer stores it.

    The definition of the type followed by those it uses, in the rosbag2/MCAP
    concatenated form (`MSG:` sections).
    """
    from fahv.sil.wire import typestore

    text, _ = typestore().generate_msgdef(TOPICS[topic], ros_version=2)
    return text


class LiveView:
    """A Foxglove WebSocket server with one channel per loop topic.

    Parameters
    ----------
    port : int
        TCP port on 127.0.0.1; 0 takes a free one (see `port`).
    Ts : float
        Control period [s]: the timestamp of step k is k Ts [ns].
    name : str
        Server name shown by Foxglove.

    Raises
    ------
    RunError
        If `foxglove-sdk` is missing or the server cannot listen on the port.
    """

    def __init__(self, port: int, Ts: float, name: str = "fahv") -> None:
        try:
            import foxglove
            from foxglove import Channel, Schema
            from foxglove.websocket import Capability
        except ImportError as exc:  # pragma: no cover - a dependency of the package
            raise RunError(f"live view needs the foxglove-sdk package: {exc}") from None
        self.Ts_ns = int(round(Ts * 1e9))
        self._context = foxglove.Context()
        try:
            self._server = foxglove.start_server(
                name=name,
                host="127.0.0.1",
                port=int(port),
                capabilities=[Capability.Time],
                supported_encodings=["cdr"],
                context=self._context,
            )
        except Exception as exc:  # the SDK raises its own error types for a busy port
            raise RunError(f"live view: cannot serve on 127.0.0.1:{port}: {exc}") from None
        self._channels = {
            topic: Channel(
                topic,
                message_encoding="cdr",
                schema=Schema(
                    name=TOPICS[topic], encoding="ros2msg", data=schema_text(topic).encode()
                ),
                context=self._context,
            )
            for topic in TOPICS
        }
        self._last_time = -1

    @property
    def port(self) -> int:
        """The TCP port the server listens on."""
        return int(self._server.port)

    @property
    def url(self) -> str:
        """`ws://127.0.0.1:PORT`, to open in Foxglove."""
        return f"ws://127.0.0.1:{self.port}"

    def log(self, topic: str, k: int, data: bytes) -> None:
        """Send the CDR bytes of step k on a loop topic; /clock also sets the server time."""
        t_ns = k * self.Ts_ns
        self._channels[topic].log(bytes(data), log_time=t_ns)
        if topic == "/clock" and t_ns > self._last_time:
            self._last_time = t_ns
            self._server.broadcast_time(t_ns)

    def close(self) -> None:
        """Stop the server (connected clients see the connection close)."""
        self._server.stop()


def live_hint() -> str:
    """How to open the live view in Foxglove, in one line."""
    return (
        "in Foxglove: Open connection > Foxglove WebSocket; layout: "
        f"{LAYOUT.relative_to(WS.parent)}"
    )
