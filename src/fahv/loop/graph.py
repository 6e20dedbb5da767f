r"""The SIL graph, written once: loop topics, their message types, and the node table.

One control step k (t_k = k Ts) flows through the nodes in this order:

    plant --y_k--> state_estimator --x_k|k--> notch_filter --q'_k--> tube_mpc --u_k-->
        fault_injector --u_f,k--> plant;  x_k|k --> nominal_trajectory --(x_r, u_r, x_n, u_n)_k
        --> tube_mpc;  u_k-1 --> state_estimator, nominal_trajectory

The plant also publishes its true state x_k (/hsv/state), which the recorder keeps for
analysis and no controller node reads: the flight computer's nodes see the vehicle only
through the measurement y_k and the estimate x_k|k.

`NODES` is the only description of the graph: the ROS nodes take their topics
from it, the SIL runner its executables and start order, the recorder its topics,
`fahv.loop.simulate.simulate` its call order, and `docs/reference/architecture.md` its
table (`markdown_table`, checked by a test).
"""

from __future__ import annotations

from dataclasses import dataclass

from fahv.errors import RunError
from fahv.msg import PKG, VehicleState

#: Loop topics -> ROS 2 message type, in the order of one control step.
TOPICS = {
    "/clock": "rosgraph_msgs/msg/Clock",
    "/hsv/state": f"{PKG}/msg/VehicleState",
    "/hsv/measurement": f"{PKG}/msg/Measurement",
    "/hsv/state_estimate": f"{PKG}/msg/StateEstimate",
    "/hsv/q_filtered": f"{PKG}/msg/FilteredPitchRate",
    "/hsv/nominal": f"{PKG}/msg/NominalTrajectory",
    "/hsv/control_command": f"{PKG}/msg/ControlCommand",
    "/hsv/tube_status": f"{PKG}/msg/TubeStatus",
    "/hsv/actuator_command": f"{PKG}/msg/ControlCommand",
    "/hsv/fault_status": f"{PKG}/msg/FaultStatus",
}

#: History depth of the loop topics' QoS: reliable, keep-last, volatile. The loop
#: nodes wait for each other (lockstep), the recorder does not: with a reliable
#: keep-last writer, a reader more than QOS_DEPTH steps behind loses samples. At
#: about 2 ms per step a depth of 50 (0.1 s) lost 4 steps of a 15000-step run; 2000
#: steps (4 s of lag, a few MB of writer history) keeps every message.
QOS_DEPTH = 2000


@dataclass(frozen=True)
class QoS:
    """A DDS quality-of-service profile, as numbers (the library imports no ROS code).

    History is always keep-last; liveliness automatic, deadlines and lifespans
    infinite. `hsv_common` turns it into an `rclpy` profile, the run writer into
    the `offered_qos_profiles` of each MCAP channel.

    Attributes
    ----------
    depth : int
        Keep-last history depth [messages].
    reliable : bool
        Reliable (True) or best-effort delivery.
    transient_local : bool
        Late joiners get the writer's history (True) or only new messages.
    """

    depth: int
    reliable: bool = True
    transient_local: bool = False


#: QoS of every loop topic: reliable, keep-last `QOS_DEPTH`, volatile.
LOOP_QOS = QoS(QOS_DEPTH)

#: Topic on which every node of a graph publishes its status (std_msgs/String, JSON of
#: `fahv.loop.graph.node_status`): once when it starts, on every change of state,
#: and every `STATUS_PERIOD_S` as a heartbeat. Readiness, the start of step 0, the
#: name of a missing or lost peer and the foreign-graph check all read it.
STATUS_TOPIC = "/hsv/node_status"
#: QoS of `STATUS_TOPIC`: reliable, transient local, the latest statuses of each node
#: (a node that joins later still learns the state of every peer).
STATUS_QOS = QoS(20, reliable=True, transient_local=True)
#: Heartbeat period of the node status [s wall time].
STATUS_PERIOD_S = 1.0
#: A peer whose latest status is older than this is lost (process gone) [s wall time].
STATUS_LOST_S = 4.0


@dataclass(frozen=True)
class NodeSpec:
    """One node of the graph.

    Attributes
    ----------
    name : str
        Node name and executable name (`<prefix>/lib/<package>/<name>`).
    package : str
        ROS 2 package that installs the executable.
    inputs, outputs : tuple of str
        Loop topics consumed and produced at each step (keys of `TOPICS`).
    previous : tuple of str
        Loop topics consumed from the previous step k - 1 (none at k = 0).
    kind : {"loop", "controller", "recorder", "replay"}
        Loop nodes and the controller run every step; the recorder and the replay
        are tools around the loop.
    description : str
        What the node does (one line, with the paper's equations).
    """

    name: str
    package: str
    inputs: tuple[str, ...]
    outputs: tuple[str, ...]
    kind: str
    description: str
    previous: tuple[str, ...] = ()


