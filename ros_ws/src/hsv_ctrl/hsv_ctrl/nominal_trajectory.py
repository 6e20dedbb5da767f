"""``nominal_trajectory`` node: reference x_r, u_r and nominal x_n, u_n of each step.

Mode ``governor``: nominal system under u_n = K x_n (eq. 20/46) with the reference
governor; mode ``command``: trim of the raw command (the RMPC baseline).
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
        return [("/hsv/nominal", self.core.on_state(inputs["/hsv/state"]))]


def run(args=None) -> None:
    """Entry point ``ros2 run hsv_ctrl nominal_trajectory``."""
    sys.exit(main(NominalTrajectoryNode, args))
