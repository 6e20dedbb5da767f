"""One run of a campaign again, recorded as a run folder (MCAP) for inspect, plot, replay.

Run `i` of variant `v` is rebuilt from the campaign folder alone: the campaign
data in `campaign.json` gives its dispersed values (`fahv.campaign.draws.draw`,
a function of (seed, i)), `design/` the design it ran with. In process it goes
through `fahv.loop.simulate.simulate` with the run's overrides, recorded by
`fahv.runs.writer.RunWriter`; the batched simulator of the campaign gives the same
bits, so the metrics equal the recorded row exactly. With `sil=True` the same
parameters go through the ROS 2 node graph (`fahv.sil.runner.run_sil`). The run
file records the run's own values: its fault in the run metadata (`fault_*`), the
campaign, its hash and seed, the run index and every dispersed value
(`dispersed.<column>`), and the parameter file of every node.

`rerun_file` reruns any run from its file alone (the parameter file it holds),
whoever wrote it, and compares the metrics with the recorded run's.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from fahv.campaign import store
from fahv.campaign.draws import _vehicle, draw, overrides, row_values, uncertainty_scale
from fahv.errors import CampaignError, RunError
from fahv.loop.simulate import simulate, simulate_parameters
from fahv.runs.bag import PARAMS, read_run, run_result_of, start_metadata
from fahv.runs.judged import run_limits
from fahv.runs.metrics import metrics
from fahv.runs.writer import RunWriter
from fahv.sil.runner import recorder_metadata, run_graph, run_parameter_file, run_sil
from fahv.spec.artefacts import load_design
from fahv.spec.plant_dispersion import rate_limit_factor


@dataclass
class Rerun:
    """Result of `rerun`.

    Attributes
    ----------
    bag : Path or None
        Run folder written (None if the run failed before any step).
    metrics : dict
        Metrics of the rerun (empty if it raised).
    recorded : dict or None
        The campaign's row of the run (None if the dataset does not hold it).
    differences : dict
        `{metric: (recorded, rerun)}` of every metric that differs (NaN equals NaN).
    error : str
        Exception of the rerun ("" if none), to compare with the recorded reason.
    """

    bag: Path | None
    metrics: dict
    recorded: dict | None
    differences: dict = field(default_factory=dict)
    error: str = ""

    @property
    def identical(self) -> bool:
        """True if the dataset holds the run and every metric is the same."""
        return self.recorded is not None and not self.differences


def _same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return a == b


def rerun(
    out_dir: str | Path,
    index: int,
    variant: str | None = None,
    sil: bool = False,
    bags: str | Path = "bags",
    watchdog_s: float = 10.0,
    quiet: bool = True,
) -> Rerun:
    """Re-simulate run `index` of a campaign folder and record it.

    Parameters
    ----------
    out_dir : path
        Campaign folder.
    index : int
        Run index.
    variant : str, optional
        The campaign's first variant by default.
    sil : bool
        Through the ROS 2 node graph instead of in process.
    bags : path
        Folder of the run folder (`<campaign>_<index>_<variant>_rerun_<time>/`, with
        `_sil` before the time for a SIL rerun).
    watchdog_s : float
        Node watchdog of a SIL run [s].
    quiet : bool
        No progress lines from the SIL runner.

    Raises
    ------
    CampaignError
        If the folder is not a campaign folder, or the index or variant is not one of
        the campaign's.
    """
    out = Path(out_dir)
    man = store.read_manifest(out)
    if man is None:
        raise CampaignError(f"{out} is not a campaign folder (no {store.MANIFEST})")
    data = man["campaign"]
    variant = data["variants"][0] if variant is None else variant
    if variant not in data["variants"]:
        raise CampaignError(f"variant '{variant}' is not in the campaign's {data['variants']}")
    clearance = man.get("kind") == "clearance"  # its runs' indices go beyond the draws'
    if not clearance and not 0 <= index < data["runs"]:
        raise CampaignError(f"run index must be in [0, {data['runs']}), got {index}")
    design = load_design(out / "design")
    recorded = next(
        (r for r in store.read_rows(out) if r["index"] == index and r["variant"] == variant),
        None,
    )
    if clearance:  # a searched point: its values are in its row
        if recorded is None:
            raise CampaignError(f"{out} holds no run {index} of variant '{variant}'")
        values = row_values(recorded)
    else:
        values = draw(data, design.case, index)
    ov = overrides(values, design, variant, uncertainty_scale(data))
    duration = float(man["duration"])
    extra = {
        "campaign": man["name"],
        "campaign_hash": man["hash"],
        "campaign_seed": data["seed"],
        "run_index": index,
        **{f"dispersed.{k}": v for k, v in values.items()},
    }
    name = f"{man['name']}_{index}_{variant}_rerun"
    bag, run, error = None, None, ""
    try:
        if sil:
            res = run_sil(
                design, variant, duration, Path(bags), watchdog_s, ov, quiet=quiet,
                name=f"{name}_sil", metadata=extra,
            )  # fmt: skip
            bag = res.bag
            run = run_result_of(read_run(bag))
        else:
            bag = Path(bags) / f"{name}_{time.strftime('%Y%m%d-%H%M%S')}"
            content = run_parameter_file(
                design, variant, bag, duration, watchdog_s, ov, "campaign-rerun", extra
            )
            meta = recorder_metadata(content)
            with RunWriter(bag, meta, design.case["Ts"], params=content) as writer:
                run = simulate(design, variant, duration, writer=writer, overrides=ov)
    except Exception as exc:  # noqa: BLE001 - compared with the recorded failure
        error = f"{type(exc).__name__}: {exc}"
    m = {}
    if run is not None:
        veh = _vehicle(design.summary.get("provenance", {}).get("vehicle_file", ""))
        m = metrics(run, veh.limits.with_rate_factor(rate_limit_factor(design.case, ov)))
    diff = {}
    if recorded is not None:
        for k, v in m.items():
            if not _same(recorded.get(k), v):
                diff[k] = (recorded.get(k), v)
        if error and not recorded["reason"].startswith(error.split(" at t =")[0]):
            diff["reason"] = (recorded["reason"], error)
    return Rerun(bag, m, recorded, diff, error)


def rerun_file(
    run: str | Path,
    sil: bool = False,
    bags: str | Path = "bags",
    watchdog_s: float = 10.0,
    quiet: bool = True,
) -> Rerun:
    """Rerun a recorded run from its file alone and compare the metrics with it.

    The run's parameter file (every node, stored in the run file by every writer)
    is simulated in process (`fahv.loop.simulate.simulate_parameters`), or with
    `sil=True` run through the node graph; the new run is recorded to
    `bags/<run>_rerun[_sil]_<time>/` with the recorded run's metadata (source
    `rerun`, `rerun_of`).

    Parameters
    ----------
    run : path
        Run folder or .mcap file (renamed, copied or alone).
    sil : bool
        Through the ROS 2 node graph instead of in process.
    bags : path
        Folder of the new run folder.
    watchdog_s : float
        Node watchdog of a SIL rerun [s].
    quiet : bool
        No progress lines from the SIL runner.

    Returns
    -------
    Rerun
        `recorded`: the metrics of the recorded run; `differences` those that
        differ in the rerun.

    Raises
    ------
    RunError
        If the run cannot be read, holds no parameter file (runs of earlier versions:
        rerun them from their campaign folder or case), or no complete step.
    """
    rec = read_run(run)
    params = rec.params()
    if params is None:
        raise RunError(
            f"{rec.path} holds no parameter file ({PARAMS}): a run of an earlier version; "
            "rerun it from its campaign folder (fahv campaign rerun DIR INDEX) or its case"
        )
    limits = run_limits(rec)
    recorded = metrics(run_result_of(rec), limits)
    meta = {**start_metadata(rec.metadata), "rerun_of": str(rec.path.resolve())}
    content = {k: {"ros__parameters": dict(v["ros__parameters"])} for k, v in params.items()}
    name = f"{rec.path.stem}_rerun"
    bag, new, error = None, None, ""
    try:
        if sil:
            meta["source"] = "sil"
            content["recorder"]["ros__parameters"]["metadata_json"] = json.dumps(meta)
            res = run_graph(content, f"{name}_sil_{time.strftime('%Y%m%d-%H%M%S')}",
                            Path(bags), quiet, domain_id=None)  # fmt: skip
            bag = res.bag
            new = run_result_of(read_run(bag))
        else:
            meta["source"] = "rerun"
            bag = Path(bags) / f"{name}_{time.strftime('%Y%m%d-%H%M%S')}"
            content["recorder"]["ros__parameters"].update(
                bag=str(bag.resolve()), metadata_json=json.dumps(meta)
            )
            nodes = {k: v["ros__parameters"] for k, v in content.items()
                     if k not in ("recorder", "/**")}  # fmt: skip
            with RunWriter(bag, meta, float(meta.get("Ts", nodes["plant"]["Ts"])),
                           params=content) as writer:  # fmt: skip
                new = simulate_parameters(nodes, writer=writer, info=meta)
    except Exception as exc:  # noqa: BLE001 - reported with the differences
        error = f"{type(exc).__name__}: {exc}"
    m = metrics(new, limits) if new is not None else {}
    diff = {k: (recorded.get(k), v) for k, v in m.items() if not _same(recorded.get(k), v)}
    if error:
        diff["error"] = ("", error)
    return Rerun(bag, m, recorded, diff, error)