_CONTROLLER_IN = ("/hsv/state_estimate", "/hsv/q_filtered", "/hsv/nominal")
_CONTROLLER_OUT = ("/hsv/control_command", "/hsv/tube_status")

#: The node table, in start order (the plant starts last: it is the lockstep master).
NODES: dict[str, NodeSpec] = {
    n.name: n
    for n in (
        NodeSpec("recorder", "hsv_bringup", tuple(TOPICS), (), "recorder",
                 "every loop topic, raw CDR, into one rosbag2/MCAP run"),
        NodeSpec("state_estimator", "hsv_ctrl", ("/hsv/measurement",), ("/hsv/state_estimate",),
                 "loop", "state estimate from the measurement: gain-scheduled Kalman filter "
                 "on the LPV model (eq. 11-12), or the exact state of a full-state sensor",
                 previous=("/hsv/control_command",)),
        NodeSpec("notch_filter", "hsv_ctrl", ("/hsv/state_estimate",), ("/hsv/q_filtered",),
                 "loop", "notch filter on the estimate's q (eq. 37-39): q -> q'"),
        NodeSpec("nominal_trajectory", "hsv_ctrl", ("/hsv/state_estimate",), ("/hsv/nominal",),
                 "loop",
                 "the law's nominal part: nominal MPC (QP) with disturbance estimate, reference "
                 "governor (eq. 20/46) or the command's trim",
                 previous=("/hsv/control_command",)),
        NodeSpec("tube_mpc", "hsv_ctrl", _CONTROLLER_IN, _CONTROLLER_OUT, "controller",
                 "control law of the run (eq. 36 / 54), tube status"),
        NodeSpec("rmpc", "hsv_ctrl", _CONTROLLER_IN, _CONTROLLER_OUT, "controller",
                 "the controller node under the name of the RMPC baseline"),
        NodeSpec("fault_injector", "hsv_plant", ("/hsv/control_command",),
                 ("/hsv/actuator_command", "/hsv/fault_status"), "loop",
                 "actuator faults between controller and plant (eq. 15 ...)"),
        NodeSpec("plant", "hsv_plant", ("/hsv/actuator_command",),
                 ("/clock", "/hsv/state", "/hsv/measurement"), "loop",
                 "nonlinear CM (eq. 1-3) with its actuators (ideal or servos) and sensors, "
                 "RK4, lockstep master, /clock"),
        NodeSpec("replay", "hsv_bringup", tuple(TOPICS), tuple(TOPICS), "replay",
                 "republishes a recorded run (raw CDR), captures outputs"),
    )
}  # fmt: skip

#: node -> (input topics, output topics) of one control step (inputs of step k - 1 included).
GRAPH = {n.name: (n.inputs + n.previous, n.outputs) for n in NODES.values()}
#: node -> topics it takes from the previous step.
PREVIOUS = {n.name: n.previous for n in NODES.values()}
#: Names of the controller node (one adapter, two executable names).
CONTROLLER_NODES = tuple(n.name for n in NODES.values() if n.kind == "controller")


def graph_nodes(controller: str = "tube_mpc", record: bool = True) -> list[str]:
    """Nodes of one run in start order: the loop, the controller node, the recorder.

    Raises
    ------
    RunError
        If `controller` is not one of `CONTROLLER_NODES`.
    """
    if controller not in CONTROLLER_NODES:
        raise RunError(f"controller node must be one of {CONTROLLER_NODES}, got {controller!r}")
    keep = {"loop"} | ({"recorder"} if record else set())
    return [n.name for n in NODES.values() if n.kind in keep or n.name == controller]


#: Nodes of the full graph in start order, the default of parameter `graph_nodes`.
DEFAULT_GRAPH = graph_nodes()


def producer_of(topic: str, nodes=None) -> str:
    """Name of the loop node that publishes `topic` (among `nodes`; '?' if none)."""
    for n in NODES.values():
        if n.kind != "replay" and topic in n.outputs and (nodes is None or n.name in nodes):
            return n.name
    return "?"


def loop_nodes(names=None) -> list[str]:
    """The loop and controller nodes among `names` (default: the table's), in their order.

    These are the nodes that exchange the loop topics step by step: the ones a replay
    can test and the `loop` process can compose (not the recorder or replay).

    Examples
    --------
    >>> loop_nodes(["recorder", "state_estimator", "tube_mpc", "plant"])
    ['state_estimator', 'tube_mpc', 'plant']
    """
    names = list(NODES) if names is None else names
    return [n for n in names if NODES[n].kind in ("loop", "controller")]


