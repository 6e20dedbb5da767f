"""``nominal_trajectory`` node: reference x_r, u_r and nominal x_n, u_n of each step.

Mode ``mpc``: online tracking MPC with an input-disturbance estimate (it takes the
controller's command of the previous step); mode ``governor``: nominal system under
u_n = K x_n (eq. 20/46) with the reference governor; mode ``command``: trim of the raw
command (the RMPC baseline).
"""

from __future__ import annotations

import sys

from hsv_common.lockstep import LockstepNode, main

from fahv.loop.cores import NominalCore


class NominalTrajectoryNode(LockstepNode):
    """Adapter of :class:`fahv.loop.NominalCore`."""

    ROLE = "nominal_trajectory"

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters."""
        self.core = NominalCore(p)

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        nominal = self.core.on_state(inputs["/hsv/state"], inputs["/hsv/control_command"])
        return [("/hsv/nominal", nominal)]


def run(args=None) -> None:
    """Entry point ``ros2 run hsv_ctrl nominal_trajectory``."""
    sys.exit(main(NominalTrajectoryNode, args))
