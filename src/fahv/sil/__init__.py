"""The SIL graph's runtime on the library's side: its protocol, wire format and runner.

What the ROS 2 node graph needs beyond the numerics the nodes share with the in-process
simulation (`fahv.loop`), written once and imported by the nodes (`ros_ws/src/hsv_common`,
`hsv_bringup`) and by the commands; no ROS code here (the nodes hold it):

- `fahv.sil.wire`: the one codec of the loop topics, typed messages <-> CDR bytes;
- `fahv.sil.peers`: the rules of the graph's status protocol: readiness, missing and lost
  peers, a run's verdict, a foreign graph in the same domain;
- `fahv.sil.tool_nodes`: the parameters of the recorder and the replay nodes;
- `fahv.sil.workspace`: the colcon workspace, built on source change, and its environment;
- `fahv.sil.runner`: `fahv sil`'s runner: the run's parameter file, the graph started in
  its own DDS domain, interrupted cleanly, its run file read back.

The protocol as a whole (lockstep, readiness, verdict, watchdog, teardown) is the
reference page docs/reference/sil_protocol.md.
"""
