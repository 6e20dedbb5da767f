"""Campaign engine: batches of runs as Dask tasks, results written as they finish.

The engine is Dask distributed: by default an embedded `LocalCluster` (one
single-threaded worker process per core, started and stopped here); with a scheduler
address, an existing cluster (`dask scheduler` and `dask worker ADDRESS` started
elsewhere, docs/guide/campaigns.md). There is no pool, queue or retry logic of our own:
tasks go to `Client.submit` and come back through `as_completed`; a worker that
dies takes its task with it and the scheduler runs it again elsewhere; an exception
inside a task is retried by Dask (`retries`).

One task = one batch (`run_batch`): up to `batch_size` run indices of one
variant, simulated together by `fahv.loop.batch.simulate_batch`. A run that
raises, diverges (non-finite state) or leaves the flight envelope is a row with
status `failed` and its reason; it never fails the task. The client writes each
finished batch as one Parquet file (`fahv.campaign.store`), so an interrupted
campaign (Ctrl-C, a killed worker, a lost scheduler) keeps every finished batch, and
`resume` runs exactly the (index, variant) pairs that are missing.

Every value of a run depends on (campaign seed, run index, variant) only, and the
batched simulator gives a run the same bits whatever batch it is in, so tables of
the same campaign are identical whatever the number of workers, the batching, or
the interruptions (only `wall_s` and `session` differ).
"""

from __future__ import annotations

import json
import os
import socket
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from fahv.campaign import store
from fahv.campaign.draws import _vehicle, draw, overrides, run_seed, uncertainty_scale
from fahv.campaign.spec import Campaign
from fahv.certificate.verified import load_or_design
from fahv.cluster import dask_client
from fahv.errors import CampaignError, DesignError
from fahv.interrupt import deferred
from fahv.loop.batch import simulate_batch
from fahv.loop.simulate import RunResult
from fahv.model.vehicle import ALPHA, THETA, H, V, load_vehicle
from fahv.runs.metrics import metrics
from fahv.sil.runner import run_coverage
from fahv.spec.artefacts import load_design, save_design
from fahv.spec.plant_dispersion import rate_limit_factor
from fahv.version import __version__

#: Decimation of the stored trajectories [s between samples].
TRAJECTORY_DT = 0.5


def envelope_exit(run: RunResult, envelope) -> str | None:
    """Why a run left the flight envelope (first step outside), None if it stayed in."""
    h, Vel = run.x[:, H], run.x[:, V]
    out = envelope.outside(h, Vel)
    if not out.any():
        return None
    k = int(np.argmax(out))
    return envelope.describe(float(run.t[k]), float(h[k]), float(Vel[k]))


def trajectory(run: RunResult, dt: float = TRAJECTORY_DT) -> dict:
    """Decimated histories of a run for the report's figures (lists of float32 values).

    Keys: `t` [s], `h_err` [ft], `V_err` [ft/s], `alpha_err_deg`,
    `theta_err_deg`, `Phi`, `delta_e_deg`, `tube_level`.
    """
    Ts = float(run.t[1] - run.t[0]) if run.t.size > 1 else dt
    s = slice(None, None, max(1, round(dt / Ts)))
    x, xr = run.x[s], run.x_r[s]
    cols = {
        "t": run.t[s],
        "h_err": x[:, H] - run.h_c[s],
        "V_err": x[:, V] - run.V_c[s],
        "alpha_err_deg": np.degrees(x[:, ALPHA] - xr[:, ALPHA]),
        "theta_err_deg": np.degrees(x[:, THETA] - xr[:, THETA]),
        "Phi": run.u[s, 0],
        "delta_e_deg": np.degrees(run.u[s, 1]),
        "tube_level": run.tube_level[s],
    }
    return {k: np.asarray(v, np.float32).tolist() for k, v in cols.items()}


