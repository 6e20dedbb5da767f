"""`tube_mpc` node: the control law of the run (parameter `law`), one step at a time.

Any registered `fahv.control.ControlLaw`: `tube_mpc` and `tube_mpc_paper`,
u = u_r + u_n + tau F (x - x_r - x_n) (eq. 36; the adjustable eq. 54 when `tau` < 1
on the 11-state ECM design), or `rmpc` (the Kothare baseline; also started as the
`rmpc` executable). Publishes the command and the tube status of each step.
"""

from __future__ import annotations

import sys

from hsv_common.lockstep import LockstepNode
from hsv_common.runtime import main

from fahv.lanes import Lanes
from fahv.loop.cores import ControllerCore


class TubeMPCNode(LockstepNode):
    """Adapter of `fahv.loop.ControllerCore`."""

    ROLE = "tube_mpc"

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters."""
        self.core = ControllerCore([p], Lanes(1))

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        cmd, tube = self.core.on_inputs(
            inputs["/hsv/state_estimate"], inputs["/hsv/q_filtered"], inputs["/hsv/nominal"]
        )
        return [("/hsv/tube_status", tube), ("/hsv/control_command", cmd)]


class RMPCNode(TubeMPCNode):
    """The same adapter under node name `rmpc` (parameters of the `rmpc` section)."""

    ROLE = "rmpc"


def run(args=None) -> None:
    """Entry point `ros2 run hsv_ctrl tube_mpc`."""
    sys.exit(main(TubeMPCNode, args))


def run_rmpc(args=None) -> None:
    """Entry point `ros2 run hsv_ctrl rmpc`."""
    sys.exit(main(RMPCNode, args))
