"""Campaign throughput: runs per second for one run, one batch, and 1 vs 2 Dask workers.

Case 1 on the paper's design (scenario case1_paper, Tube-MPC with the notch), runs
dispersed as in offline_design/campaigns/case1_paper.yaml (uncertainty box, loss of
effectiveness 0-30 %), shortened to DURATION seconds of simulated time; every figure is
also given per 300 s run, the length of the 1000-run campaign, with the time that
campaign would take.

The machine is shared: the figures move with its load (run twice and compare).

Last, the machine's own ceiling for two workers: the same batch simulated by one
process alone, then by two processes at once (no Dask, no files). What two processes
get over one is the most two Dask workers can get over one worker here; on a virtual
machine whose two cores share a physical one it is well below 2.

Usage: .venv/bin/python benchmarks/bench_campaign.py [DURATION] [BATCH] [RUNS] [--smoke]
       (defaults 30 s, 50 runs per batch, 200 runs per campaign)

`--smoke` runs the same code path at a tiny size in seconds (CI's check that the
benchmark still runs; its figures mean nothing): 1 s runs, batches of 2, a campaign of 2
runs on one Dask worker only, and the ceiling with those batches.
"""

import argparse
import io
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import yaml

from fahv.campaign.draws import draw, overrides
from fahv.campaign.engine import run_campaign
from fahv.campaign.spec import campaign_from_mapping, load_campaign
from fahv.certificate.verified import load_or_design
from fahv.loop.batch import simulate_batch
from fahv.loop.simulate import simulate

ROOT = Path(__file__).resolve().parents[1]
CAMPAIGN = ROOT / "offline_design" / "campaigns" / "case1_paper.yaml"
FULL = 300.0
#: --smoke: DURATION [s], BATCH and RUNS.
SMOKE = (1.0, 2, 2)


def line(what, runs, seconds, duration):
    rate = runs / seconds
    per300 = seconds / runs * FULL / duration
    print(
        f"  {what:<34} {rate:8.2f} runs/s  ({per300:6.2f} s per 300 s run; 1000 runs: "
        f"{1000 * per300 / 60:6.1f} min of this engine)"
    )


def case1_runs(batch: int):
    """The campaign's design and the overrides of its first `batch` runs.

    The design is the campaign engine's: the scenario's stored, verified design with the
    scenario's arrays (`fahv.design.store.load_or_design`, its draws beyond the
    design's range allowed as the engine allows them).
    """
    c = load_campaign(CAMPAIGN)
    _, design, _ = load_or_design(c.run_spec.path, log=io.StringIO().write, allow_uncertified=True)
    return design, [
        overrides(draw(c.data, design.case, i), design, "tube_mpc") for i in range(batch)
    ]


def one_batch(duration: float, batch: int) -> None:
    """Simulate one batch (the ceiling measurement's unit of work)."""
    design, ovs = case1_runs(batch)
    simulate(design, "tube_mpc", 1.0, overrides=ovs[0])  # warm-up, as in main()
    t0 = time.perf_counter()
    simulate_batch(design, "tube_mpc", ovs, duration)
    print(f"{time.perf_counter() - t0:.6f}")


def ceiling(duration: float, batch: int) -> None:
    """One process alone, then two at once, each simulating one batch; print both."""
    cmd = [sys.executable, __file__, str(duration), str(batch), "--one-batch"]

    def wall(n):  # the slowest of n processes started together
        procs = [subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True) for _ in range(n)]
        outs = [p.communicate()[0] for p in procs]
        if any(p.returncode for p in procs):
            sys.exit(f"bench_campaign: {' '.join(cmd)} failed")
        return max(float(out.split()[-1]) for out in outs)

    one = wall(1)
    two = wall(2)
    line("ceiling: one process, one batch", batch, one, duration)
    line("ceiling: two processes at once", 2 * batch, two, duration)
    print(f"  two processes get {2 * one / two:.2f}x one process (the bound for 2 workers / 1)")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("duration", nargs="?", type=float, default=30.0,
                    help="simulated time per run [s]")  # fmt: skip
    ap.add_argument("batch", nargs="?", type=int, default=50, help="runs per batch")
    ap.add_argument("runs", nargs="?", type=int, default=200, help="runs per campaign")
    ap.add_argument("--smoke", action="store_true",
                    help="tiny size, one Dask worker (CI: the benchmark still runs)")  # fmt: skip
    ap.add_argument("--one-batch", action="store_true", help=argparse.SUPPRESS)  # ceiling()
    args = ap.parse_args()
    if args.one_batch:
        one_batch(args.duration, args.batch)
        return
    duration, batch, runs = SMOKE if args.smoke else (args.duration, args.batch, args.runs)
    worker_counts = (1,) if args.smoke else (1, 2)
    if args.smoke:
        print(f"smoke: {duration:g} s runs, batches of {batch}, {runs} runs on one Dask worker "
              "(2 workers skipped; the figures mean nothing)")  # fmt: skip
    design, ovs = case1_runs(batch)
    print(f"Case 1 tube_mpc, {duration:g} s per run (Ts 0.02 s: {duration / 0.02:.0f} steps)")
    # warm-up: compiled kernels (numba cache), imports and first-call costs are not timed
    t0 = time.perf_counter()
    simulate(design, "tube_mpc", 1.0, overrides=ovs[0])
    print(f"  warm-up (1 s run: imports, compiled-kernel cache) {time.perf_counter() - t0:.2f} s")
    t0 = time.perf_counter()
    simulate(design, "tube_mpc", duration, overrides=ovs[0])
    line("one run, simulate()", 1, time.perf_counter() - t0, duration)
    t0 = time.perf_counter()
    simulate_batch(design, "tube_mpc", ovs[:1], duration)
    line("one run, simulate_batch (B = 1)", 1, time.perf_counter() - t0, duration)
    t0 = time.perf_counter()
    simulate_batch(design, "tube_mpc", ovs, duration)
    line(f"one batch, simulate_batch (B = {batch})", batch, time.perf_counter() - t0, duration)
    data = yaml.safe_load(CAMPAIGN.read_text())
    data.update(runs=runs, duration=duration, batch_size=batch, name="bench")
    for workers in worker_counts:
        camp = campaign_from_mapping(data, "bench", base=CAMPAIGN.parent)
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            res = run_campaign(
                camp, Path(tmp) / "out", workers=workers, progress=False, log=lambda *_: None
            )
            wall = time.perf_counter() - t0
        assert res.missing == 0, res
        line(f"campaign, LocalCluster {workers} worker(s)", runs, wall, duration)
    print("(campaign lines include cluster start, design copy and Parquet writes)")
    ceiling(duration, batch)


if __name__ == "__main__":
    main()
