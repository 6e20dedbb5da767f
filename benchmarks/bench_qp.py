"""Nominal MPC QP and whole in-process step of Case 1 (tube_mpc): median, p99, max.

Run: .venv/bin/python benchmarks/bench_qp.py [--steps 15000]
Prints the time of every nominal QP (DAQP) and of every in-process loop step of
``fahv.loop.simulate.simulate`` (plant, notch, nominal MPC, controller, fault injector,
and the step's messages kept in memory) over a Case 1 run.
"""

import argparse
import io
import time

import numpy as np

from fahv.cli.design import load_or_design
from fahv.control import nominal_mpc
from fahv.loop.simulate import simulate


def main() -> None:
    """Run Case 1 with timers around the QP and the step; print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=15000)
    args = ap.parse_args()
    _, design, _ = load_or_design(
        "offline_design/case1_vertex.yaml", None, None, io.StringIO().write
    )
    qp_times = []
    solve = nominal_mpc.TrackingMPC.solve

    def timed(self, *a):
        t0 = time.perf_counter()
        out = solve(self, *a)
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

    nominal_mpc.TrackingMPC.solve = timed
    run = simulate(design, "tube_mpc", duration=args.steps * design.case["Ts"], progress=step_timer)
    for name, t in (("nominal QP (build + solve + check)", qp_times), ("whole step", steps)):
        t = np.array(t) * 1e3
        print(
            f"{name:36s} n={t.size:6d}  median {np.median(t):.3f} ms  "
            f"p99 {np.percentile(t, 99):.3f} ms  max {t.max():.3f} ms"
        )
    print(f"QP counters (accepted, shifted plan, terminal law): {run.qp_counts.tolist()}")


if __name__ == "__main__":
    main()
