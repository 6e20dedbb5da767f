"""`notch_filter` node: the notch filter on the pitch rate (eq. 38-39), q -> q'."""

from __future__ import annotations

import sys

from hsv_common.lockstep import LockstepNode
from hsv_common.runtime import main

from fahv.lanes import Lanes
from fahv.loop.cores import NotchCore


class NotchFilterNode(LockstepNode):
    """Adapter of `fahv.loop.NotchCore`."""

    ROLE = "notch_filter"

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters."""
        self.core = NotchCore([p], Lanes(1))

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        return [("/hsv/q_filtered", self.core.on_state(inputs["/hsv/state_estimate"]))]


def run(args=None) -> None:
    """Entry point `ros2 run hsv_ctrl notch_filter`."""
    sys.exit(main(NotchFilterNode, args))
