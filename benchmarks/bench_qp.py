"""Nominal MPC QP and whole in-process step of Case 1 (tube_mpc): median, p99, max.

Run: .venv/bin/python benchmarks/bench_qp.py [--steps 15000] [--case SCENARIO]
     [--x-box-both] [--smoke]
Prints the time of every nominal re-plan (the QP's vectors, its DAQP solve and KKT
re-check: `TrackingMPCNominal._replan`) and of every in-process loop step of
`fahv.loop.simulate.simulate` (plant, notch, nominal MPC, controller, fault injector,
and the step's messages kept in memory) over a Case 1 run (default: scenario
offline_design/scenarios/case1_paper.yaml, on the paper's design). `--x-box-both` runs
the case twice in one session, with the design's state range rows (`mpc.x_box`) and
without them (the parameter set to zeros), to compare the QP's cost of those rows.
`--smoke` runs 100 steps (4 QPs) in seconds: CI's check that the benchmark still runs
(its figures mean nothing).
"""

import argparse
import io
import time

import numpy as np

from fahv.certificate.verified import load_or_design
from fahv.control.mpc.nominal_source import TrackingMPCNominal
from fahv.loop.simulate import simulate

#: --smoke: the steps simulated (the nominal MPC solves a QP every 25 steps).
SMOKE_STEPS = 100


def main() -> None:
    """Run Case 1 with timers around the QP and the step; print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=15000)
    ap.add_argument("--case", default="offline_design/scenarios/case1_paper.yaml")
    ap.add_argument("--x-box-both", action="store_true")
    ap.add_argument("--smoke", action="store_true",
                    help=f"{SMOKE_STEPS} steps (CI: the benchmark still runs)")  # fmt: skip
    args = ap.parse_args()
    if args.smoke:
        args.steps = SMOKE_STEPS
        print(f"smoke: {SMOKE_STEPS} steps (the figures mean nothing)")
    _, design, _ = load_or_design(args.case, log=io.StringIO().write, variants=["tube_mpc"])
    runs = [("", None)]
    if args.x_box_both:
        off = {"nominal_trajectory": {"mpc.x_box": [0.0] * 14}}
        runs = [("with mpc.x_box: ", None), ("without mpc.x_box: ", off)]
    for label, ov in runs:
        _bench(design, args.steps, label, ov)


def _bench(design, steps_n: int, label: str, overrides) -> None:
    """One timed run of `steps_n` steps with node-parameter `overrides`; prints it."""
    qp_times = []
    replan = TrackingMPCNominal._replan

    def timed(self, *a, **kw):
        t0 = time.perf_counter()
        out = replan(self, *a, **kw)
        qp_times.append(time.perf_counter() - t0)
        return out

    steps = []

    def step_timer(it):
        """simulate's progress hook: the time between two steps is one loop step."""
        t0 = time.perf_counter()
        for k in it:
            yield k
            t1 = time.perf_counter()
            steps.append(t1 - t0)
            t0 = t1

    TrackingMPCNominal._replan = timed
    try:
        run = simulate(design, "tube_mpc", duration=steps_n * design.case["Ts"],
                       progress=step_timer, overrides=overrides)  # fmt: skip
    finally:
        TrackingMPCNominal._replan = replan
    figures = (("nominal re-plan (QP vectors, solve, check)", qp_times), ("whole step", steps))
    for name, t in figures:
        t = np.array(t) * 1e3
        print(
            f"{label}{name:44s} n={t.size:6d}  median {np.median(t):.3f} ms  "
            f"p99 {np.percentile(t, 99):.3f} ms  max {t.max():.3f} ms"
        )
    print(f"{label}QP counters (accepted, shifted plan, terminal law, recovery re-plans): "
          f"{run.qp_counts.tolist()}")  # fmt: skip


if __name__ == "__main__":
    main()
