"""What a node of the SIL graph knows about its peers: readiness, missing nodes, foreign graphs.

Every node of a graph publishes its status on `fahv.loop.graph.STATUS_TOPIC`
(a JSON object, `status`) when it starts, whenever its state changes, and every
`fahv.loop.graph.STATUS_PERIOD_S` as a heartbeat; it exits with a last status
that carries its exit status and reason. `Peers` keeps the latest status of
every node instance it heard of and answers, from them alone (no ROS code here, so
the rules are tested without a graph):

- which nodes of the graph are not ready yet, and why (`Peers.not_ready`);
- which nodes are missing: never started, exited, or lost (no heartbeat for
  `fahv.loop.graph.STATUS_LOST_S`), `Peers.missing`; a node whose input
  stays silent names these, not the neighbour that waits for them as well;
- whether a peer ended the run with a verdict (`Peers.run_verdict`,
  `fahv.verdict`): every node then stops with it, and the recorder finishes the
  file with it;
- whether another graph runs in the same ROS domain and which of the two joined
  second (`Peers.foreign_verdict`). Nodes of one graph share a run id (parameter
  `run_id`, written by `fahv sil` for every node); a graph joined when its first
  node started.

A status:

    {"node": "plant", "pid": 4242, "run": "case1_tube_mpc_sil_...", "start": 1.7e9,
     "state": "ready", "k": 0, "stamp": 1.7e9, "waiting": [], "exit": None, "reason": "",
     "verdict": None}

`start` and `stamp` are wall-clock times [s] (`time.time()`; the graph runs on
one host). `state` is one of `STATES`.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field

from fahv.loop.graph import STATUS_LOST_S
from fahv.verdict import Verdict

#: States of a node, in order: building its core and matching its topics, every topic
#: matched, stepping, after its last step, gone (with an exit status).
STATES = ("starting", "ready", "running", "done", "exited")


def status(
    node: str,
    pid: int,
    run: str,
    start: float,
    state: str,
    k: int = 0,
    waiting=(),
    exit_status: int | None = None,
    reason: str = "",
    stamp: float | None = None,
    verdict: dict | None = None,
) -> str:
    """One status message as JSON text (the `data` of a std_msgs/String).

    Parameters
    ----------
    node : str
        Node name.
    pid : int
        Process id (tells two instances of one name apart).
    run : str
        Run id of the node's graph ("" when the parameter file sets none).
    start : float
        Wall time when the node started [s].
    state : str
        One of `STATES`.
    k : int
        Current step.
    waiting : sequence of str
        What the node still waits for (unmatched topics, peers).
    exit_status : int, optional
        Exit status, with `state` "exited".
    reason : str
        Why it exited (the error message), or what it waits for.
    stamp : float, optional
        Wall time of this status [s]; now by default.
    verdict : dict, optional
        The verdict that ended the run (`fahv.verdict.Verdict.as_dict`), found by this
        node or learnt from a peer: in every status from then on, the exit's included.

    Raises
    ------
    ValueError
        On an unknown state.
    """
    if state not in STATES:
        raise ValueError(f"node state must be one of {STATES}, got {state!r}")
    return json.dumps(
        {
            "node": node,
            "pid": int(pid),
            "run": run,
            "start": float(start),
            "state": state,
            "k": int(k),
            "stamp": time.time() if stamp is None else float(stamp),
            "waiting": list(waiting),
            "exit": exit_status,
            "reason": reason,
            "verdict": verdict,
        }
    )


def parse_status(text: str) -> dict | None:
    """A status from JSON text; None if it is not one (another program's message)."""
    try:
        s = json.loads(text)
    except ValueError:
        return None
    keys = ("node", "pid", "run", "start", "state", "k", "stamp")
    if not isinstance(s, dict) or any(k not in s for k in keys) or s["state"] not in STATES:
        return None
    return s


def _clock(t: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(t))


@dataclass
class Peers:
    """The latest status of every node instance heard of, seen from one node.

    Parameters
    ----------
    node : str
        Name of the node that keeps the table.
    pid : int
        Its process id.
    run : str
        Its run id.
    start : float
        Its start [s wall time].
    graph_nodes : sequence of str
        Nodes of its graph (parameter `graph_nodes`).
    lost_s : float
        A peer whose latest status is older than this is lost [s].
    """

    node: str
    pid: int
    run: str
    start: float
    graph_nodes: list
    lost_s: float = STATUS_LOST_S
    table: dict = field(default_factory=dict)
    #: Count of changes of `table` by `update` (keys the cache of `failed`).
    version: int = field(default=0, init=False, compare=False)
    _failed: tuple = field(default=(-1, ()), init=False, repr=False, compare=False)

    def update(self, s: dict | None) -> bool:
        """Take one status; True if it is news (a new instance or another state)."""
        if s is None or (s["node"] == self.node and s["pid"] == self.pid):
            return False
        key = (s["node"], s["pid"], s["run"])
        old = self.table.get(key)
        if old is not None and old["stamp"] > s["stamp"]:
            return False
        self.table[key] = s
        self.version += 1
        return old is None or old["state"] != s["state"]

    def alive(self, s: dict, now: float | None = None) -> bool:
        """True if the instance has not exited and its heartbeat is recent."""
        now = time.time() if now is None else now
        return s["state"] != "exited" and now - s["stamp"] <= self.lost_s

    def own(self, name: str) -> dict | None:
        """Latest status of node `name` of this node's run (None if never heard of)."""
        mine = [s for (n, _, r), s in self.table.items() if n == name and r == self.run]
        return max(mine, key=lambda s: s["stamp"]) if mine else None

    def peers(self) -> list[str]:
        """The other nodes of the graph."""
        return [n for n in self.graph_nodes if n != self.node]

    def describe(self, name: str, now: float | None = None) -> str | None:
        """Why peer `name` is missing (None if it is alive).

        Returns e.g. `fault_injector (never started)`, `tube_mpc (lost: no status
        for 6.1 s, last at step 812)`, `tube_mpc (exited with status 3: ...)`.
        """
        now = time.time() if now is None else now
        s = self.own(name)
        if s is None:
            return f"{name} (never started)"
        if s["state"] == "exited":
            why = f": {s['reason']}" if s.get("reason") else ""
            return f"{name} (exited with status {s.get('exit')} at step {s['k']}{why})"
        if now - s["stamp"] > self.lost_s:
            return f"{name} (lost: no status for {now - s['stamp']:.1f} s, last at step {s['k']})"
        return None

    def missing(self, now: float | None = None) -> list[str]:
        """Peers of the graph that never started, exited or are lost, described."""
        found = (self.describe(n, now) for n in self.peers())
        return [d for d in found if d is not None]

    def run_verdict(self) -> Verdict | None:
        """The verdict that ended this run, as a peer that found or learnt it announced it.

        A node announces the verdict as soon as it has it, in every status it publishes
        after (its heartbeats while it lingers for its last messages' delivery, then its
        exit): its peers stop with it at once, not only when it exits, which may be
        after their own watchdog's time without a step.

        Returns
        -------
        fahv.verdict.Verdict or None
            None while no peer of the run announced a verdict (or the status is not
            one: another program's), and while a node of this run has two alive
            instances (`twins`: the same run started twice, which the foreign-graph
            check stops; the verdict may be the other instance's).
        """
        if self.twins():
            return None
        for n in self.peers():
            s = self.own(n)
            if s is not None and s.get("verdict"):
                try:
                    return Verdict.from_dict(s["verdict"])
                except ValueError:
                    continue
        return None

    def failed(self) -> list[str]:
        """Peers that exited with a non-zero status, described (their own reasons).

        A peer that exited with the run's verdict (`run_verdict`) did not fail:
        the run ended. Depends on the table only, so it is computed once per
        `version` (every node asks between any two spins).
        """
        if self._failed[0] != self.version:
            out = []
            for n in self.peers():
                s = self.own(n)
                if s is not None and s["state"] == "exited" and s.get("exit"):
                    if s.get("verdict"):
                        continue
                    out.append(self.describe(n))
            self._failed = (self.version, tuple(out))
        return list(self._failed[1])

    def failed_verdict(self, now: float | None = None) -> str | None:
        """Why this node must stop because a peer exited with an error (None if none did).

        The root cause comes first: the peers that never started or were lost (a
        failed peer may have stopped because of them). When every failed peer names
        one of those in its own reason, they are only listed (`stopped with plant,
        which exited for it too`); otherwise the first failed peer with a reason of
        its own is described.

        Returns
        -------
        str or None
            E.g. `missing fault_injector (never started); stopped with plant, which
            exited for it too` or `peer tube_mpc (exited with status 2 at step 0: ...)`.
        """
        failed = self.failed()
        if not failed:
            return None
        gone = [d for d in self.missing(now) if d not in failed and "(exited" not in d]
        head = f"missing {'; '.join(gone)}; " if gone else ""
        names = [d.split(" (")[0] for d in gone]
        own = [d for d in failed if not any(f"{n} (" in d for n in names)]
        if not own:
            same = ", ".join(d.split(" (")[0] for d in failed)
            return f"{head}stopped with {same}, which exited for it too"
        return f"{head}peer {own[0]}"

    def not_ready(self, now: float | None = None) -> list[str]:
        """Peers alive but still starting, with what each waits for."""
        out = []
        for n in self.peers():
            s = self.own(n)
            if s is not None and self.alive(s, now) and s["state"] == "starting":
                waits = ", ".join(s.get("waiting") or []) or "its core"
                out.append(f"{n} (starting, waits for {waits})")
        return out

    def ready(self, name: str) -> bool:
        """True if peer `name` of this run announced itself ready (or is further)."""
        s = self.own(name)
        return s is not None and s["state"] in ("ready", "running", "done")

    def joined(self, run: str) -> float:
        """When a run's graph joined the domain: the earliest start of its nodes [s]."""
        starts = [s["start"] for (_, _, r), s in self.table.items() if r == run]
        if run == self.run:
            starts.append(self.start)
        return min(starts)

    def foreign(self, now: float | None = None) -> dict[str, list[dict]]:
        """Alive instances of other runs, by run id."""
        out: dict[str, list[dict]] = {}
        for (_, _, r), s in self.table.items():
            if r != self.run and self.alive(s, now):
                out.setdefault(r, []).append(s)
        return out

    def twins(self, now: float | None = None) -> list[str]:
        """Nodes of this run with two alive instances (the same run started twice)."""
        names = [n for (n, _, r), s in self.table.items() if r == self.run and self.alive(s, now)]
        return sorted({n for n in names if names.count(n) > 1 or n == self.node})

    def foreign_verdict(self, domain: int, now: float | None = None) -> tuple[str, str] | None:
        """Whether another graph is in the domain, and which one joined second.

        Returns
        -------
        None or (str, str)
            None when no other graph is seen; `("stop", message)` when this graph
            joined second, or when the two cannot be told apart (the same run id twice);
            `("stay", message)` when the other graph joined after this one (it stops
            by itself; this node ignores its messages, which are of earlier steps).
        """
        now = time.time() if now is None else now
        twins = self.twins(now)
        if twins:
            return "stop", (
                f"{self.node}: a second {twins[0]} of the same run '{self.run}' runs in ROS "
                f"domain {domain} (ROS_DOMAIN_ID={domain}): two graphs started from one "
                "parameter file cannot be told apart; both stop. Give each graph its own "
                "domain (fahv sil takes a free one from domain_coordinator)"
            )
        others = self.foreign(now)
        if not others:
            return None
        mine = self.joined(self.run)
        first = min(others, key=self.joined)
        nodes = ", ".join(sorted(s["node"] for s in others[first]))
        if self.joined(first) < mine:
            return "stop", (
                f"{self.node}: another graph (run '{first}': {nodes}) is running in ROS domain "
                f"{domain} (ROS_DOMAIN_ID={domain}) since {_clock(self.joined(first))}, "
                f"before this one joined at {_clock(mine)}: this graph stops. Give each graph "
                "its own domain (fahv sil takes a free one from domain_coordinator)"
            )
        return "stay", (
            f"{self.node}: another graph (run '{first}': {nodes}) joined ROS domain {domain} "
            f"at {_clock(self.joined(first))}, after this one ({_clock(mine)}): it stops by "
            "itself; this run goes on and ignores its messages"
        )

    def explains(self, producer: str, now: float | None = None) -> bool:
        """True if an extra publisher of `producer`'s topic is a later graph's node."""
        mine = self.joined(self.run)
        for run, nodes in self.foreign(now).items():
            if self.joined(run) > mine and any(s["node"] == producer for s in nodes):
                return True
        return False