def run_batch(design, data: dict, variant: str, indices: list[int], duration: float,
              values: list[dict] | None = None) -> dict:  # fmt: skip
    """One Dask task: the runs `indices` of `variant`, their rows and trajectories.

    Parameters
    ----------
    design : fahv.spec.artefacts.Design
        The campaign's design (scattered to the workers once).
    data : dict
        Validated campaign data.
    variant : str
    indices : list of int
        Run indices of the batch.
    duration : float
        Simulated time of each run [s].
    values : list of dict, optional
        The dispersed values of each run (`fahv.campaign.draws.draw`'s form); by
        default the campaign's draws of `indices`. A search over the dispersion space
        (`fahv.clearance`) gives its own points.

    Returns
    -------
    dict
        `rows` (one dict per run: index, variant, seeds, dispersed values,
        `coverage` (its coverage verdict, `fahv.sil.runner.run_coverage`), status,
        reason, every metric of `fahv.runs.metrics.metrics` (`settling_after_command_s`
        among them), `wall_s`), `trajectories` (per completed
        run), `wall_s` of the batch, `host`.
    """
    t0 = time.perf_counter()
    case, seed = design.case, data["seed"]
    if values is None:
        values = [draw(data, case, i) for i in indices]
    if len(values) != len(indices):
        raise ValueError(f"{len(values)} runs' values for {len(indices)} run indices")
    scale = uncertainty_scale(data)
    results: list = [None] * len(indices)
    ovs, where, covered = [], [], [""] * len(indices)
    for j, v in enumerate(values):
        try:
            ovs.append(overrides(v, design, variant, scale))
            where.append(j)
        except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
            results[j] = exc
        else:
            covered[j] = run_coverage(design, duration, ovs[-1]).text()
    for j, res in zip(where, simulate_batch(design, variant, ovs, duration), strict=True):
        results[j] = res
    veh = _vehicle(design.summary.get("provenance", {}).get("vehicle_file", ""))
    rows, trajs = [], []
    factors = dict(zip(where, (rate_limit_factor(case, ov) for ov in ovs), strict=True))
    for j, (i, vals, res, cov) in enumerate(zip(indices, values, results, covered,
                                                strict=True)):  # fmt: skip
        row = {"index": int(i), "variant": variant, "campaign_seed": seed,
               "run_seed": run_seed(seed, i), **vals, "coverage": cov}  # fmt: skip
        failure = f"{type(res).__name__}: {res}" if isinstance(res, BaseException) else None
        run = getattr(res, "partial", None) if failure else res
        if run is None:
            row.update(status="failed", reason=failure)
        else:
            # a failed run keeps the metrics and trajectory of the steps it flew
            try:
                # judged against the rates of the run's own (dispersed) servos
                m = metrics(run, veh.limits.with_rate_factor(factors.get(j, 1.0)))
            except Exception as exc:  # noqa: BLE001 - recorded as the run's failure
                why = f"metrics: {type(exc).__name__}: {exc}"
                row.update(status="failed", reason=failure or why)
            else:
                exit_reason = envelope_exit(run, veh.envelope)
                row.update(
                    status="ok" if failure is None and exit_reason is None else "failed",
                    reason="; ".join(r for r in (failure, exit_reason) if r),
                    **m,
                )
                trajs.append({"index": int(i), "variant": variant, **trajectory(run)})
        rows.append(row)
    wall = time.perf_counter() - t0
    for row in rows:
        row["wall_s"] = wall / len(rows)
    return {"rows": rows, "trajectories": trajs, "wall_s": wall, "host": socket.gethostname()}


@dataclass
class Outcome:
    """What one call of `run_campaign` did.

    Attributes
    ----------
    out_dir : Path
    total : int
        Runs of the campaign (samples x variants).
    before : int
        Runs already in the dataset when the call started.
    new : int
        Runs finished and written by this call.
    failed : int
        Of those, runs with status `failed`.
    wall_s : float
        Wall time of the call [s] (cluster start to last write).
    interrupted : bool
        Stopped by Ctrl-C (KeyboardInterrupt).
    errors : list of str
        Tasks that failed as a whole (their runs stay missing for `resume`).
    """

    out_dir: Path
    total: int
    before: int = 0
    new: int = 0
    failed: int = 0
    wall_s: float = 0.0
    interrupted: bool = False
    errors: list[str] = field(default_factory=list)

    @property
    def missing(self) -> int:
        """Runs still missing from the dataset."""
        return self.total - self.before - self.new


