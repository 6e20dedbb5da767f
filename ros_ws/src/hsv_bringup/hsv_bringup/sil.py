"""`sil` runner: start the node graph of one run, supervise it, stop every node.

There is no `launch` among the ROS 2 wheels this project installs, so this runner starts
the installed executables itself, each with the run's parameter file, in the order of the
node table (`fahv.loop.graph.NODES`: recorder, state_estimator, notch_filter,
nominal_trajectory, controller, fault_injector, plant; the plant waits until every other
node has announced itself, so the order only saves time). It watches the processes: the
run succeeds when every node exits 0 after the last step; the first node that exits non-
zero or is killed (a node whose status is not 3 first: the cause rather than the peers
that stopped because of it) fails the run, the others get SIGINT (the recorder closes its
file), then SIGKILL after a grace period, and the runner exits 1 naming that node and
showing the end of its log. A run that ends with a verdict (fahv.verdict: the node that
finds it and then every peer exit with status 6, the recorder finishes the file with it)
is no failure: the runner waits for every node and exits 3.

Isolation: every graph runs in a DDS domain of its own. Unless `--domain-id` is
given, the runner takes a free `ROS_DOMAIN_ID` from ROS 2's `domain_coordinator`
(unique among the processes of this host that use it, held until the runner exits),
whatever `ROS_DOMAIN_ID` the shell exports, and restricts discovery to this host
(`ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`), and prints the domain with the line to
type in another shell to see the graph (`watch_line`). Should another graph join
the domain anyway, the one that joined second stops (exit status 5, see
`hsv_common.graph_status`). The recorder's live-view address (`--live`) is passed
on to stderr.

Interruption: SIGINT (Ctrl-C) or SIGTERM stops every node with SIGINT (the recorder
closes its file with status `interrupted`) and the runner exits 130; a second signal
while the graph stops only prints a note.

Usually started by `fahv sil CASE` (or `fahv replay`), which writes the parameter
file; by hand:

    sil --params-file RUN_PARAMS.yaml --log-dir DIR [--controller tube_mpc|rmpc] [--compose]
    sil --params-file REPLAY_PARAMS.yaml --log-dir DIR --nodes replay tube_mpc

With `--compose` the loop nodes run in one process, `loop` (hsv_bringup.composed,
ROS 2 composition); the runner then supervises that process under that name, and the
recorder (or replay) as before.
"""

from __future__ import annotations

import argparse
import os
import signal
import subprocess
import sys
import threading
import time
from contextlib import ExitStack
from pathlib import Path

import domain_coordinator
import yaml
from tqdm import tqdm

from fahv.loop.graph import (
    COMPOSED,
    CONTROLLER_NODES,
    NODES,
    graph_nodes,
    loop_nodes,
    teardown_hung,
)

#: Exit status of the runner (and of `fahv sil`) after SIGINT / SIGTERM (128 + SIGINT).
EXIT_INTERRUPTED = 130
#: Exit status of a node whose watchdog fired (hsv_common.runtime.EXIT_WATCHDOG); a node
#: that stops because a peer failed exits so too, so the runner names another first.
EXIT_WATCHDOG_NODE = 3
#: Exit status of a node that ended the run with a verdict (hsv_common.runtime.EXIT_VERDICT).
EXIT_VERDICT_NODE = 6
#: Exit status of the runner (and of `fahv sil`) when the run ended with a verdict
#: other than completed (fahv.verdict): the graph ended cleanly, the run file holds it.
EXIT_VERDICT = 3
#: How long the nodes of a run that ended with a verdict may take to exit [s].
VERDICT_GRACE_S = 20.0
#: How long a watchdog exit waits for the failed peer it names to exit too [s].
CAUSE_GRACE_S = 3.0
#: How long a failed graph waits for a still-starting recorder to open its run file [s]
#: (so that even a graph that failed at once leaves a run with status and reason).
RECORDING_START_S = 30.0
#: Period of the runner's look at its nodes [s]: the run ends this long at most after
#: the last node exited (its wall time is the run's).
SUPERVISE_S = 0.02


