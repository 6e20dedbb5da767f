"""`fahv sil`: run a designed case through the ROS 2 node graph and record it.

This module imports no ROS code: it builds the colcon workspace when needed
(`scripts/build_ros.sh`), writes the run's parameter file (the design's node
parameters for the variant, the recorder's section, and `graph_nodes` /
`use_sim_time` for every node, see `USE_SIM_TIME`), starts the `sil` runner
of `hsv_bringup` in the workspace's environment, and reads the recorded run back.
The runner isolates the graph: a free `ROS_DOMAIN_ID` from `domain_coordinator`
(whatever the shell exports) and `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`; the
recorder stores the domain in the run metadata (`ros_domain_id`).

Interruption: a `KeyboardInterrupt` while the runner works (Ctrl-C, or SIGTERM turned
into one by `fahv.cli`) is forwarded to the runner as SIGINT; the runner stops every
node, the recorder finalises the run (status `interrupted`), and the result says
`interrupted`. Further interrupts while the graph stops are ignored.
"""

from __future__ import annotations

import json
import signal
import subprocess
import time
from dataclasses import dataclass
from pathlib import Path

import yaml

from fahv.errors import RunError
from fahv.loop.graph import graph_nodes
from fahv.loop.params import case_with, controller_node, node_parameters, parameter_file
from fahv.plant.faults import FAULTS
from fahv.sil.workspace import ROOT, WS, ensure_built, ros_env
from fahv.spec.coverage import Coverage, coverage
from fahv.spec.requirements import limits_of
from fahv.version import code_version

#: `use_sim_time` of the graph's nodes. The loop runs on the step index k and t_k that
#: every message carries and reads no clock, so the nodes need no ROS time; with
#: `use_sim_time` each node subscribes to `/clock` and wakes up once more per step,
#: just when the notch filter and the nominal trajectory need the CPU (about 12 % of
#: the step on this 2-core machine, docs/guide/sil.md). The plant still publishes `/clock`
#: for the recorder and for tools.
USE_SIM_TIME = False


@dataclass
class SilRun:
    """Outcome of one SIL run."""

    bag: Path
    returncode: int
    wall_s: float
    simulated_s: float
    interrupted: bool = False


def run_name(case: str, variant: str, source: str) -> str:
    """`<case>_<variant>_<source>_<YYYYmmdd-HHMMSS>`."""
    return f"{case}_{variant}_{source}_{time.strftime('%Y%m%d-%H%M%S')}"


def fault_metadata(fault_params: dict) -> dict:
    """`fault_<key>` metadata of the fault a run's `fault_injector` applies.

    Parameters
    ----------
    fault_params : dict
        The node's parameters (after every override): `kind`, `t_onset` and the
        parameters of its kind (`fahv.plant.faults.FAULTS`).
    """
    kind = fault_params["kind"]
    keys = ("kind", "t_onset", *(f.name for f in FAULTS[kind].parameters))
    return {f"fault_{k}": fault_params[k] for k in keys if k in fault_params}


def run_coverage(design, duration: float | None = None, nodes: dict | None = None) -> Coverage:
    """The coverage verdict of a run (`fahv.spec.coverage.coverage`).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
        The run's design (a stored design with its scenario's arrays and run spec).
    duration : float, optional
        Simulated time [s] (the run spec's by default): a fault from then on never acts.
    nodes : dict, optional
        The run's node parameters or overrides: the fault and command a campaign run
        draws (`fahv.loop.params.case_with`).

    Returns
    -------
    fahv.spec.coverage.Coverage
    """
    return coverage(design, case_with(design.case, nodes), duration=duration)


#: The design provenance a run's metadata carries.
PROVENANCE_KEYS = ("design_file", "design_file_hash", "vehicle_file", "vehicle_hash", "code_hash")


