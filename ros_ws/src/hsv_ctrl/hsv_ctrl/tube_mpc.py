"""``tube_mpc`` node: u = u_r + u_n + tau F (x - x_r - x_n) (eq. 36; eq. 54 for tau < 1).

Parameter ``law``: ``tube_mpc`` (eq. 36), ``adjustable`` (eq. 54 on the 11-state ECM
design, factor ``tau``) or ``rmpc`` (the Kothare baseline; also started as the
``rmpc`` executable). Publishes the command and the tube status of each step.
"""

from __future__ import annotations

import sys

from hsv_common.lockstep import LockstepNode, main

from fahv.loop.cores import ControllerCore


class TubeMPCNode(LockstepNode):
    """Adapter of :class:`fahv.loop.ControllerCore`."""

    ROLE = "tube_mpc"

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters."""
        self.core = ControllerCore(p)

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        cmd, tube = self.core.on_inputs(
            inputs["/hsv/state"], inputs["/hsv/q_filtered"], inputs["/hsv/nominal"]
        )
        return [("/hsv/tube_status", tube), ("/hsv/control_command", cmd)]


class RMPCNode(TubeMPCNode):
    """The same adapter under node name ``rmpc`` (parameters of the ``rmpc`` section)."""

    ROLE = "rmpc"


def run(args=None) -> None:
    """Entry point ``ros2 run hsv_ctrl tube_mpc``."""
    sys.exit(main(TubeMPCNode, args))


def run_rmpc(args=None) -> None:
    """Entry point ``ros2 run hsv_ctrl rmpc``."""
    sys.exit(main(RMPCNode, args))
