"""One run of a campaign again, recorded as a run folder (MCAP) for inspect, plot, replay.

Run ``i`` of variant ``v`` is rebuilt from the campaign folder alone: the campaign
data in ``campaign.json`` gives its dispersed values (:func:`fahv.campaign.draws.draw`,
a function of (seed, i)), ``design/`` the design it ran with. In process it goes
through :func:`fahv.loop.simulate.simulate` with the run's overrides, recorded by
:class:`fahv.runs.bag.RunWriter`; the batched simulator of the campaign gives the same
bits, so the metrics equal the recorded row exactly. With ``sil=True`` the same
parameters go through the ROS 2 node graph (:func:`fahv.runs.sil.run_sil`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from pathlib import Path

from fahv.campaign import store
from fahv.campaign.draws import _vehicle, draw, overrides
from fahv.design.artefacts import load_design
from fahv.errors import CampaignError
from fahv.loop.simulate import simulate
from fahv.runs.bag import RunWriter, read_run, run_result_of
from fahv.runs.metrics import metrics
from fahv.runs.sil import run_metadata, run_sil, write_run_params


@dataclass
class Rerun:
    """Result of :func:`rerun`.

    Attributes
    ----------
    bag : Path or None
        Run folder written (None if the run failed before any step).
    metrics : dict
        Metrics of the rerun (empty if it raised).
    recorded : dict or None
        The campaign's row of the run (None if the dataset does not hold it).
    differences : dict
        ``{metric: (recorded, rerun)}`` of every metric that differs (NaN equals NaN).
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
    """Re-simulate run ``index`` of a campaign folder and record it.

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
        Folder of the run folder (``<campaign>_<index>_<variant>_rerun_<time>/``;
        the SIL runner names its own ``<case>_<variant>_sil_<time>/``).
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
    if not 0 <= index < data["runs"]:
        raise CampaignError(f"run index must be in [0, {data['runs']}), got {index}")
    design = load_design(out / "design")
    ov = overrides(draw(data, design.case, index), design, variant)
    duration = float(man["duration"])
    recorded = next(
        (r for r in store.read_rows(out) if r["index"] == index and r["variant"] == variant),
        None,
    )
    bag, run, error = None, None, ""
    try:
        if sil:
            res = run_sil(design, variant, duration, Path(bags), watchdog_s, ov, quiet=quiet)
            bag = res.bag
            run = run_result_of(read_run(bag))
        else:
            stamp = time.strftime("%Y%m%d-%H%M%S")
            bag = Path(bags) / f"{man['name']}_{index}_{variant}_rerun_{stamp}"
            meta = run_metadata(design, variant, "campaign-rerun", duration, ov)
            meta.update(campaign=man["name"], campaign_hash=man["hash"], run_index=index)
            with RunWriter(bag, meta, design.case["Ts"]) as writer:
                write_run_params(design, variant, bag, bag / "params.yaml", duration, 10.0, ov)
                run = simulate(design, variant, duration, writer=writer, overrides=ov)
    except Exception as exc:  # noqa: BLE001 - compared with the recorded failure
        error = f"{type(exc).__name__}: {exc}"
    m = {}
    if run is not None:
        veh = _vehicle(design.summary.get("provenance", {}).get("vehicle_file", ""))
        m = metrics(run, veh.limits)
    diff = {}
    if recorded is not None:
        for k, v in m.items():
            if not _same(recorded.get(k), v):
                diff[k] = (recorded.get(k), v)
        if error and not recorded["reason"].startswith(error.split(" at t =")[0]):
            diff["reason"] = (recorded["reason"], error)
    return Rerun(bag, m, recorded, diff, error)
