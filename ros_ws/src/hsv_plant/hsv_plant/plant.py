"""`plant` node: nonlinear CM of the vehicle, lockstep master, publisher of /clock.

Publishes /clock, /hsv/state (with the actuator positions; for the record, no controller
node reads it) and /hsv/measurement (its sensors; the state estimator reads it) for step
k, integrates
[t_k, t_k+1] when /hsv/actuator_command of step k arrives (`fahv.loop.PlantCore`:
ideal actuators or the vehicle file's servos, parameter `actuators`), and starts step
0 only when every node of the graph has announced itself on /hsv/ready. With
parameter `rate` r > 0 it publishes step k no earlier than k Ts / r after step 0 (a
graph watched live at real time: r = 1).
"""

from __future__ import annotations

import sys
import time

from hsv_common.lockstep import LockstepNode
from hsv_common.runtime import main

from fahv.lanes import Lanes
from fahv.loop.cores import PlantCore
from fahv.loop.graph import clock_msg


class PlantNode(LockstepNode):
    """Adapter of `fahv.loop.PlantCore`; the lockstep master.

    It is ready (and publishes step 0) only when every other node of the graph
    announced itself ready; until then it logs which peers it still waits for.
    """

    ROLE = "plant"
    WAIT_FOR_PEERS = True

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters.

        The core compiles its integrator and sensor kernels when it is built
        (`fahv.plant.rk4.compile_kernels`), before the node is ready: a compile in a
        step would leave every peer waiting past its watchdog.
        """
        self.core = PlantCore([p], Lanes(1))
        self.rate = float(p["rate"])  # 0: as fast as the graph steps
        self.t_ready = 0.0

    def _publish_state(self) -> list:
        """/clock, the true state (for the record) and the measurement the estimator reads."""
        k = self.core.k
        state = self.core.state()
        return [("/clock", clock_msg(k, self.Ts)), ("/hsv/state", state),
                ("/hsv/measurement", self.core.measurement())]  # fmt: skip

    def on_ready(self) -> None:
        """Every peer is ready: publish the state and the measurement of step 0."""
        self.get_logger().info(f"graph ready ({len(self.graph_nodes) - 1} peers): step 0")
        self.t_ready = time.monotonic()
        self.publish(self._publish_state())

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        self.core.advance(inputs["/hsv/actuator_command"])
        if self.rate > 0.0:  # paced: step k + 1 no earlier than its time / rate after step 0
            wait = self.t_ready + self.core.k * self.Ts / self.rate - time.monotonic()
            if wait > 0.0:
                time.sleep(wait)
        return self._publish_state() if self.core.k < self.n_steps else []


def run(args=None) -> None:
    """Entry point `ros2 run hsv_plant plant`."""
    sys.exit(main(PlantNode, args))
