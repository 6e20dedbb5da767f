"""Campaign throughput of both loops, beside an earlier commit's, in one run of the benchmark.

For the exact-state loop (campaign `case1`: the paper's loop on `cm_certified`) and the
implementable loop (campaign `case1_implementable_1000`: servos, noisy sensors, the Kalman
filter), each dispersed as its campaign file says, the cost of a 300 s run

- of a single run (`simulate`) and of a batch of B runs stepped together
  (`simulate_batch`, B in BATCHES): runs of DURATION seconds, each figure the time of
  building the runs (the same call for one step) plus their stepping scaled to 300 s;
- of a campaign of whole 300 s runs on a LocalCluster of 1 and of 2 Dask workers
  (CAMPAIGN_RUNS runs in batches of half of them, at most 100: cluster start, design
  scatter, metrics and Parquet writes included),

with the microseconds per step per run, the share of the nominal MPC's re-plans
(scheduling where due, the QPs' vectors, solve and KKT re-check:
`TrackingMPCNominal._replan`) in the batch of 50, and where the
time of the largest batch goes, part by part of the step.

The same measurements run on an earlier commit (`--baseline`, by default the commit
before the batched implementable loop): a git worktree of it, its own library, campaign
files and shipped designs, measured by this same script in a process of its own, in the
same session, alternating with the working tree's so that the machine's load falls on
both alike. The DURATION-second runs hold the steps' transient and most of the QP's
re-schedulings: their stepping, scaled to 300 s, costs more per simulated second than a
whole run's (the campaign lines fly whole runs).

Usage: .venv/bin/python benchmarks/bench_campaign.py [--duration S] [--batches 1,10,50,200]
           [--campaign-runs N] [--campaign-duration S] [--baseline REV | --no-baseline]
           [--write-docs] [--smoke]

`--write-docs` writes the table into docs/results/speed.md (between its
`bench_campaign` markers). `--smoke` runs the same code path at a tiny size in seconds
(CI's check that the benchmark still runs; its figures mean nothing): 1 s runs, batches of
1 and 2, a campaign of 2 runs on one worker, no baseline.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: The commit before the implementable loop batched (the default baseline).
BASELINE = "70ad77f"
#: Loop name -> campaign file (relative to a checkout's root) and variant.
LOOPS = {
    "exact state": ("offline_design/campaigns/case1.yaml", "tube_mpc"),
    "implementable": ("offline_design/campaigns/case1_implementable_1000.yaml", "tube_mpc"),
}
FULL = 300.0  # [s] a campaign's run
TS = 0.02  # [s] the control period of both loops
DOCS = ROOT / "docs" / "results" / "speed.md"
MARK = ("<!-- bench_campaign -->", "<!-- /bench_campaign -->")


# -- measurement (runs in the process of one checkout) ---------------------------------
def _design_and_overrides(campaign_file: str, variant: str, n: int):
    """The campaign's design (as its engine loads it) and the overrides of its first n runs."""
    from fahv.campaign.draws import draw, overrides
    from fahv.campaign.spec import load_campaign
    from fahv.certificate.verified import load_or_design

    c = load_campaign(campaign_file)
    _, design, _ = load_or_design(c.run_spec.path, log=io.StringIO().write,
                                  allow_uncertified=True)  # fmt: skip
    return c, design, [overrides(draw(c.data, design.case, i), design, variant) for i in range(n)]


def _clocked(f, add):
    """`f` with a clock: each call's duration [s] passed to `add`."""

    def run(*args, **kwargs):
        t0 = time.perf_counter()
        try:
            return f(*args, **kwargs)
        finally:
            add(time.perf_counter() - t0)

    return run


def _qp_clock():
    """Wrap the re-plans with a clock; returns the list of their durations [s].

    `TrackingMPCNominal._replan`: every run's scheduling where due, its QP's vectors,
    solve and KKT re-check (the same method in the baseline).
    """
    from fahv.control.mpc.nominal_source import TrackingMPCNominal

    spent: list[float] = []
    TrackingMPCNominal._replan = _clocked(TrackingMPCNominal._replan, spent.append)
    return spent


