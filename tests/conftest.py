import copy
import functools
import json
import os
import subprocess
import time
import warnings
from pathlib import Path

import pytest
import yaml

from fahv.design.pipeline import run_design
from fahv.loop.graph import COMPOSED
from fahv.model.tp_model import build_tp_model
from fahv.model.vehicle import load_vehicle
from fahv.spec.files import spec_file

ROOT = Path(__file__).resolve().parents[1]
#: The paper's Case 1 design with its scenario: the quick design of the tests.
SCENARIO = "offline_design/scenarios/case1_paper.yaml"


#: The longest a test marked `ros` waits for the workspace build beside the suite [s].
BUILD_WAIT_S = 900.0


@functools.cache
def _workspace_build(status: str, log: str) -> str:
    """'' once the build `scripts/test.sh` runs beside the suite has succeeded, else why not.

    `status` is the file its exit status is written to when the build ends, `log` its
    output.
    """
    path, deadline = Path(status), time.monotonic() + BUILD_WAIT_S
    while not path.exists():
        if time.monotonic() > deadline:
            return f"the ROS 2 workspace build did not end within {BUILD_WAIT_S:.0f} s"
        time.sleep(0.5)
    rc = path.read_text().strip()
    if rc == "0":
        return ""
    tail = Path(log).read_text(errors="replace")[-3000:] if Path(log).is_file() else ""
    return f"the ROS 2 workspace build failed (exit status {rc}):\n{tail}"


def pytest_runtest_setup(item):
    """A test marked `ros` waits for the workspace build that runs beside the suite.

    `scripts/test.sh` builds ros_ws while the tests start (environment variable
    `FAHV_ROS_BUILD`: the file the build's exit status goes to); without it the
    workspace is taken as built.
    """
    status = os.environ.get("FAHV_ROS_BUILD")
    if status and item.get_closest_marker("ros") is not None:
        why = _workspace_build(status, os.environ.get("FAHV_ROS_BUILD_LOG", ""))
        if why:
            pytest.fail(why, pytrace=False)


@pytest.fixture(scope="session")
def vehicle():
    return load_vehicle()


@pytest.fixture(scope="session")
def tp_cm(vehicle):
    """20-vertex CM TP model on a coarse 11 x 11 grid (shared by the tube tests)."""
    return build_tp_model(vehicle, "cm", 4, 5, 11, 11)


def plain(data):
    """A validated mapping as plain YAML/JSON data (tuples as lists)."""
    return json.loads(json.dumps(data))


@pytest.fixture(scope="session")
def raw():
    """The whole case of scenario case1_paper (its design's entries with its own)."""
    from fahv.spec.scenario import load_scenario

    return plain(load_scenario(SCENARIO).run_spec.data)


def quick(raw, **changes):
    """Case 1 with a small W sample (CI) and the given top-level changes."""
    d = copy.deepcopy(raw)
    d["disturbance"]["samples"] = 40
    d["certificate"] = {"schedules": 0}  # checked in tests/design/test_one_step_bound.py
    d.update(changes)
    return spec_file(d, "quick.yaml")


@pytest.fixture(scope="session")
def make_case(raw):
    """Factory of quick cases: `make_case(**changes)` (Case 1, small W sample; without
    the RMPC baseline, whose off-line design costs about a minute, unless `variants`
    is given)."""
    no_rmpc = [v for v in raw["variants"] if v != "rmpc"]
    return lambda **changes: quick(raw, **{"variants": no_rmpc, **changes})


def shared_design(spec, shipped: str, name: str, tmp_path_factory, worker_id):
    """`run_design(spec)` made once per test session, its LMIs started from the shipped
    design `shipped` (the arrays are the same, every certificate re-checked all the same).

    Under pytest-xdist the first worker designs it and saves the artefacts next to the
    workers' temporary folders under `name`; the others wait on the lock and load them
    (the content hash is checked by load_design), so the suite designs it once.
    """
    from filelock import FileLock

    from fahv.spec.artefacts import load_design, save_design

    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    previous = load_design(ROOT / "offline_design" / "designs" / shipped).warm_starts
    if worker_id == "master":  # not distributed
        return run_design(spec, log=lambda *_: None, previous=previous)
    shared = tmp_path_factory.getbasetemp().parent
    with FileLock(str(shared / f"{name}.lock")):
        folder = shared / name
        if (folder / "design.json").exists():
            return load_design(folder)
        d = run_design(spec, log=lambda *_: None, previous=previous)
        save_design(d, folder)
        return d