def prepare(campaign: Campaign, out_dir: Path, resume: bool, vehicle=None, log=print):
    """Create or check the campaign folder and return its design.

    The design is the one saved in `out_dir/design` (a resumed campaign must keep
    it), else the stored, verified design of the campaign's scenario with the
    scenario's arrays (`fahv.certificate.verified.load_or_design`; nothing is designed).

    Raises
    ------
    CampaignError
        If the folder holds results and `resume` is False, if it belongs to another
        campaign or case content, or if its design no longer matches the code.
    """
    out = Path(out_dir)
    veh = load_vehicle() if vehicle is None else vehicle
    man = store.read_manifest(out)
    done = len(store.done_keys(out))
    if done and not resume:
        raise CampaignError(
            f"{out} already holds {done} runs of a campaign: use --resume to complete it, "
            "or another --out"
        )
    if man is not None and man["hash"] != campaign.content_hash():
        raise CampaignError(
            f"{out} holds the campaign {man['name']} with other content (hash {man['hash']}, "
            f"now {campaign.content_hash()}): the campaign or case file changed; use another "
            "--out"
        )
    out.mkdir(parents=True, exist_ok=True)
    design = None
    try:
        design = load_design(out / "design")
    except DesignError:
        pass
    same = design is not None and _same(design.case, campaign.run_spec.data)
    if design is not None and done and not same:
        raise CampaignError(f"{out}: its design belongs to another scenario content; its runs "
                            "cannot be completed, use another --out")  # fmt: skip
    if not same:
        design = load_or_design(campaign.run_spec.path, None, veh.source_file if not veh.packaged
                                else None, log=log, allow_uncertified=True)[1]  # fmt: skip
        save_design(design, out / "design")
    if man is None:
        store.write_manifest(
            out,
            {
                "name": campaign.name,
                "hash": campaign.content_hash(),
                "campaign": campaign.data,
                "campaign_file": str(campaign.path),
                "case": campaign.run_spec.data,
                "duration": campaign.duration,
                "design_hash": design.summary["design_hash"],
                "code_version": __version__,
                "started": time.strftime("%Y-%m-%d %H:%M:%S"),
            },
        )
    return design


def _same(a: dict, b: dict) -> bool:
    def norm(x):
        return json.dumps(x, sort_keys=True, default=list)

    return norm(a) == norm(b)


def batches(campaign: Campaign, done: set) -> list[tuple[str, list[int]]]:
    """(variant, indices) of every batch still to run.

    In index order, the variants of one range of indices next to each other (runs
    0-99 of every variant, then 100-199, ...), so that the finished part of an
    interrupted or partly run campaign holds both runs of each pair (paired report).
    """
    size = campaign["batch_size"]
    todo = {
        v: [i for i in range(campaign["runs"]) if (i, v) not in done] for v in campaign["variants"]
    }
    out = []
    for j in range(0, max((len(t) for t in todo.values()), default=0), size):
        out += [(v, t[j : j + size]) for v, t in todo.items() if t[j : j + size]]
    return out


