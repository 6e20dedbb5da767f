"""`loop` executable: several loop nodes composed in one process (ROS 2 composition).

    ros2 run hsv_bringup loop NODE [NODE ...] --ros-args --params-file RUN_PARAMS.yaml

Each NODE (`plant`, `fault_injector`, `state_estimator`, `notch_filter`,
`nominal_trajectory`, `tube_mpc`, `rmpc`) is the same node class its own executable
runs, with its name, parameters and topics; the nodes share one executor, and the
middleware delivers between them within the process, which shortens every hop of a
lockstep step (the speed page of the docs measures it). `sil --compose` starts the
loop this way; the recorder stays a process of its own. Exit status: that of
`hsv_common.runtime.main_composed`.
"""

from __future__ import annotations

import argparse
import importlib
import sys

from rclpy.utilities import remove_ros_args

#: The class of each loop node: (module, class), the ones the node's own executable runs.
NODE_CLASSES = {
    "plant": ("hsv_plant.plant", "PlantNode"),
    "fault_injector": ("hsv_plant.fault_injector", "FaultInjectorNode"),
    "state_estimator": ("hsv_ctrl.state_estimator", "StateEstimatorNode"),
    "notch_filter": ("hsv_ctrl.notch_filter", "NotchFilterNode"),
    "nominal_trajectory": ("hsv_ctrl.nominal_trajectory", "NominalTrajectoryNode"),
    "tube_mpc": ("hsv_ctrl.tube_mpc", "TubeMPCNode"),
    "rmpc": ("hsv_ctrl.tube_mpc", "RMPCNode"),
}


def node_class(name: str) -> type:
    """The `LockstepNode` class of loop node `name`.

    Raises
    ------
    KeyError
        If `name` is not a loop node (`NODE_CLASSES`).
    """
    module, cls = NODE_CLASSES[name]
    return getattr(importlib.import_module(module), cls)


def main(argv: list[str] | None = None) -> int:
    """Compose the nodes named on the command line; returns the exit status."""
    from hsv_common.runtime import EXIT_PARAM, main_composed

    argv = sys.argv if argv is None else argv
    ap = argparse.ArgumentParser(prog="loop", description=__doc__.split("\n\n")[0])
    ap.add_argument("nodes", nargs="+", choices=sorted(NODE_CLASSES), metavar="NODE",
                    help=f"loop nodes to compose: {', '.join(NODE_CLASSES)}")  # fmt: skip
    try:
        args = ap.parse_args(remove_ros_args(argv)[1:])
    except SystemExit as exc:
        return EXIT_PARAM if exc.code else 0
    return main_composed([node_class(n) for n in args.nodes], argv)


def run() -> None:
    """Entry point `ros2 run hsv_bringup loop`."""
    sys.exit(main())