def executable(name: str) -> Path:
    """Installed executable `<prefix>/lib/<pkg>/<name>` found on AMENT_PREFIX_PATH.

    Raises
    ------
    FileNotFoundError
        If no prefix holds it (the workspace is not built or not sourced).
    """
    pkg = "hsv_bringup" if name == COMPOSED else NODES[name].package
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        exe = Path(prefix) / "lib" / pkg / name
        if prefix and exe.is_file():
            return exe
    raise FileNotFoundError(
        f"executable {pkg}/{name} not found on AMENT_PREFIX_PATH: build ros_ws and source "
        "ros_ws/install/setup.bash"
    )


def _tail(path: Path, n: int = 12) -> str:
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError:
        return ""
    return "\n".join("    " + ln for ln in lines[-n:])


class Graph:
    """The processes of one run."""

    def __init__(
        self, params_file: Path, log_dir: Path, names: list[str], env: dict, compose: bool = False
    ) -> None:
        self.params_file, self.log_dir, self.env = params_file, log_dir, env
        # with `compose`, the loop nodes are one process (COMPOSED) after the others
        self.composed = loop_nodes(names) if compose else []
        self.names = [n for n in names if n not in self.composed]
        self.names += [COMPOSED] if self.composed else []
        self.procs: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, Path] = {}
        self.progress = (0, 0)
        self.stop_signal: int | None = None
        self.teardown_noted: dict[str, int] = {}

    def start(self) -> None:
        """Start every node (own process group, output to <log_dir>/<node>.log)."""
        self.log_dir.mkdir(parents=True, exist_ok=True)
        for name in self.names:
            self.logs[name] = self.log_dir / f"{name}.log"
            nodes = self.composed if name == COMPOSED else []
            cmd = [str(executable(name)), *nodes, "--ros-args", "--params-file",
                   str(self.params_file)]  # fmt: skip
            pipe = name in ("recorder", "replay")  # they print progress lines
            with open(self.logs[name], "w") as log:
                p = subprocess.Popen(
                    cmd,
                    stdout=subprocess.PIPE if pipe else log,
                    stderr=subprocess.STDOUT,
                    env=self.env,
                    start_new_session=True,
                    text=True,
                )
            self.procs[name] = p
            if pipe:
                threading.Thread(
                    target=self._follow, args=(p, self.logs[name]), daemon=True
                ).start()

    def _follow(self, p: subprocess.Popen, path: Path) -> None:
        with open(path, "w") as log:
            for line in p.stdout:
                log.write(line)
                log.flush()
                if line.startswith("progress "):
                    _, k, n = line.split()
                    self.progress = (int(k), int(n))
                elif line.startswith("live view "):  # the recorder's Foxglove server
                    print(f"sil: {line.strip()}", file=sys.stderr, flush=True)

    def stop(self, grace_s: float = 15.0) -> None:
        """SIGINT to every running node, SIGKILL after the grace period."""
        for p in self.procs.values():
            if p.poll() is None:
                try:
                    os.killpg(p.pid, signal.SIGINT)
                except ProcessLookupError:
                    pass
        t_end = time.monotonic() + grace_s
        for p in self.procs.values():
            try:
                p.wait(timeout=max(0.1, t_end - time.monotonic()))
            except subprocess.TimeoutExpired:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()

    def await_recording(self, bag: str | None, timeout_s: float = RECORDING_START_S) -> None:
        """Wait until the recording node (recorder or replay) has opened `bag`.

        Returns at once without a recording node or run folder, when the folder exists,
        when that node has exited, or after `timeout_s`; the node then records why the
        graph stopped (a peer's failure) when it is stopped.
        """
        rec = next((self.procs[n] for n in ("recorder", "replay") if n in self.procs), None)
        if rec is None or not bag:
            return
        t_end = time.monotonic() + timeout_s
        while not Path(bag).exists() and rec.poll() is None and time.monotonic() < t_end:
            if self.stop_signal is not None:
                return
            time.sleep(0.1)

    def own_status(self, name: str, rc: int) -> int:
        """Exit status of node `name` as the node meant it.

        A node whose DDS teardown hung after it closed is ended by its teardown timer
        with status 1 (hsv_common.runtime.TEARDOWN_S); its own status is then the one
        it closed with (said once on stderr), not a failure of the run.
        """
        if rc != 1 or name in self.teardown_noted:
            return self.teardown_noted.get(name, rc) if rc == 1 else rc
        try:
            own = teardown_hung(self.logs[name].read_text(errors="replace"))
        except OSError:
            own = None
        if own is None:
            return rc
        self.teardown_noted[name] = own
        print(
            f"sil: node '{name}' closed with status {own}, then its DDS teardown hung "
            "(Fast DDS); its teardown timer ended it",
            file=sys.stderr,
            flush=True,
        )
        return own

    def on_signal(self, signum: int, frame) -> None:
        """Handler of SIGINT / SIGTERM: the first one ends `supervise`.

        Later ones only print a note (the nodes are already stopping, the run stays intact).
        """
        if self.stop_signal is None:
            self.stop_signal = signum
        else:
            print("sil: already stopping every node, please wait", file=sys.stderr, flush=True)

    def supervise(self, on_progress=None) -> tuple[str | None, int]:
        """Wait for the end of the run, a failed node, or a stop signal.

        Returns
        -------
        (str or None, int)
            The first node that failed and its exit status; (None, 0) when every node
            finished; (None, 130) after `on_signal`; (node, 6) when the run
            ended with a verdict and every node exited (or `VERDICT_GRACE_S`
            passed): the first node that exited with it.
        """
        t_watchdog = t_verdict = None
        while True:
            if self.stop_signal is not None:
                return None, EXIT_INTERRUPTED
            running = 0
            failed = []
            for name in self.names:
                rc = self.procs[name].poll()
                if rc is None:
                    running += 1
                    continue
                rc = self.own_status(name, rc)
                if rc != 0:
                    failed.append((name, rc))
            ended = [f for f in failed if f[1] == EXIT_VERDICT_NODE]
            failed = [f for f in failed if f[1] != EXIT_VERDICT_NODE]
            if ended and not failed:  # the run ended: the recorder finishes its file
                t_verdict = time.monotonic() if t_verdict is None else t_verdict
                if running == 0 or time.monotonic() - t_verdict > VERDICT_GRACE_S:
                    return ended[0]
            if failed:  # the cause first: a node that stopped because a peer failed says 3
                cause = [f for f in failed if f[1] != EXIT_WATCHDOG_NODE]
                if cause:
                    return cause[0]
                # a watchdog exit names a peer's failure that peer may still be ending
                # with (its own exit status tells the cause): wait for it a moment
                if t_watchdog is None:
                    t_watchdog = time.monotonic()
                if time.monotonic() - t_watchdog > CAUSE_GRACE_S or running == 0:
                    return failed[0]
            if on_progress is not None:
                on_progress(*self.progress)
            if running == 0:
                return None, 0
            time.sleep(SUPERVISE_S)