@pytest.fixture(scope="session")
def design(raw, tmp_path_factory, worker_id):
    """Case 1 designed with a small W sample (shared by the design, SIL and log tests),
    without the RMPC baseline (its ellipsoids are half a minute of LMIs; the tests that
    run the baseline take the shipped design, `paper_scenario_design`)."""
    spec = quick(raw, variants=[v for v in raw["variants"] if v != "rmpc"])
    return shared_design(spec, "cm_paper", "quick_design", tmp_path_factory, worker_id)


@pytest.fixture(scope="session")
def case2_design(tmp_path_factory, worker_id):
    """Case 2 (11-state ECM, adjustable law tau = 0.8) designed with a small W sample."""
    from fahv.spec.scenario import load_scenario

    raw2 = plain(load_scenario("offline_design/scenarios/case2.yaml").run_spec.data)
    return shared_design(quick(raw2), "ecm_paper", "quick_design_case2", tmp_path_factory,
                         worker_id)  # fmt: skip


@pytest.fixture(scope="session")
def paper_scenario_design():
    """The shipped cm_paper design with scenario case1_paper's arrays, as `fahv simulate`
    runs it (every variant of the scenario, the RMPC baseline's included)."""
    from fahv.certificate.verified import load_or_design

    return load_or_design(ROOT / SCENARIO, log=lambda *_: None)[1]


@pytest.fixture(scope="session")
def quick_case(design, raw, tmp_path_factory):
    """The test design as a case file plus its saved artefacts, for the `fahv` command:
    (case file, artefact folder) to pass as `fahv simulate|sil CASE --design DIR`."""

    folder = tmp_path_factory.mktemp("case")
    return store_quick(design, folder)


@pytest.fixture(scope="session")
def store_as_files():
    """`store_quick`, for the test folders that need their own copy."""
    return store_quick


def store_quick(design, folder):
    """Store a test design as `fahv` finds it: design file, stored design, scenario file.

    `design` is a design made from a whole case (`quick`); its design part is
    written to `folder/designs/quick.yaml`, its arrays stored beside it as that design
    file's design, and the case's scenario to `folder/scenarios/quick.yaml`. Returns
    (scenario file, artefact folder) to pass as `fahv simulate|sil SCENARIO --design DIR`.
    """
    from fahv.spec.artefacts import Design, save_design
    from fahv.spec.files import load_design_file, spec_file
    from fahv.spec.scenario import design_part
    from fahv.spec.schema import SCENARIO_KEYS

    c = design.case
    dpart = design_part(spec_file(c, "quick.yaml"))
    (folder / "designs").mkdir(parents=True, exist_ok=True)
    (folder / "scenarios").mkdir(parents=True, exist_ok=True)
    dfile = folder / "designs" / "quick.yaml"
    dfile.write_text(yaml.safe_dump(plain({**dpart.data, "name": "quick"}), sort_keys=False))
    summary = {
        k: v
        for k, v in design.summary.items()
        if k not in ("plant_params", "scenario_hash", "content_hash")
    }
    summary["provenance"] = {
        **summary["provenance"],
        "design_file": str(dfile),
        "design_file_hash": load_design_file(dfile).content_hash(),
    }
    stored = Design(load_design_file(dfile).data, dict(design.arrays), summary)
    stored.summary["design_hash"] = stored.content_hash()
    save_design(stored, folder / "designs" / "quick")
    scen = {k: c[k] for k in SCENARIO_KEYS if k in c}  # plant: optional
    scen["design"] = "quick"
    sfile = folder / "scenarios" / "quick.yaml"
    sfile.write_text(yaml.safe_dump(plain(scen), sort_keys=False))
    return sfile, folder / "designs" / "quick"


