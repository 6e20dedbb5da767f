"""``fahv sil``: run a designed case through the ROS 2 node graph and record it.

This module imports no ROS code: it builds the colcon workspace when needed
(``scripts/build_ros.sh``), writes the run's parameter file (the design's node
parameters for the variant, the recorder's section, and ``graph_nodes`` /
``use_sim_time`` for every node), starts the ``sil`` runner of ``hsv_bringup`` in the
workspace's environment with an isolated ``ROS_DOMAIN_ID`` and
``ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST``, and reads the recorded run back.
"""

from __future__ import annotations

import hashlib
import json
import random
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from fahv.errors import RunError
from fahv.loop import graph_nodes
from fahv.params import node_parameters, parameter_file
from fahv.runlog import code_version

#: Repository root (the library is installed in editable mode from it).
ROOT = Path(__file__).resolve().parents[2]
WS = ROOT / "ros_ws"
PACKAGES = ("hsv_interfaces", "hsv_common", "hsv_plant", "hsv_ctrl", "hsv_bringup")


def sources_hash(ws: Path = WS) -> str:
    """SHA-256 over every source file of ``ws/src`` (message files included).

    The packages are installed as copies (no ``--symlink-install``), so a changed
    node or message needs a rebuild; :func:`workspace_built` compares this hash
    with the one the last build recorded.
    """
    h = hashlib.sha256()
    for f in sorted((ws / "src").rglob("*")):
        if f.is_file() and "__pycache__" not in f.parts:
            h.update(str(f.relative_to(ws)).encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


def write_build_stamp(ws: Path = WS) -> None:
    """Record :func:`sources_hash` after a successful build (``scripts/build_ros.sh``)."""
    (ws / "install" / ".fahv_sources").write_text(sources_hash(ws))


def workspace_built(ws: Path = WS) -> bool:
    """True if every hsv package is installed in ``ws/install`` from the current sources."""
    stamp = ws / "install" / ".fahv_sources"
    return (
        (ws / "install" / "setup.bash").is_file()
        and all((ws / "install" / p / "share" / p / "package.xml").is_file() for p in PACKAGES)
        and stamp.is_file()
        and stamp.read_text() == sources_hash(ws)
    )


def ensure_built(ws: Path = WS, log=print) -> None:
    """Build the workspace with colcon if a package is missing or its sources changed.

    Raises
    ------
    RunError
        If the build fails (the colcon output is shown).
    """
    if workspace_built(ws):
        return
    log(f"building {ws} (colcon) ...")
    r = subprocess.run(
        ["bash", str(ROOT / "scripts" / "build_ros.sh")], capture_output=True, text=True
    )
    if r.returncode != 0 or not workspace_built(ws):
        raise RunError(f"colcon build of {ws} failed:\n{r.stdout[-3000:]}\n{r.stderr[-3000:]}")


def ros_env(ws: Path = WS) -> dict:
    """Environment of ``source ws/install/setup.bash`` with this venv first on PATH.

    Raises
    ------
    RunError
        If sourcing fails.
    """
    venv_bin = str(Path(sys.executable).parent)
    script = f'export PATH="{venv_bin}:$PATH"; source "{ws}/install/setup.bash" && env -0'
    r = subprocess.run(["bash", "-c", script], capture_output=True)
    if r.returncode != 0:
        raise RunError(f"sourcing {ws}/install/setup.bash failed: {r.stderr.decode()[-2000:]}")
    env = dict(item.split("=", 1) for item in r.stdout.decode().split("\0") if "=" in item)
    return env


@dataclass
class SilRun:
    """Outcome of one SIL run."""

    bag: Path
    returncode: int
    wall_s: float
    simulated_s: float

    @property
    def real_time_factor(self) -> float:
        """Simulated time / wall time (> 1: faster than real time)."""
        return self.simulated_s / self.wall_s if self.wall_s > 0 else float("nan")


def run_name(case: str, variant: str, source: str) -> str:
    """``<case>_<variant>_<source>_<YYYYmmdd-HHMMSS>``."""
    return f"{case}_{variant}_{source}_{time.strftime('%Y%m%d-%H%M%S')}"


def run_metadata(design, variant: str, source: str, duration: float) -> dict:
    """Run metadata recorded with every run (case, design hash, code version, fault ...)."""
    c = design.case
    f = c["fault"]
    return {
        "case": c["name"],
        "variant": variant,
        "design_hash": design.summary["design_hash"],
        "code_version": code_version(),
        "source": source,
        "Ts": c["Ts"],
        "duration": duration,
        "fault_kind": f["kind"],
        "fault_t_onset": f["t_onset"],
        "fault_rho_f": f["rho_f"],
        "fault_bias_deg": f["bias_deg"],
    }


def write_run_params(
    design,
    variant: str,
    bag: Path,
    path: Path,
    duration: float | None,
    watchdog_s: float,
    overrides: dict | None = None,
) -> dict:
    """Write the parameter file of one SIL run and return its content.

    ``overrides``: {node: {name: value}} applied last (tests use it to inject faults
    or bad values).
    """
    nodes = node_parameters(design, variant, watchdog_s=watchdog_s)
    if duration is not None:
        for p in nodes.values():
            p["duration"] = float(duration)
    controller = "rmpc" if "rmpc" in nodes else "tube_mpc"
    plant = nodes["plant"]
    nodes["recorder"] = {
        "bag": str(bag),
        "Ts": plant["Ts"],
        "duration": plant["duration"],
        "watchdog_s": float(watchdog_s),
        "metadata_json": json.dumps(run_metadata(design, variant, "sil", plant["duration"])),
    }
    content = parameter_file(nodes)
    content["/**"] = {
        "ros__parameters": {
            "use_sim_time": True,
            "graph_nodes": graph_nodes(controller),
        }
    }
    for node, values in (overrides or {}).items():
        content[node]["ros__parameters"].update(values)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(content, sort_keys=False, width=120))
    return content