def run_metadata(
    design, variant: str, source: str, duration: float, nodes: dict | None = None
) -> dict:
    """Metadata recorded with every run: case, variant, design hash and provenance, fault.

    The provenance (case hash, vehicle file and hash, design code hash) lets
    `fahv inspect` say exactly what a run was made from, and the metrics use the
    recorded vehicle's limits. `coverage` is the run's coverage verdict
    (`run_coverage`, with the fault and command of `nodes`).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    variant, source : str
    duration : float
        Simulated time [s].
    nodes : dict, optional
        The run's node parameters `{node: {name: value}}` after every override: the
        fault is the one its `fault_injector` applies (a campaign run's own), not
        the case file's; `plant_params.<p>` are its `plant` node's perturbed
        parameters (the design's draw without `nodes`), from which the metrics
        compute the attitude from the vehicle's own trim.
    """
    params = dict(design.summary.get("plant_params", {}))
    for k, v in ((nodes or {}).get("plant") or {}).items():
        if k.startswith("params."):
            params[k.split(".", 1)[1]] = float(v)
    c = design.case
    prov = design.summary.get("provenance", {})
    fault = (
        fault_metadata(nodes["fault_injector"])
        if nodes is not None and "fault_injector" in nodes
        else {f"fault_{k}": v for k, v in c["fault"].items()}
    )
    return {
        "case": c["name"],
        "variant": variant,
        "design": design.summary.get("design_name", ""),
        "design_hash": design.summary["design_hash"],
        "scenario_hash": design.summary.get("scenario_hash", ""),
        "code_version": code_version(),
        "source": source,
        "Ts": c["Ts"],
        "duration": duration,
        "coverage": run_coverage(design, duration, nodes).text(),
        "requirements": json.dumps(limits_of(c), sort_keys=True),
        **{k: prov[k] for k in PROVENANCE_KEYS if k in prov},
        **fault,
        **{f"plant_params.{k}": float(v) for k, v in params.items()},
    }


def reserve_run(name: str, work_root: Path, out_dir=None) -> tuple[str, Path]:
    """A run name no other run uses, with its work folder created atomically.

    Two runs started in the same second with the same case and variant (e.g. two
    `fahv sil` at once) would otherwise share the name, the work folder (parameter
    file, logs) and the run folder. The work folder `work_root/<name>` is created
    with an exclusive `mkdir`; if it, or `out_dir/<name>`, exists, `-2`, `-3`
    ... is appended.

    Returns
    -------
    (str, Path)
        The name and its work folder (created).
    """
    work_root.mkdir(parents=True, exist_ok=True)
    for i in range(1, 10_000):
        cand = name if i == 1 else f"{name}-{i}"
        if out_dir is not None and (Path(out_dir) / cand).exists():
            continue
        try:
            (work_root / cand).mkdir()
        except FileExistsError:
            continue
        return cand, work_root / cand
    raise RunError(f"no free run name {name}-N in {work_root}")


def run_parameter_file(
    design,
    variant: str,
    bag: Path,
    duration: float | None,
    watchdog_s: float,
    overrides: dict | None = None,
    source: str = "sil",
    metadata: dict | None = None,
    params_file: Path | None = None,
    live_port: int | None = None,
) -> dict:
    """The ROS 2 parameter file of one run (every node, the recorder's section, `/**`).

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    variant : str
    bag : Path
        Run folder the recorder creates.
    duration : float or None
        Simulated time [s] (the case's by default).
    watchdog_s : float
        Wall-clock watchdog of every node [s].
    overrides : dict, optional
        `{node: {name: value}}` applied to the nodes before the run metadata is made
        (a campaign run's dispersed values; tests inject faults or bad values).
    source : str
        `source` of the run metadata.
    metadata : dict, optional
        Further run metadata (a campaign run: campaign, index, dispersed values).
    params_file : Path, optional
        Where this content is written: the recorder attaches that file to the run.
    live_port : int, optional
        The recorder serves the live view on this port (0: any free port; None: no
        live view, `fahv.runs.live`).

    Returns
    -------
    dict
        `{node: {"ros__parameters": {...}}}`; the recorder's `metadata_json` holds
        the run metadata, with the fault of the (overridden) `fault_injector`.

    Raises
    ------
    RunError
        On an override for a node that is not in the run.

    Notes
    -----
    Every node gets `graph_nodes` and `run_id` (the run folder's name: it tells
    this graph's nodes from another graph's in the same ROS domain).
    """
    nodes = node_parameters(design, variant, watchdog_s=watchdog_s)
    if duration is not None:
        for p in nodes.values():
            p["duration"] = float(duration)
    later = {}
    for node, values in (overrides or {}).items():
        if node in nodes:
            nodes[node].update(values)
        elif node in ("recorder", "/**"):
            later[node] = values
        else:
            raise RunError(f"override for node '{node}', which is not in the run: {sorted(nodes)}")
    controller = controller_node(nodes)
    plant = nodes["plant"]
    meta = {**run_metadata(design, variant, source, plant["duration"], nodes), **(metadata or {})}
    nodes["recorder"] = {
        "bag": str(bag),
        "Ts": plant["Ts"],
        "duration": plant["duration"],
        "watchdog_s": float(watchdog_s),
        "metadata_json": json.dumps(meta),
        "params_file": "" if params_file is None else str(Path(params_file).resolve()),
        "live_port": -1 if live_port is None else int(live_port),
    }
    content = parameter_file(nodes)
    content["/**"] = {
        "ros__parameters": {
            "use_sim_time": USE_SIM_TIME,
            "graph_nodes": graph_nodes(controller),
            "run_id": Path(bag).name,
        }
    }
    for node, values in later.items():
        content[node]["ros__parameters"].update(values)
    return content