@pytest.fixture(scope="session")
def interrupt_fahv():
    """Run a `fahv` command, signal it once its run folder exists, check the interruption.

    `interrupt_fahv(args, out, signals, wait_s, timeout_s)`: starts `.venv/bin/fahv
    *args` in a new process group (as a terminal's foreground job), waits until
    `out/*/run.json` exists (for `fahv sil`, also until the plant's log says the graph
    is ready and the recording holds its first chunk: its start-up takes longer on a
    loaded machine), sleeps
    `wait_s`, sends `signals` to the group 0.2 s apart, and asserts exit 130, no
    traceback, the "interrupted at step K of 15000; run written to RUN" message, and a
    run whose status is interrupted, not truncated, with K steps recorded. Returns (K,
    the Recording, the output).
    """
    import os
    import re
    import subprocess
    import time

    from fahv.runs.bag import read_run
    from fahv.sil.workspace import ROOT, WS

    def run(args, out, signals, wait_s, timeout_s):
        p = subprocess.Popen(
            [str(ROOT / ".venv" / "bin" / "fahv"), *map(str, args)],
            cwd=ROOT, start_new_session=True, stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT, text=True,
        )  # fmt: skip
        t0 = time.monotonic()
        while not list(out.glob("*/run.json")) and time.monotonic() - t0 < timeout_s:
            time.sleep(0.1)
        if args[0] == "sil" and list(out.glob("*/run.json")):
            plant_log = WS / "log" / "sil" / next(out.glob("*/run.json")).parent.name / "logs"
            plant_log = plant_log / "plant.log"
            while time.monotonic() - t0 < timeout_s and not (
                plant_log.is_file() and "graph ready" in plant_log.read_text(errors="replace")
            ):
                time.sleep(0.1)
            # stepping: the recorder has written its first 1 MiB chunk (some 500 steps)
            folder = next(out.glob("*/run.json")).parent
            while time.monotonic() - t0 < timeout_s and not any(
                f.stat().st_size > 1 << 20 for f in folder.glob("*.mcap")
            ):
                time.sleep(0.1)
        time.sleep(wait_s)
        for i, sig in enumerate(signals):
            if i:
                time.sleep(0.2)
            os.killpg(p.pid, sig)
        text, _ = p.communicate(timeout=timeout_s)
        assert p.returncode == 130, text
        assert "Traceback" not in text
        m = re.search(r"interrupted at step (\d+) of 15000; run written to (\S+)", text)
        assert m, text
        rec = read_run(m.group(2))
        assert rec.metadata["status"] == "interrupted"
        assert not rec.truncated
        steps = int(m.group(1))
        assert int(rec.metadata["steps_recorded"]) == steps
        return steps, rec, text

    return run