def _runner(work: Path, args: list[str], quiet: bool) -> list[str]:
    """Command line of the hsv_bringup ``sil`` runner for a run folder ``work``."""
    exe = WS / "install" / "hsv_bringup" / "lib" / "hsv_bringup" / "sil"
    cmd = [str(exe), "--params-file", str(work / "params.yaml"), "--log-dir", str(work / "logs")]
    return cmd + args + (["--quiet"] if quiet else [])


def run_sil(
    design,
    variant: str | None = None,
    duration: float | None = None,
    out_dir: Path | str = ROOT / "bags",
    watchdog_s: float = 10.0,
    overrides: dict | None = None,
    quiet: bool = False,
    log=print,
) -> SilRun:
    """Run one variant of a designed case through the node graph, recorded to MCAP.

    Parameters
    ----------
    design : fahv.design.Design
    variant : str, optional
        The case's first variant by default.
    duration : float, optional
        Simulated time [s]; the case's by default.
    out_dir : path
        Where the run folder ``<case>_<variant>_sil_<time>/`` is created.
    watchdog_s : float
        Wall-clock watchdog of every node [s].
    overrides : dict, optional
        Parameter overrides {node: {name: value}}.

    Returns
    -------
    SilRun
        ``returncode`` 0 when every node finished; the bag is readable in any case.

    Raises
    ------
    RunError
        If the workspace cannot be built or sourced.
    """
    variant = design.case["variants"][0] if variant is None else variant
    ensure_built(log=log)
    env = ros_env()
    env.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 100)))
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    name = run_name(design.case["name"], variant, "sil")
    bag = Path(out_dir).resolve() / name
    work = WS / "log" / "sil" / name
    params = write_run_params(
        design, variant, bag, work / "params.yaml", duration, watchdog_s, overrides
    )
    sim_s = params["plant"]["ros__parameters"]["duration"]
    controller = "rmpc" if "rmpc" in params else "tube_mpc"
    cmd = _runner(work, ["--controller", controller], quiet)
    log(f"SIL run {name}: ROS_DOMAIN_ID={env['ROS_DOMAIN_ID']}, logs in {work}")
    t0 = time.monotonic()
    rc = subprocess.run(cmd, env=env).returncode
    wall = time.monotonic() - t0
    if bag.is_dir():  # keep the parameters and node logs with the run
        for src in [work / "params.yaml", *sorted((work / "logs").glob("*.log"))]:
            if src.is_file():
                dst = bag / ("params.yaml" if src.name == "params.yaml" else f"logs/{src.name}")
                dst.parent.mkdir(exist_ok=True)
                dst.write_bytes(src.read_bytes())
    return SilRun(bag, rc, wall, sim_s)


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
    """

    out: Path | None
    returncode: int
    wall_s: float
    log_dir: Path


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
    from fahv.loop import replay_topics
    from fahv.runlog import bag_paths, stored_metadata

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
    env.setdefault("ROS_DOMAIN_ID", str(random.SystemRandom().randint(1, 100)))
    env.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    work = WS / "log" / "replay" / time.strftime("%Y%m%d-%H%M%S")
    work.mkdir(parents=True, exist_ok=True)
    (work / "params.yaml").write_text(yaml.safe_dump(content, sort_keys=False, width=120))
    cmd = _runner(work, ["--nodes", "replay", *nodes], quiet)
    log(f"replay of {folder.name} into {list(nodes) or 'the graph'}: logs in {work}")
    t0 = time.monotonic()
    rc = subprocess.run(cmd, env=env).returncode
    return ReplayRun(None if out is None else Path(out), rc, time.monotonic() - t0, work)


__all__ = [
    "ROOT",
    "WS",
    "workspace_built",
    "ensure_built",
    "ros_env",
    "SilRun",
    "run_name",
    "run_metadata",
    "write_run_params",
    "run_sil",
    "ReplayRun",
    "run_replay",
]