def write_run_params(
    design,
    variant: str,
    bag: Path,
    path: Path,
    duration: float | None,
    watchdog_s: float,
    overrides: dict | None = None,
    metadata: dict | None = None,
) -> dict:
    """Write the parameter file of one SIL run to `path` and return its content.

    `run_parameter_file` with `params_file = path`: the recorder attaches the
    file to the run, so the run file holds every node's parameters.
    """
    content = run_parameter_file(
        design, variant, bag, duration, watchdog_s, overrides, "sil", metadata, path
    )
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(yaml.safe_dump(content, sort_keys=False, width=120))
    return content


def _runner(work: Path, args: list[str], quiet: bool, domain_id: int | None = None) -> list[str]:
    """Command line of the hsv_bringup `sil` runner for a run folder `work`."""
    exe = WS / "install" / "hsv_bringup" / "lib" / "hsv_bringup" / "sil"
    cmd = [str(exe), "--params-file", str(work / "params.yaml"), "--log-dir", str(work / "logs")]
    if domain_id is not None:
        cmd += ["--domain-id", str(int(domain_id))]
    return cmd + args + (["--quiet"] if quiet else [])


#: Exit status of the runner after SIGINT / SIGTERM.
EXIT_INTERRUPTED = 130


def run_runner(cmd: list[str], env: dict) -> tuple[int, bool]:
    """Run the `sil` runner to its end; forward an interrupt to it.

    Parameters
    ----------
    cmd : list of str
        Command line (`_runner`).
    env : dict
        Environment of the sourced workspace.

    Returns
    -------
    (int, bool)
        The runner's exit status and whether the run was interrupted (a
        `KeyboardInterrupt` here, or the runner's own status 130).
    """
    proc = subprocess.Popen(cmd, env=env)
    try:
        rc = proc.wait()
    except KeyboardInterrupt:
        proc.send_signal(signal.SIGINT)  # the terminal may have sent it already: harmless
        while True:  # a second Ctrl-C must not leave the runner orphaned mid-shutdown
            try:
                return proc.wait(), True
            except KeyboardInterrupt:
                continue
    return rc, rc == EXIT_INTERRUPTED


def recorder_metadata(content: dict) -> dict:
    """The run metadata in a run's parameter file (the recorder's `metadata_json`)."""
    return json.loads(content["recorder"]["ros__parameters"]["metadata_json"])


