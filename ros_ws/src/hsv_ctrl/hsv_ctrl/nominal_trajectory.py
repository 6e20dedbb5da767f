"""`nominal_trajectory` node: reference x_r, u_r and nominal x_n, u_n of each step.

Runs the nominal part of the run's law (parameter `nominal`, a registered
`fahv.control.NominalSource`: `mpc` the online tracking MPC with its disturbance
estimate, `governor` the paper's nominal system with the reference governor,
`command` the trim of the raw command for the RMPC baseline). It takes the
controller's command of the previous step as well as the state.
"""

from __future__ import annotations

import sys

from hsv_common.lockstep import LockstepNode
from hsv_common.runtime import main

from fahv.lanes import Lanes
from fahv.loop.cores import NominalCore


class NominalTrajectoryNode(LockstepNode):
    """Adapter of `fahv.loop.NominalCore`."""

    ROLE = "nominal_trajectory"

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters."""
        self.core = NominalCore([p], Lanes(1))

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        nominal = self.core.output(inputs["/hsv/state_estimate"], inputs["/hsv/control_command"])
        return [("/hsv/nominal", nominal)]

    def after_publish(self, k: int) -> None:
        """The nominal's advance to step k + 1, once step k's output is on its way."""
        self.core.advance()


def run(args=None) -> None:
    """Entry point `ros2 run hsv_ctrl nominal_trajectory`."""
    sys.exit(main(NominalTrajectoryNode, args))