def describe(rc: int) -> str:
    """Human form of a process exit status."""
    if rc < 0:
        return f"killed by signal {signal.Signals(-rc).name}"
    return {
        2: "bad parameter",
        3: "watchdog",
        4: "stopped by a signal",
        5: "foreign graph in its ROS domain",
        6: "run ended with a verdict",
    }.get(rc, f"exit status {rc}")


def watch_line(domain: int) -> str:
    """The line to type in another shell to list the topics of a graph in `domain`."""
    prefix = os.environ.get("COLCON_PREFIX_PATH", "").split(os.pathsep)[0]
    setup = Path(prefix) / "setup.bash" if prefix else Path("ros_ws/install/setup.bash")
    return (
        f"export ROS_DOMAIN_ID={domain} ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST; "
        f"source {setup}; ros2 topic list"
    )


def _progress_bar(quiet: bool):
    """Progress callback (k, n): a tqdm bar of steps with rate and ETA on stderr.

    On a terminal the bar updates in place; in a log file it writes a line every 10 s.
    """
    if quiet:
        return None, lambda: None
    state: dict = {"bar": None}

    def show(k: int, n: int) -> None:
        if not n:
            return
        bar = state["bar"]
        if bar is None:
            tty = sys.stderr.isatty()
            bar = state["bar"] = tqdm(
                total=n,
                desc="sil",
                unit="step",
                mininterval=0.5 if tty else 10.0,
                dynamic_ncols=True,
            )
        bar.update(k - bar.n)

    def close() -> None:
        if state["bar"] is not None:
            state["bar"].close()

    return show, close


