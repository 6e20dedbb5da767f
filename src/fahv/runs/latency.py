"""Where the wall time of a SIL step goes: per-hop latency from recorded DDS timestamps.

The SIL recorder keeps, for every message it records, the DDS source timestamp (wall
clock when the producing node published it) and its own receive time, and attaches them
to the run file when it closes the run (attachment `timestamps.npz`,
`timestamps_npz`; runs of earlier versions have the same file in the run folder). From
them, `hop_latencies` gives for every loop node of the step

    latency(node, k) = source time of its output of step k
                       - latest source time of its inputs of step k
                         (of step k - 1 for an input it takes from the previous step)

i.e. the DDS transport of its last input, the executor's wake-up, the node's own
computation and the publication, as seen on the wall clock (the plant's output of
step k + 1 follows its input of step k). The nodes of one step run one after the
other along the critical path (plant -> state_estimator -> notch_filter |
nominal_trajectory -> controller -> fault_injector -> plant), so these latencies add up
to the step period. The
recorder's own receive delay (receive - source) estimates one DDS hop without any
computation.

Runs of `fahv simulate` have no such file: their timing is not a graph's.
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import yaml

from fahv.loop.graph import CONTROLLER_NODES, GRAPH, PREVIOUS, TOPICS, graph_nodes

#: Name of the recorded timestamps (the run file's attachment; a file in older run folders).
TIMESTAMPS_FILE = "timestamps.npz"
#: The lockstep master: its output of step k + 1 answers its input of step k.
MASTER = "plant"


def _key(topic: str) -> str:
    return topic.strip("/").replace("/", ".")


def _arrays(stamps: dict) -> dict[str, np.ndarray]:
    return {_key(t): np.asarray(v, dtype=np.int64).reshape(-1, 3) for t, v in stamps.items()}


def timestamps_npz(stamps: dict) -> bytes:
    """The recorder's timestamps of a run as the bytes of a compressed `.npz` file.

    Parameters
    ----------
    stamps : dict
        Topic -> flat int64 sequence `k, source_ns, received_ns` per message
        (array of 3 N values, or an (N, 3) array); wall-clock nanoseconds.

    Returns
    -------
    bytes
        The attachment `timestamps.npz` of the run file (`load_timestamps`
        reads it back).
    """
    buf = io.BytesIO()
    np.savez_compressed(buf, **_arrays(stamps))
    return buf.getvalue()


def save_timestamps(folder: str | Path, stamps: dict) -> Path:
    """Write the timestamps to `<folder>/timestamps.npz` (the layout of earlier runs).

    Parameters
    ----------
    folder : path
        Folder (exists).
    stamps : dict
        As `timestamps_npz`.

    Returns
    -------
    Path
        The file written.

    Raises
    ------
    OSError
        If the file cannot be written.
    """
    path = Path(folder) / TIMESTAMPS_FILE
    path.write_bytes(timestamps_npz(stamps))
    return path


def load_timestamps(source: str | Path | bytes | None) -> dict[str, np.ndarray] | None:
    """Timestamps of a run: topic -> (N, 3) int64 [k, source_ns, received_ns].

    Parameters
    ----------
    source : bytes, path or None
        The attachment's bytes (`timestamps_npz`), or a run folder of an earlier
        version holding `timestamps.npz`.

    Returns
    -------
    dict or None
        `{topic: timestamps}`; None when there are no (readable) timestamps.
    """
    if source is None:
        return None
    try:
        data = io.BytesIO(source) if isinstance(source, bytes) else Path(source) / TIMESTAMPS_FILE
        with np.load(data) as z:
            return {t: z[_key(t)] for t in TOPICS if _key(t) in z.files}
    except (OSError, ValueError, KeyError, EOFError):
        return None


def run_controller(params: dict | str | Path | None) -> str:
    """Controller node of a run from its parameter file (`tube_mpc` if unknown).

    `params`: the parsed parameter file (`{node: {"ros__parameters": ...}}`), or a
    run folder of an earlier version holding `params.yaml`.
    """
    if params is not None and not isinstance(params, dict):
        try:
            params = yaml.safe_load((Path(params) / "params.yaml").read_text())
        except (OSError, yaml.YAMLError):
            params = None
    params = params if isinstance(params, dict) else {}
    return next((n for n in CONTROLLER_NODES if n in params), CONTROLLER_NODES[0])


def _source_by_step(rows: np.ndarray) -> dict[int, int]:
    return {int(k): int(src) for k, src, _ in rows}


def _stats(values_ns: np.ndarray) -> dict:
    v = np.asarray(values_ns, dtype=float) * 1e-6
    if v.size == 0:
        return {"n": 0, "median_ms": None, "p90_ms": None, "max_ms": None}
    return {
        "n": int(v.size),
        "median_ms": float(np.median(v)),
        "p90_ms": float(np.percentile(v, 90)),
        "max_ms": float(v.max()),
    }


def hop_latencies(stamps: dict[str, np.ndarray], controller: str = "tube_mpc") -> dict:
    """Per-hop latency breakdown of a SIL run (see the module docstring).

    Parameters
    ----------
    stamps : dict
        `load_timestamps` of the run.
    controller : str
        Controller node of the run (one of `fahv.loop.graph.CONTROLLER_NODES`).

    Returns
    -------
    dict
        `hops`: one entry per loop node in graph order, with `node`, `inputs`,
        `output` (the output the next node waits for) and the statistics over the
        steps: `n`, `median_ms`, `p90_ms`, `max_ms` [ms of wall time];
        `step`: the same statistics of the step period (state k -> state k + 1);
        `dds_hop`: the recorder's receive delay over every loop topic (one DDS hop
        without computation).
    """
    nodes = [n for n in graph_nodes(controller, record=False) if n in GRAPH]
    consumed = {t for n in nodes for t in GRAPH[n][0]}
    src = {t: _source_by_step(rows) for t, rows in stamps.items()}
    hops = []
    for n in nodes:
        inputs, outputs = GRAPH[n]
        out = next((t for t in outputs if t in consumed), outputs[0])
        lag = 1 if n == MASTER else 0
        # input steps: k (k - 1 for the topics taken from the previous step)
        shift = {t: 1 if t in PREVIOUS.get(n, ()) else 0 for t in inputs}
        lat = []
        for k, t_out in src.get(out, {}).items():
            k_in = k - lag
            steps = {t: k_in - shift[t] for t in inputs if k_in - shift[t] >= 0}
            if k_in >= 0 and steps and all(j in src.get(t, {}) for t, j in steps.items()):
                lat.append(t_out - max(src[t][j] for t, j in steps.items()))
        hops.append({"node": n, "inputs": list(inputs), "output": out, **_stats(lat)})
    state = src.get("/hsv/state", {})
    period = [state[k + 1] - state[k] for k in state if k + 1 in state]
    delay = [rows[:, 2] - rows[:, 1] for rows in stamps.values() if len(rows)]
    return {
        "hops": hops,
        "step": _stats(period),
        "dds_hop": _stats(np.concatenate(delay) if delay else np.zeros(0)),
    }


def run_latencies(run: bytes | str | Path | None, params=None) -> dict | None:
    """`hop_latencies` of a run, or None if it has no timestamps.

    Parameters
    ----------
    run : bytes, path or None
        The timestamps attachment itself, or a run (folder or .mcap: its attachment;
        a run folder of an earlier version: its `timestamps.npz`).
    params : dict, optional
        The run's parameter file (`run_controller`); by default the run's.
    """
    if run is None or isinstance(run, bytes):
        stamps = load_timestamps(run)
    else:
        from fahv.errors import RunError
        from fahv.runs.bag import bag_paths, run_attachments, run_params

        try:
            data = run_attachments(run).get(TIMESTAMPS_FILE)
            if params is None:
                params = run_params(run)
        except RunError:
            data = None
        stamps = load_timestamps(data if data is not None else bag_paths(run)[0])
        if params is None:
            params = bag_paths(run)[0]
    if not stamps:
        return None
    return hop_latencies(stamps, run_controller(params))


def format_latencies(lat: dict) -> str:
    """Text table of `hop_latencies`: median, 90th percentile and max per hop [ms]."""

    def row(label: str, s: dict) -> str:
        f = [("-" if s[k] is None else f"{s[k]:.3f}") for k in ("median_ms", "p90_ms", "max_ms")]
        share = (
            f"{100 * s['median_ms'] / lat['step']['median_ms']:.0f} %"
            if s["median_ms"] is not None and lat["step"]["median_ms"]
            else "-"
        )
        return f"{label:<52} {f[0]:>8} {f[1]:>8} {f[2]:>9} {share:>7}"

    lines = [
        f"{'wall-clock latency per hop (DDS source timestamps)':<52} {'median':>8} {'p90':>8} "
        f"{'max [ms]':>9} {'of step':>7}"
    ]
    for h in lat["hops"]:
        label = f"{h['node']}: {' + '.join(h['inputs'])} -> {h['output']}"
        if len(label) > 52:
            label = f"{h['node']} -> {h['output']}"
        lines.append(row(label, h))
    lines.append(row("step period: /hsv/state k -> k + 1", lat["step"]))
    lines.append(row("one DDS hop (recorder receive - source)", lat["dds_hop"]))
    return "\n".join(lines)
