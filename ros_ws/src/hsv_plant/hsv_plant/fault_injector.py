"""`fault_injector` node: actuator faults between the controller and the plant.

Loss of elevator effectiveness (rho_f, onset, eq. 15), stuck elevator, elevator bias,
dropped commands and an elevator hardover to a position limit (`kind` parameter),
applied by `fahv.loop.FaultCore`; the fault applied at every step is announced on
/hsv/fault_status.
"""

from __future__ import annotations

import sys

from hsv_common.lockstep import LockstepNode
from hsv_common.runtime import main

from fahv.lanes import Lanes
from fahv.loop.cores import FaultCore


class FaultInjectorNode(LockstepNode):
    """Adapter of `fahv.loop.FaultCore`."""

    ROLE = "fault_injector"

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters."""
        self.core = FaultCore([p], Lanes(1))
        self.announced = False

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        act, status = self.core.on_command(inputs["/hsv/control_command"])
        if status.active[0] and not self.announced:
            self.announced = True
            self.get_logger().warning(f"fault {status.kind[0]} active from t = {status.t:.2f} s")
        return [("/hsv/fault_status", status), ("/hsv/actuator_command", act)]


def run(args=None) -> None:
    """Entry point `ros2 run hsv_plant fault_injector`."""
    sys.exit(main(FaultInjectorNode, args))