#: The parts of a step timed in the largest batch: (label, core attribute, method).
PARTS = (
    ("plant: state, sensors", "plant", ("state", "measurement")),
    ("plant: RK4 (with the servos where it has them)", "plant", ("advance",)),
    ("state estimator", "estimator", ("on_measurement",)),
    ("notch filter", "notch", ("on_state",)),
    ("nominal MPC: fast step", "nominal", ("output", "advance")),
    ("tube law", "controller", ("on_inputs",)),
    ("fault injector", "fault", ("on_command",)),
)


def _part_clocks():
    """Clock each part of `Loop.step` (`PARTS`) and the re-plans; returns {label: seconds}.

    The re-plans (`TrackingMPCNominal._replan`) are inside the nominal's output: their
    time is taken out of the fast step's.
    """
    from fahv.control.mpc.nominal_source import TrackingMPCNominal
    from fahv.loop import simulate as sim

    spent: dict[str, float] = {label: 0.0 for label, _, _ in PARTS}
    spent["nominal MPC: re-plans (QP)"] = 0.0

    def clocked(label, f):
        return _clocked(f, lambda dt: spent.__setitem__(label, spent[label] + dt))

    build = sim.Loop.__init__

    def init(self, *args, **kwargs):
        build(self, *args, **kwargs)
        for label, core, methods in PARTS:
            obj = getattr(self, core)
            for m in methods:
                setattr(obj, m, clocked(label, getattr(obj, m)))

    sim.Loop.__init__ = init
    TrackingMPCNominal._replan = clocked("nominal MPC: re-plans (QP)", TrackingMPCNominal._replan)
    return spent


def _campaign_wall(c, runs: int, duration: float, batch: int, workers: int) -> float:
    """Wall time [s] of a campaign of `runs` runs on a LocalCluster of `workers`."""
    from fahv.campaign.engine import run_campaign
    from fahv.campaign.spec import campaign_from_mapping
    from fahv.config.yamlio import load_yaml

    data = {**load_yaml(c.path.read_text()), "runs": runs, "duration": duration,
            "batch_size": batch, "name": "bench", "variants": c.data["variants"][:1]}  # fmt: skip
    camp = campaign_from_mapping(data, "bench", base=c.path.parent)
    with tempfile.TemporaryDirectory() as tmp:
        t0 = time.perf_counter()
        res = run_campaign(camp, Path(tmp) / "out", workers=workers, progress=False,
                           log=lambda *_: None)  # fmt: skip
        wall = time.perf_counter() - t0
    if res.missing:
        sys.exit(f"bench_campaign: the campaign left {res.missing} runs undone")
    return wall