def run_campaign(
    campaign: Campaign,
    out_dir: str | Path,
    scheduler: str | None = None,
    workers: int | None = None,
    resume: bool = False,
    progress: bool = True,
    on_batch: Callable | None = None,
    vehicle=None,
    log=print,
    dashboard: str | None = None,
) -> Outcome:
    """Run (or complete) a campaign on Dask, writing each finished batch to `out_dir`.

    One concept, kept whole: the Dask client's lifetime, the interruption and the
    manifest update are one try/finally around the batches.

    Parameters
    ----------
    campaign : Campaign
    out_dir : path
        Campaign folder (created; see `fahv.campaign.store`).
    scheduler : str, optional
        Address of an existing Dask scheduler (`tcp://host:8786`); default: a
        LocalCluster started and stopped here.
    workers : int, optional
        Worker processes of the LocalCluster (default: the machine's cores).
    resume : bool
        Complete a folder that holds results (only the missing runs are run).
    progress : bool
        Progress bar (runs done, failures, rate, ETA) on stderr.
    on_batch : callable, optional
        `on_batch(client, runs_written)` after each written batch (tests use it to
        kill a worker).
    vehicle : fahv.model.vehicle.Vehicle, optional
    log : callable
        Receives progress lines (and the dashboard's address).
    dashboard : str, optional
        Address of the LocalCluster's Dask dashboard (e.g. `":8787"`); default none
        (`dask_client`).

    Returns
    -------
    Outcome

    Raises
    ------
    CampaignError
        From `prepare`.
    """
    from dask.distributed import as_completed
    from tqdm import tqdm

    out = Path(out_dir)
    design = prepare(campaign, out, resume, vehicle, log)
    done = store.done_keys(out)
    total = campaign["runs"] * len(campaign["variants"])
    res = Outcome(out, total, before=len(done))
    todo = batches(campaign, done)
    if not todo:
        return res
    session = store.next_session(out)
    t0 = time.perf_counter()
    client, cluster = dask_client(scheduler, workers, dashboard)
    if cluster is not None and dashboard is not None:
        log(f"Dask dashboard: {client.dashboard_link}")
    bar = tqdm(total=total, initial=len(done), unit="run", desc=campaign.name,
               disable=not progress, smoothing=0.05)  # fmt: skip
    futures = []
    try:
        design_f = client.scatter(design, broadcast=True)
        tag = f"{campaign.content_hash()}-{session}"
        for b, (variant, idx) in enumerate(todo):
            futures.append(
                client.submit(
                    run_batch,
                    design_f,
                    campaign.data,
                    variant,
                    idx,
                    campaign.duration,
                    key=f"fahv-batch-{tag}-{b}",
                    retries=2,
                    pure=False,
                )  # fmt: skip
            )
        names = {f.key: f"part-{session:03d}-{b:05d}" for b, f in enumerate(futures)}
        for fut in as_completed(futures):
            try:
                batch = fut.result()
            except Exception as exc:  # noqa: BLE001 - the batch stays missing for --resume
                res.errors.append(f"{fut.key}: {type(exc).__name__}: {exc}")
                continue
            rows = batch["rows"]
            for row in rows:
                row["session"] = session
            with deferred():  # a stop waits until the batch is written and counted
                store.write_part(out, store.TRAJECTORIES, names[fut.key], batch["trajectories"])
                store.write_part(out, store.RESULTS, names[fut.key], rows)
                res.new += len(rows)
                res.failed += sum(r["status"] != "ok" for r in rows)
            bar.set_postfix(failed=res.failed, refresh=False)
            bar.update(len(rows))
            if on_batch is not None:
                on_batch(client, res.new)
    except KeyboardInterrupt:
        res.interrupted = True
    finally:
        bar.close()
        res.wall_s = time.perf_counter() - t0
        try:
            client.cancel(futures)
            client.close()
            if cluster is not None:
                cluster.close()
        except Exception:  # noqa: BLE001 - shutting down after an interruption
            pass
        man = store.read_manifest(out) or {}
        engine = scheduler or f"LocalCluster({workers or os.cpu_count()})"
        man.setdefault("sessions", []).append(
            {"session": session, "engine": engine, "wall_s": res.wall_s, "new": res.new,
             "failed": res.failed, "interrupted": res.interrupted, "errors": len(res.errors)}
        )  # fmt: skip
        store.write_manifest(out, man)
    return res