def replay_topics(nodes) -> tuple[list[str], list[str]]:
    """(inputs to replay, outputs to capture) for testing `nodes` against a run.

    The inputs are the loop topics the nodes consume and do not produce themselves;
    the outputs are what they produce.

    Raises
    ------
    RunError
        On a node that is not a loop node of `NODES`.
    """
    testable = sorted(loop_nodes())
    unknown = [n for n in nodes if n not in testable]
    if unknown:
        raise RunError(f"cannot replay into {unknown}: nodes are {testable}")
    produced = [t for n in nodes for t in GRAPH[n][1]]
    consumed = [t for n in nodes for t in GRAPH[n][0]]
    inputs = [t for t in TOPICS if t in consumed and t not in produced]
    return inputs, [t for t in TOPICS if t in produced]


def markdown_table() -> str:
    """The node table as Markdown (the table of `docs/reference/architecture.md`)."""
    rows = ["| node | package | consumes | produces | does |", "|---|---|---|---|---|"]
    for n in NODES.values():
        cons = (
            "every loop topic"
            if n.inputs == tuple(TOPICS)
            else ", ".join(n.inputs + tuple(f"{t} (step k-1)" for t in n.previous))
        )
        prod = "every loop topic" if n.outputs == tuple(TOPICS) else ", ".join(n.outputs)
        rows.append(f"| `{n.name}` | {n.package} | {cons} | {prod or '-'} | {n.description} |")
    return "\n".join(rows)


#: Field names of VehicleState after k, t, in plant state order (eq. 1-3).
STATE_FIELDS = VehicleState.STATE


def n_steps_of(p: dict) -> int:
    """Number of control steps of a run: round(duration / Ts)."""
    return int(round(p["duration"] / p["Ts"]))


def clock_msg(k: int, Ts: float) -> dict:
    """rosgraph_msgs/Clock of step k: t_k = k Ts in whole nanoseconds."""
    ns = k * int(round(Ts * 1e9))
    return {"clock": {"sec": ns // 1_000_000_000, "nanosec": ns % 1_000_000_000}}


def registry_tables() -> str:
    """The registries of laws, nominal parts, variants and fault kinds as Markdown.

    The tables of `docs/reference/architecture.md` (checked by a test), generated from
    `fahv.control.LAWS`, `fahv.control.NOMINAL_SOURCES`,
    `fahv.control.VARIANTS` and `fahv.plant.faults.FAULTS`.
    """
    from fahv.control import LAWS, NOMINAL_SOURCES, VARIANTS
    from fahv.plant.faults import FAULTS

    def first_line(cls) -> str:
        return (cls.__doc__ or "").strip().splitlines()[0]

    def where(cls) -> str:
        return f"`{cls.__module__}.{cls.__name__}`"

    out = ["| law | class | node | nominal part | tube | design-file section | what |",
           "|---|---|---|---|---|---|---|"]  # fmt: skip
    for name, cls in LAWS.items():
        sec = f"`{cls.section.name}`" if cls.section is not None else "-"
        out.append(
            f"| `{name}` | {where(cls)} | `{cls.node}` | `{cls.nominal.name}` | "
            f"{'yes' if cls.has_tube else 'no'} | {sec} | {first_line(cls)} |"
        )
    out += ["", "| nominal part | class | estimates d | design-file section | what |",
            "|---|---|---|---|---|"]  # fmt: skip
    for name, cls in NOMINAL_SOURCES.items():
        sec = f"`{cls.section.name}`" if cls.section is not None else "-"
        est = "yes" if cls.estimates_disturbance else "no"
        out.append(f"| `{name}` | {where(cls)} | {est} | {sec} | {first_line(cls)} |")
    out += ["", "| variant | law | notch | what |", "|---|---|---|---|"]
    for name, v in VARIANTS.items():
        out.append(f"| `{name}` | `{v.law}` | {v.notch} | {v.description} |")
    out += ["", "| fault kind | class | parameters | what |", "|---|---|---|---|"]
    for name, cls in FAULTS.items():
        params = ", ".join(f"`{f.name}`" for f in cls.parameters) or "-"
        out.append(f"| `{name}` | {where(cls)} | {params} | {first_line(cls)} |")
    return "\n".join(out)


#: Line a node process prints (`[name] closed with exit status S; DDS teardown`) after
#: its close, before the DDS teardown that a C-level timer bounds (hsv_common.runtime).
TEARDOWN_MARK = "closed with exit status"
#: Name of the process (and executable, package hsv_bringup) that runs loop nodes
#: composed in one process (`sil --compose`; hsv_bringup.composed).
COMPOSED = "loop"


def teardown_hung(log: str) -> int | None:
    """The node's own exit status if its log shows a hung DDS teardown, else None.

    `log` is the node's output; a hung teardown is the line `[name] closed with exit
    status S; DDS teardown` followed by faulthandler's `Timeout (...)!` dump.
    """
    i = log.rfind(TEARDOWN_MARK)
    if i < 0 or "Timeout (" not in log[i:]:
        return None
    try:
        return int(log[i + len(TEARDOWN_MARK) :].split(";")[0])
    except ValueError:
        return None