def measure(loop: str, duration: float, batches: list[int], campaign_runs: int,
            workers: list[int], campaign_duration: float = FULL) -> dict:  # fmt: skip
    """Seconds of each measurement of one loop in this process's checkout (a dict).

    Each entry is (setup [s], wall [s], runs): `setup` the time of building the runs
    (the same call for one step), `wall` that of the call for `duration` seconds; a
    campaign's entry is its wall time for `campaign_duration`-second runs, scaled to
    `duration`, with no setup apart.
    """
    from fahv.loop.batch import simulate_batch
    from fahv.loop.simulate import simulate

    campaign_file, variant = LOOPS[loop]
    c, design, ovs = _design_and_overrides(campaign_file, variant, max(batches))
    simulate(design, variant, 1.0, overrides=ovs[0])  # imports, compiled kernels: not timed

    def clock(f, *args):
        t0 = time.perf_counter()
        f(*args)
        return time.perf_counter() - t0

    out: dict = {}
    setup = clock(lambda: simulate(design, variant, TS, overrides=ovs[0]))
    out["single"] = (setup, clock(lambda: simulate(design, variant, duration, overrides=ovs[0])), 1)
    spent = _qp_clock()
    for b in batches:
        setup = clock(simulate_batch, design, variant, ovs[:b], TS)  # building the runs
        spent.clear()
        wall = clock(simulate_batch, design, variant, ovs[:b], duration)
        out[f"batch {b}"] = (setup, wall, b)
        if b == 50 or (b == max(batches) and "qp_share" not in out):
            out["qp_share"] = (sum(spent) / wall, b)
    parts = _part_clocks()  # the largest batch once more, each part of the step clocked
    t0 = time.perf_counter()
    simulate_batch(design, variant, ovs[: max(batches)], duration)
    wall = time.perf_counter() - t0
    parts["nominal MPC: fast step"] -= parts["nominal MPC: re-plans (QP)"]
    parts["rest of the loop (messages, history)"] = wall - sum(parts.values())
    out["parts"] = {"batch": max(batches), "wall": wall, "seconds": parts}
    batch = max(1, min(100, campaign_runs // 2))
    for w in workers:  # whole runs: a campaign's setup, scatter and writes as they are
        wall = _campaign_wall(c, campaign_runs, campaign_duration, batch, w)
        out[f"campaign {w}"] = (0.0, wall * duration / campaign_duration, campaign_runs)
    return out


# -- orchestration (the benchmark's own process) ----------------------------------------
def _run_checkout(root: Path, args, loop: str) -> dict:
    """`measure` of one loop in a process of the checkout at `root` (its src and files)."""
    env = {**os.environ, "PYTHONPATH": str(root / "src")}
    cmd = [sys.executable, str(Path(__file__).resolve()), "--measure", loop,
           "--duration", str(args.duration), "--batches", args.batches,
           "--campaign-runs", str(args.campaign_runs), "--workers", args.workers,
           "--campaign-duration", str(args.campaign_duration)]  # fmt: skip
    r = subprocess.run(cmd, cwd=root, env=env, capture_output=True, text=True)
    if r.returncode:
        sys.exit(f"bench_campaign: {' '.join(cmd)} in {root} failed:\n{r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def _worktree(rev: str) -> Path:
    """A detached git worktree of `rev` in a temporary folder."""
    path = Path(tempfile.mkdtemp(prefix="bench_baseline_"))
    subprocess.run(["git", "worktree", "add", "--detach", str(path), rev], cwd=ROOT,
                   check=True, capture_output=True)  # fmt: skip
    return path


def _cpu_model() -> str:
    """The processor's model name (Linux), else what `platform` knows of it."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def _per_run(setup: float, wall: float, runs: int, duration: float) -> float:
    """Seconds per 300 s run: the setup once, the stepping scaled from `duration`.

    The setup is timed by a call of its own: on a loaded machine it can take longer than
    the whole call for a short `duration` (the smoke run's 1 s), so the stepping's share
    is at least zero (the figure is then the setup's alone).
    """
    return (setup + max(wall - setup, 0.0) * FULL / duration) / runs


def _rows(results: dict, duration: float) -> list[tuple[str, str, dict]]:
    """(loop, measurement, {version: seconds per 300 s run}) rows of the table."""
    rows = []
    for loop, by_version in results.items():
        keys = [k for k in next(iter(by_version.values())) if k not in ("qp_share", "parts")]
        for k in keys:
            rows.append((loop, k, {v: _per_run(*m[k], duration) for v, m in by_version.items()}))
    return rows


def _label(key: str) -> str:
    kind, _, n = key.partition(" ")
    return {"single": "one run, `simulate`", "batch": f"a batch of {n}, `simulate_batch`",
            "campaign": f"campaign, {n} worker{'s' if n != '1' else ''}"}[kind]  # fmt: skip


def table(results: dict, duration: float, versions: list[str]) -> str:
    """The markdown table: seconds per 300 s run and microseconds per step per run."""
    steps = FULL / TS
    head = "| loop | measured on | " + " | ".join(
        f"{v}: s per 300 s run (us per step per run)" for v in versions)
    lines = [head + (" | before / after |" if len(versions) == 2 else " |"),
             "|---|---|" + "---|" * (len(versions) + (len(versions) == 2))]  # fmt: skip
    for loop, key, per in _rows(results, duration):
        cells = [f"{per[v]:.3f} ({per[v] / steps * 1e6:.1f})" for v in versions]
        ratio = [f"{per[versions[0]] / per[versions[1]]:.1f}x"] if len(versions) == 2 else []
        lines.append(f"| {loop} | {_label(key)} | " + " | ".join(cells + ratio) + " |")
    for loop, by_version in results.items():
        b = by_version[versions[-1]]["qp_share"][1]
        cells = [f"{100 * by_version[v]['qp_share'][0]:.0f} %" for v in versions]
        cells += [""] * (len(versions) == 2)
        lines.append(f"| {loop} | share of the re-plans (scheduling, QP vectors, solve, KKT) "
                     f"in the batch of {b} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def parts_table(results: dict, duration: float, version: str) -> str:
    """The markdown table of where the largest batch's time goes, loop by loop."""
    loops = list(results)
    lines = ["| part of the step | " + " | ".join(
        f"{loop}: share (us per step and run)" for loop in loops) + " |",
        "|---|" + "---|" * len(loops)]  # fmt: skip
    labels = list(results[loops[0]][version]["parts"]["seconds"])
    for label in labels:
        cells = []
        for loop in loops:
            p = results[loop][version]["parts"]
            sec = p["seconds"][label]
            cells.append(f"{100 * sec / p['wall']:.0f} % "
                         f"({sec / p['batch'] / (duration / TS) * 1e6:.1f})")  # fmt: skip
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def write_docs(text: str) -> None:
    """Put the table between the markers of docs/results/speed.md."""
    page = DOCS.read_text()
    head, rest = page.split(MARK[0], 1)
    _, tail = rest.split(MARK[1], 1)
    DOCS.write_text(head + MARK[0] + "\n" + text + "\n" + MARK[1] + tail)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=20.0, help="simulated time per run [s]")
    ap.add_argument("--batches", default="1,10,50,200", help="batch sizes B, comma-separated")
    ap.add_argument("--campaign-runs", type=int, default=20, help="runs of each campaign")
    ap.add_argument("--campaign-duration", type=float, default=FULL,
                    help="simulated time of each campaign run [s]")  # fmt: skip
    ap.add_argument("--workers", default="1,2", help="worker counts of the campaigns")
    ap.add_argument("--baseline", default=BASELINE, help="commit measured beside the tree")
    ap.add_argument("--no-baseline", action="store_true", help="the working tree alone")
    ap.add_argument("--write-docs", action="store_true", help="the table into speed.md")
    ap.add_argument("--smoke", action="store_true", help="tiny size (CI: it still runs)")
    ap.add_argument("--measure", help=argparse.SUPPRESS)  # one loop, in a checkout's process
    args = ap.parse_args()
    if args.smoke:
        args.duration, args.batches, args.campaign_runs, args.workers = 1.0, "1,2", 2, "1"
        args.campaign_duration = 1.0
        args.no_baseline = True
    if args.measure:
        out = measure(args.measure, args.duration, [int(b) for b in args.batches.split(",")],
                      args.campaign_runs, [int(w) for w in args.workers.split(",")],
                      args.campaign_duration)  # fmt: skip
        print(json.dumps(out))
        return
    checkouts = {"working tree": ROOT}
    if not args.no_baseline:
        checkouts = {args.baseline: _worktree(args.baseline), **checkouts}
    machine = (f"{_cpu_model()}, {os.cpu_count()} cores; runs of {args.duration:g} s alone and "
               f"in batches of {args.batches} (each figure: the runs' building once, their "
               f"stepping scaled to 300 s), campaigns of {args.campaign_runs} runs of "
               f"{args.campaign_duration:g} s on {args.workers} worker(s)")  # fmt: skip
    print(machine)
    results: dict = {loop: {} for loop in LOOPS}
    try:
        for loop in LOOPS:  # the versions alternate loop by loop (the machine's load on both)
            for version, root in checkouts.items():
                t0 = time.perf_counter()
                results[loop][version] = _run_checkout(root, args, loop)
                print(f"  {loop}, {version}: measured in {time.perf_counter() - t0:.0f} s",
                      flush=True)  # fmt: skip
    finally:
        for root in checkouts.values():
            if root != ROOT:
                subprocess.run(["git", "worktree", "remove", "--force", str(root)], cwd=ROOT,
                               capture_output=True)  # fmt: skip
    text = f"Measured on: {machine}.\n\n" + table(results, args.duration, list(checkouts))
    batch = results[next(iter(LOOPS))]["working tree"]["parts"]["batch"]
    text += (f"\n\nWhere the time of a batch of {batch} goes in the working tree (each part "
             "of the step clocked in process):\n\n"
             + parts_table(results, args.duration, "working tree"))  # fmt: skip
    print(text)
    if args.write_docs:
        write_docs(text)
        print(f"written to {DOCS.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
