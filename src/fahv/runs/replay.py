"""``fahv replay``: republish a recorded run over DDS, optionally into nodes under test."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from fahv.errors import RunError
from fahv.runs.sil import _runner, reserve_run, run_runner
from fahv.runs.workspace import WS, ensure_built, ros_env


@dataclass
class ReplayRun:
    """Outcome of one replay (:func:`run_replay`).

    Attributes
    ----------
    out : Path or None
        Run folder written by the replay node (None when not recorded).
    returncode : int
        Exit status of the ``sil`` runner: 0 when the replay and every node finished.
    wall_s : float
        Wall time of the whole replay, start-up included [s].
    log_dir : Path
        Folder with the parameter file and the node logs.
    interrupted : bool
        Stopped by SIGINT / SIGTERM (the output run, if any, is finalised).
    """

    out: Path | None
    returncode: int
    wall_s: float
    log_dir: Path
    interrupted: bool = False


def _ros_list(values) -> list[str]:
    """A string-array parameter; [""] stands for empty (a YAML [] has no type)."""
    return list(values) or [""]


def run_replay(
    run: str | Path,
    nodes=(),
    topics=None,
    capture=None,
    out: str | Path | None = None,
    rate: float = 1.0,
    steps: int = 0,
    watchdog_s: float = 10.0,
    quiet: bool = False,
    log=print,
) -> ReplayRun:
    """Republish a recorded run (``replay`` node), optionally into nodes under test.

    Parameters
    ----------
    run : path
        Run folder (or its .mcap file).
    nodes : sequence of str
        Nodes to start against the replay (e.g. ``["tube_mpc"]``), with the
        parameters the run was made with (``<run>/params.yaml``).
    topics : sequence of str, optional
        Topics to republish; default: the inputs of ``nodes`` they do not produce
        (:func:`fahv.loop.replay_topics`), or every loop topic without nodes.
    capture : sequence of str, optional
        Topics to capture (lockstep on them); default: the outputs of ``nodes``.
    out : path, optional
        Run folder to write (replayed + captured messages); None: not recorded.
    rate : float
        1: recorded timing, r: r times faster, 0: as fast as possible.
    steps : int
        Steps to replay (0: all); the nodes under test run that many steps.
    watchdog_s : float
        Wall-clock watchdog of every node [s].

    Returns
    -------
    ReplayRun
        ``returncode`` 0 when the replay (and every node) finished.

    Raises
    ------
    RunError
        If the run is missing, a node is unknown, the run has no parameter file
        for a node under test, or the workspace cannot be built.
    """
    from fahv.loop.graph import replay_topics
    from fahv.runs.bag import bag_paths, stored_metadata

    folder, mcap = bag_paths(run)
    if not mcap.is_file():
        raise RunError(f"run file {mcap} does not exist")
    inputs, outputs = replay_topics(nodes)
    if topics is None:
        topics = inputs if nodes else []  # []: the replay node takes every loop topic
    topics, capture = list(topics), list(outputs if capture is None else capture)
    content = {}
    if nodes:
        pfile = folder / "params.yaml"
        try:
            recorded = yaml.safe_load(pfile.read_text())
        except (OSError, yaml.YAMLError) as exc:
            raise RunError(f"cannot start {list(nodes)}: parameters of the run: {exc}") from None
        for n in nodes:
            if n not in recorded:
                raise RunError(f"{pfile} has no parameters for node '{n}'")
            p = dict(recorded[n]["ros__parameters"])
            if steps:
                p["duration"] = steps * float(p["Ts"])
            content[n] = {"ros__parameters": p}
    meta = stored_metadata(folder)
    content["replay"] = {
        "ros__parameters": {
            "run": str(mcap.resolve()),
            "topics": _ros_list(topics),
            "rate": float(rate),
            "capture": _ros_list(capture),
            "out": "" if out is None else str(Path(out).resolve()),
            "wait_for": _ros_list(nodes),
            "steps": int(steps),
            "watchdog_s": float(watchdog_s),
            "metadata_json": json.dumps(
                {k: meta[k] for k in ("case", "variant", "design_hash", "Ts") if k in meta}
            ),
        }
    }
    content["/**"] = {
        "ros__parameters": {
            "use_sim_time": "/clock" in topics or not topics,
            "graph_nodes": ["replay", *nodes],
        }
    }
    ensure_built(log=log)
    env = ros_env()
    _, work = reserve_run(time.strftime("%Y%m%d-%H%M%S"), WS / "log" / "replay")
    (work / "params.yaml").write_text(yaml.safe_dump(content, sort_keys=False, width=120))
    cmd = _runner(work, ["--nodes", "replay", *nodes], quiet)
    log(f"replay of {folder.name} into {list(nodes) or 'the graph'}: logs in {work}")
    t0 = time.monotonic()
    rc, interrupted = run_runner(cmd, env)
    return ReplayRun(
        None if out is None else Path(out), rc, time.monotonic() - t0, work, interrupted
    )
