"""``plant`` node: nonlinear CM of the vehicle, lockstep master, publisher of /clock.

Publishes /clock and /hsv/state for step k, integrates [t_k, t_k+1] when
/hsv/actuator_command of step k arrives (``fahv.loop.PlantCore``), and starts step 0
only when every node of the graph has announced itself on /hsv/ready.
"""

from __future__ import annotations

import sys
import time

from hsv_common.lockstep import READY_QOS, LockstepNode, WatchdogError, main, to_msg
from std_msgs.msg import String

from fahv.lanes import Lanes
from fahv.loop.cores import PlantCore
from fahv.loop.graph import clock_msg


class PlantNode(LockstepNode):
    """Adapter of :class:`fahv.loop.PlantCore`."""

    ROLE = "plant"

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters."""
        self.core = PlantCore([p], Lanes(1))
        self.peers_ready: set[str] = set()
        self.create_subscription(String, "/hsv/ready", self._peer_ready, READY_QOS)

    def _peer_ready(self, msg: String) -> None:
        self.peers_ready.add(msg.data)

    def _publish_state(self) -> list:
        k = self.core.k
        return [("/clock", clock_msg(k, self.Ts)), ("/hsv/state", self.core.state())]

    def poll(self) -> None:
        """Start step 0 once every peer is ready; afterwards the watchdog.

        Raises
        ------
        ForeignGraphError
            If another graph publishes in the domain (checked before step 0).
        WatchdogError
            If the graph is not ready within max(60 s, watchdog_s).
        """
        if not self.ready:
            self.check_foreign(time.monotonic())
            waiting = [n for n in self.graph_nodes if n != "plant" and n not in self.peers_ready]
            if self.matched() or waiting:
                if time.monotonic() - self.last_progress > max(60.0, self.watchdog_s):
                    raise WatchdogError(
                        f"plant: graph not ready after {max(60.0, self.watchdog_s):g} s; "
                        f"waiting for {waiting or self.matched()}"
                    )
                return
            self.check_foreign()
            self.ready = True
            self.get_logger().info(f"graph ready ({len(self.peers_ready)} peers): step 0")
            self.last_progress = self.t_ready = time.monotonic()
            for topic, fields in self._publish_state():
                self.pubs[topic].publish(to_msg(topic, fields))
            return
        self.check_watchdog()

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        self.core.advance(inputs["/hsv/actuator_command"])
        return self._publish_state() if self.core.k < self.n_steps else []


def run(args=None) -> None:
    """Entry point ``ros2 run hsv_plant plant``."""
    sys.exit(main(PlantNode, args))
