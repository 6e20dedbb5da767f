"""`state_estimator` node: the state estimate x_k|k from the measurement y_k.

Runs the run's estimator (parameter `estimator`, `fahv.loop.EstimatorCore`): `none`
passes the exact state of the plant's full-state sensor through (the paper's loop),
`kalman` the gain-scheduled Kalman filter of `fahv.estimation` on the measured
channels. It takes the controller's command of the previous step for its prediction,
and publishes /hsv/state_estimate, which the notch, the nominal trajectory and the
controller read.
"""

from __future__ import annotations

import sys

from hsv_common.lockstep import LockstepNode
from hsv_common.runtime import main

from fahv.lanes import Lanes
from fahv.loop.cores import EstimatorCore


class StateEstimatorNode(LockstepNode):
    """Adapter of `fahv.loop.EstimatorCore`."""

    ROLE = "state_estimator"

    def make_core(self, p: dict) -> None:
        """Build the library object from the raw node parameters."""
        self.core = EstimatorCore([p], Lanes(1))

    def on_step(self, k: int, inputs: dict) -> list:
        """Outputs of step k (see LockstepNode.on_step)."""
        est = self.core.on_measurement(inputs["/hsv/measurement"], inputs["/hsv/control_command"])
        return [("/hsv/state_estimate", est)]


def run(args=None) -> None:
    """Entry point `ros2 run hsv_ctrl state_estimator`."""
    sys.exit(main(StateEstimatorNode, args))