def run_graph(graph: Graph, bag, quiet: bool) -> int:
    """Start, supervise and stop one graph; returns the runner's exit status."""
    show, close_bar = _progress_bar(quiet)
    try:
        graph.start()
        failed, rc = graph.supervise(show)
    except OSError as exc:  # an executable not found, a log folder not writable
        close_bar()
        print(f"sil: {exc}", file=sys.stderr)
        graph.stop()
        return 2
    close_bar()
    if rc == EXIT_INTERRUPTED:
        name = signal.Signals(graph.stop_signal).name
        print(f"sil: {name} received: stopping every node", file=sys.stderr, flush=True)
        graph.stop()
        print(f"sil: run (interrupted) written to {bag or '(not recorded)'}", file=sys.stderr)
        return EXIT_INTERRUPTED
    if rc == EXIT_VERDICT_NODE:
        graph.stop()  # every node exited already, unless one took longer than the grace
        print(f"sil: the run ended with a verdict (node '{failed}' first); run written to "
              f"{bag}", file=sys.stderr)  # fmt: skip
        return EXIT_VERDICT
    if failed is not None:
        print(f"sil: node '{failed}' failed ({describe(rc)}); stopping the graph", file=sys.stderr)
        graph.await_recording(bag)
        graph.stop()
        print(f"--- end of {graph.logs[failed]}\n{_tail(graph.logs[failed])}", file=sys.stderr)
        print(f"sil: run (incomplete) written to {bag}", file=sys.stderr)
        return 1
    print(f"sil: run written to {bag or '(not recorded)'}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the graph once; returns 0 done, 1 node failed, 3 run ended with a verdict, 130 stop."""
    ap = argparse.ArgumentParser(prog="sil", description=__doc__.split("\n\n")[0])
    ap.add_argument("--params-file", type=Path, required=True)
    ap.add_argument("--log-dir", type=Path, required=True)
    ap.add_argument("--controller", choices=CONTROLLER_NODES, default="tube_mpc")
    ap.add_argument(
        "--nodes",
        nargs="+",
        choices=sorted(NODES),
        default=None,
        help="nodes to start (default: recorder and the loop nodes with --controller)",
    )
    ap.add_argument(
        "--domain-id",
        type=int,
        default=None,
        help="ROS_DOMAIN_ID of the graph (default: a free one from domain_coordinator; "
        "an exported ROS_DOMAIN_ID is not used)",
    )
    ap.add_argument(
        "--compose",
        action="store_true",
        help=f"run the loop nodes in one process ('{COMPOSED}', ROS 2 composition) "
        "instead of one process each",
    )
    ap.add_argument("--quiet", action="store_true", help="no progress bar")
    args = ap.parse_args(argv)
    try:
        params = yaml.safe_load(args.params_file.read_text())
        names = args.nodes or graph_nodes(args.controller)
        bag = next(
            params[n]["ros__parameters"].get(key)
            for n, key in (("recorder", "bag"), ("replay", "out"))
            if n in names
        )
    except (OSError, yaml.YAMLError, KeyError, TypeError, StopIteration) as exc:
        print(f"sil: parameter file {args.params_file} unusable: {exc}", file=sys.stderr)
        return 2
    env = dict(os.environ)
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    env["PYTHONUNBUFFERED"] = "1"
    graph = Graph(args.params_file, args.log_dir, names, env, args.compose)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, graph.on_signal)
    with ExitStack() as held:
        if args.domain_id is None:  # reserved for this host until the runner exits
            domain = held.enter_context(domain_coordinator.domain_id())
        else:
            domain = args.domain_id
        env["ROS_DOMAIN_ID"] = str(domain)
        inherited = os.environ.get("ROS_DOMAIN_ID")
        note = (
            f" (exported ROS_DOMAIN_ID={inherited} not used)"
            if inherited not in (None, str(domain))
            else ""
        )
        print(f"sil: graph in ROS domain {domain}{note}", file=sys.stderr)
        print(f"sil: to see it from another shell: {watch_line(domain)}", file=sys.stderr)
        sys.stderr.flush()
        status = run_graph(graph, bag, args.quiet)
    return status


def run() -> None:
    """Entry point `ros2 run hsv_bringup sil`."""
    sys.exit(main())