def _hand_graph(quick_case, out, duration, watchdog=None, without=(), logs=None):
    """The README's graph by hand: `fahv sil --write-params`, then one `ros2 run` per node.

    Parameters
    ----------
    quick_case : (Path, Path)
        Case file and design folder (fixture `quick_case`).
    out : Path
        Folder of the parameter file `run.yaml` and of the run (`out/bags`).
    duration, watchdog : float
        Run length and node watchdog [s] (None: the default watchdog).
    without : sequence of str
        Nodes not started (a graph with a node missing).
    logs : Path, optional
        Each node's output in `logs/<node>.log` (else the shell's output).

    Returns
    -------
    (list of str, list of str, dict, Path)
        The shell lines (the shell ends once every node has exited and prints a line
        `exit NODE STATUS` per node: `_exit_statuses`), the nodes started in
        order, the environment (without ROS_DOMAIN_ID: the caller takes a free one) and
        the parameter file.
    """
    from fahv.sil.workspace import ROOT

    case_file, art = quick_case
    params = out / "run.yaml"
    argv = [
        str(ROOT / ".venv" / "bin" / "fahv"),
        "sil",
        str(case_file),
        "--design",
        str(art),
        "--duration",
        str(duration),
        "--out",
        str(out / "bags"),
        "--write-params",
        str(params),
    ]
    if watchdog is not None:
        argv += ["--watchdog", str(watchdog)]
    r = subprocess.run(argv, cwd=ROOT, capture_output=True, text=True, check=True)
    commands = [ln.strip() for ln in r.stdout.splitlines() if ln.strip().startswith("ros2 run")]
    commands = [c for c in commands if c.split()[3] != COMPOSED]  # one process per node
    if logs is not None:
        logs.mkdir(parents=True, exist_ok=True)
    lines, started = ["source ros_ws/install/setup.bash"], []
    for c in commands:  # each node in the background
        name = c.split()[3]
        if name in without:
            continue
        started.append(name)
        to_log = f" > {logs / name}.log 2>&1" if logs is not None else ""
        lines.append(f"{c.removesuffix(' &')}{to_log} & pid_{name}=$!")
    lines += [f'wait "$pid_{n}"; echo "exit {n} $?"' for n in started]
    env = {k: v for k, v in os.environ.items() if not k.startswith(("AMENT", "COLCON"))}
    env["ROS_AUTOMATIC_DISCOVERY_RANGE"] = "LOCALHOST"
    return lines, started, env, params


def _exit_statuses(stdout, logs=None):
    """{node: exit status} from the `exit NODE STATUS` lines of `_hand_graph`.

    With the nodes' `logs` folder, a node whose log shows a hung DDS teardown after it
    closed (`fahv.loop.graph.teardown_hung`: exit status 1 from the teardown's C-level
    timer) counts with the status it closed with, as the SIL runner counts it.
    """
    import re

    from fahv.loop.graph import teardown_hung

    out = {m[1]: int(m[2]) for m in re.finditer(r"^exit (\w+) (\d+)$", stdout, re.M)}
    for name, status in out.items():
        log = logs / f"{name}.log" if logs is not None else None
        if status == 1 and log is not None and log.is_file():
            own = teardown_hung(log.read_text(errors="replace"))
            out[name] = status if own is None else own
    return out


@pytest.fixture(scope="session")
def hand_graph():
    """The README's graph by hand as a function (`_hand_graph`)."""
    return _hand_graph


@pytest.fixture(scope="session")
def exit_statuses():
    """Per-node exit statuses of a hand-started graph's output (`_exit_statuses`)."""
    return _exit_statuses


#: Debian's Chromium, which scripts/test.sh installs for the browser test.
CHROMIUM = "/usr/bin/chromium"


@pytest.fixture(scope="session")
def rendered_body():
    """`rendered_body(page) -> {attribute: value}` of <body> once headless Chromium loaded it.

    The report pages write how many of their images loaded into `data-images-loaded`
    (`fahv.runs.report_page.COUNT_IMAGES`). Chromium starts with a fresh profile and
    without background networking (this machine's network is closed).
    """
    import re
    import tempfile

    if not Path(CHROMIUM).is_file():
        pytest.fail(f"{CHROMIUM} is missing: scripts/test.sh installs Debian's chromium "
                    "(apt-get install chromium) for this test")  # fmt: skip

    def render(page: Path) -> dict:
        with tempfile.TemporaryDirectory() as profile:
            out = subprocess.run(
                [CHROMIUM, "--headless", "--no-sandbox", "--disable-gpu", "--disable-quic",
                 "--no-first-run", "--disable-background-networking", "--disable-sync",
                 "--disable-component-update", f"--user-data-dir={profile}",
                 "--virtual-time-budget=10000", "--dump-dom", page.resolve().as_uri()],
                capture_output=True, text=True, timeout=120, check=True,
            ).stdout  # fmt: skip
        body = re.search(r"<body([^>]*)>", out)
        assert body, f"Chromium rendered no <body> of {page}"
        return dict(re.findall(r'([\w-]+)="([^"]*)"', body.group(1)))

    return render