def run_sil(
    design,
    variant: str | None = None,
    duration: float | None = None,
    out_dir: Path | str = ROOT / "bags",
    watchdog_s: float = 10.0,
    overrides: dict | None = None,
    quiet: bool = False,
    log=print,
    domain_id: int | None = None,
    name: str | None = None,
    metadata: dict | None = None,
    live_port: int | None = None,
    compose: bool = False,
) -> SilRun:
    """Run one variant of a designed case through the node graph, recorded to MCAP.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
    variant : str, optional
        The case's first variant by default.
    duration : float, optional
        Simulated time [s]; the case's by default.
    out_dir : path
        Where the run folder `<case>_<variant>_sil_<time>/` is created.
    watchdog_s : float
        Wall-clock watchdog of every node [s].
    overrides : dict, optional
        Parameter overrides {node: {name: value}}.
    quiet : bool
        No progress bar.
    log : callable
        Receives the lines about the build and the run folder.
    domain_id : int, optional
        ROS_DOMAIN_ID of the graph; by default the runner takes a free one from
        `domain_coordinator` (an exported `ROS_DOMAIN_ID` is not used).
    name : str, optional
        Run name without the time stamp (default `<case>_<variant>_sil`); the
        folder is `<name>_<time>`.
    metadata : dict, optional
        Further run metadata (`run_parameter_file`).
    live_port : int, optional
        Serve the live view on this port (0: any free one); None: no live view.
    compose : bool
        Run the loop nodes in one process (the runner's `--compose`, ROS 2
        composition) instead of one process each; the run is the same step for step.

    Returns
    -------
    SilRun
        `returncode` 0 when every node finished (130 when interrupted); the bag is
        readable in any case.

    Raises
    ------
    RunError
        If the workspace cannot be built or sourced, or an override names a node that
        is not in the run.
    """
    variant = design.case["variants"][0] if variant is None else variant
    content = run_parameter_file(
        design,
        variant,
        Path("."),
        duration,
        watchdog_s,
        overrides,
        "sil",
        metadata,
        live_port=live_port,
    )
    base = name or f"{design.case['name']}_{variant}_sil"
    stem = f"{base}_{time.strftime('%Y%m%d-%H%M%S')}"
    return run_graph(content, stem, out_dir, quiet, log, domain_id, compose)


def run_graph(
    content: dict,
    name: str,
    out_dir: Path | str = ROOT / "bags",
    quiet: bool = False,
    log=print,
    domain_id: int | None = None,
    compose: bool = False,
) -> SilRun:
    """Run a parameter file's graph (every node in it, the recorder included).

    Parameters
    ----------
    content : dict
        The run's parameter file (`run_parameter_file`, or the one stored in a
        run file); the recorder's `bag` and `params_file` are set here.
    name : str
        Run name (`-2` ... appended if it is taken).
    out_dir, quiet, log, domain_id, compose
        As `run_sil`.

    Returns
    -------
    SilRun

    Raises
    ------
    RunError
        If the workspace cannot be built or sourced.
    """
    ensure_built(log=log)
    env = ros_env()
    name, work = reserve_run(name, WS / "log" / "sil", out_dir)
    bag = Path(out_dir).resolve() / name
    path = work / "params.yaml"
    rec = content["recorder"]["ros__parameters"]
    meta = recorder_metadata(content)  # how the loop ran: one process, or one per node
    meta["graph_processes"] = "composed" if compose else "per_node"
    rec.update(bag=str(bag), params_file=str(path.resolve()), metadata_json=json.dumps(meta))
    content.setdefault("/**", {"ros__parameters": {}})["ros__parameters"]["run_id"] = name
    path.write_text(yaml.safe_dump(content, sort_keys=False, width=120))
    sim_s = content["plant"]["ros__parameters"]["duration"]
    controller = controller_node(content)
    cmd = _runner(work, ["--controller", controller] + (["--compose"] if compose else []), quiet,
                  domain_id)  # fmt: skip
    log(f"SIL run {name}: logs in {work}")
    t0 = time.monotonic()
    rc, interrupted = run_runner(cmd, env)
    wall = time.monotonic() - t0
    if bag.is_dir():  # keep the node logs with the run (the parameters are in its file)
        for src in sorted((work / "logs").glob("*.log")):
            dst = bag / "logs" / src.name
            dst.parent.mkdir(exist_ok=True)
            dst.write_bytes(src.read_bytes())
    return SilRun(bag, rc, wall, sim_s, interrupted)
