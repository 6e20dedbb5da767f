"""Nominal MPC QP and whole in-process step of Case 1 (tube_mpc): median, p99, max.

Run: .venv/bin/python benchmarks/bench_qp.py [--steps 15000]
Prints the time of every accepted nominal QP (DAQP) and of every in-process loop step
(plant, notch, nominal MPC, controller, fault injector) over a Case 1 run.
"""

import argparse
import io
import time

import numpy as np

from fahv.cli.design import load_or_design
from fahv.control import nominal_mpc
from fahv.loop.cores import build_core
from fahv.loop.params import node_parameters


def main() -> None:
    """Run Case 1 with timers around the QP and the step; print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=15000)
    args = ap.parse_args()
    _, design, _ = load_or_design("offline_design/case1.yaml", None, None, io.StringIO().write)
    p = node_parameters(design, "tube_mpc")
    plant, notch, nominal, fault, ctrl = (
        build_core(n, p[n])
        for n in ("plant", "notch_filter", "nominal_trajectory", "fault_injector", "tube_mpc")
    )
    qp_times = []
    solve = nominal_mpc.TrackingMPC.solve

    def timed(self, *a):
        t0 = time.perf_counter()
        out = solve(self, *a)
        qp_times.append(time.perf_counter() - t0)
        return out

    nominal_mpc.TrackingMPC.solve = timed
    steps, cmd = [], None
    for _ in range(args.steps):
        t0 = time.perf_counter()
        state = plant.state()
        qf = notch.on_state(state)
        nom = nominal.on_state(state, cmd)
        cmd, _ = ctrl.on_inputs(state, qf, nom)
        act, _ = fault.on_command(cmd)
        plant.advance(act)
        steps.append(time.perf_counter() - t0)
    for name, t in (("nominal QP (build + solve + check)", qp_times), ("whole step", steps)):
        t = np.array(t) * 1e3
        print(
            f"{name:36s} n={t.size:6d}  median {np.median(t):.3f} ms  "
            f"p99 {np.percentile(t, 99):.3f} ms  max {t.max():.3f} ms"
        )
    print(f"QP counters: {nominal.mpc.stats}")


if __name__ == "__main__":
    main()
