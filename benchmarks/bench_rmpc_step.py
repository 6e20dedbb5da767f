"""Per-step cost of the off-line RMPC baseline (law `rmpc`), Case 1, in process.

Times every call of the law's step (ellipsoid search, gain interpolation, command) and
of the controller core around it (messages in and out), over a whole Case 1 run of
`fahv.loop.simulate.simulate` (B = 1), and the whole in-process step; then the law
alone on the run's recorded states, each step timed in 5 passes and the minimum kept
(what the step costs without preemption by other processes), and the law step of a
batch of B runs (per run). Prints median, p99 and max.

Run: .venv/bin/python benchmarks/bench_rmpc_step.py [--steps 15000] [--batch 100] [--smoke]
Target: law step p99 <= 0.2 ms. Time it on a quiet machine.

The run is scenario offline_design/scenarios/case1_paper.yaml (Case 1 on the paper's
design, whose RMPC baseline was designed along the scenario's step). `--smoke` runs 50
steps, a batch of 4 and 20 batch steps, in seconds: CI's check that the benchmark still
runs (its figures mean nothing).
"""

import argparse
import io
import time

import numpy as np

from fahv.certificate.verified import load_or_design
from fahv.control.rmpc import RMPCLaw
from fahv.lanes import Lanes
from fahv.loop.cores import ControllerCore
from fahv.loop.simulate import simulate

#: --smoke: steps of the run, runs B of the batch and batch steps timed.
SMOKE_STEPS, SMOKE_BATCH, SMOKE_BATCH_STEPS = 50, 4, 20


def stats(name: str, t) -> None:
    """Print median, p99 and max of times t [s] in ms."""
    t = np.asarray(t) * 1e3
    print(
        f"{name:44s} n={t.size:6d}  median {np.median(t):.4f} ms  "
        f"p99 {np.percentile(t, 99):.4f} ms  max {t.max():.4f} ms"
    )


def _timed_run(design, steps: int):
    """Case 1 in process with timers around the law, the controller core and each step.

    Returns the run and the three lists of times [s].
    """
    law_t, core_t, step_t = [], [], []
    law_step, core_step = RMPCLaw.step, ControllerCore.on_inputs

    def timed_law(self, *a):
        t0 = time.perf_counter()
        out = law_step(self, *a)
        law_t.append(time.perf_counter() - t0)
        return out

    def timed_core(self, *a):
        t0 = time.perf_counter()
        out = core_step(self, *a)
        core_t.append(time.perf_counter() - t0)
        return out

    def step_timer(it):
        t0 = time.perf_counter()
        for k in it:
            yield k
            t1 = time.perf_counter()
            step_t.append(t1 - t0)
            t0 = t1

    RMPCLaw.step, ControllerCore.on_inputs = timed_law, timed_core
    try:
        t0 = time.perf_counter()
        run = simulate(design, "rmpc", steps * design.case["Ts"], progress=step_timer)
        wall = time.perf_counter() - t0
    finally:
        RMPCLaw.step, ControllerCore.on_inputs = law_step, core_step
    print(f"Case 1 rmpc, {run.t.size} steps in process: wall {wall:.2f} s")
    return run, law_t, core_t, step_t


def _law_alone(p, run) -> None:
    """The law alone on the run's recorded states, B = 1, each step timed in 5 passes.

    The minimum per step drops preemption by other processes (a loaded machine).
    """
    from types import SimpleNamespace

    law1, lanes1 = RMPCLaw(p, 1), Lanes(1, strict=False)
    xs, refs = run.x.copy(), run.x_r.copy()
    xs[:, 4] = run.q_f  # the controller sees q'
    ref_u = np.zeros((1, 2))
    per = np.full((5, run.t.size), np.inf)
    for rep in range(5):
        for k in range(run.t.size):
            ref = SimpleNamespace(x_r=refs[k : k + 1], u_r=ref_u)
            x = xs[k : k + 1]
            t0 = time.perf_counter()
            law1.step(k, x, ref, lanes1)
            per[rep, k] = time.perf_counter() - t0
    stats("law step, B = 1, min of 5 passes per step", per.min(axis=0))


def _law_batch(p, run, B: int, batch_steps: int) -> None:
    """The law on a batch: the run's recorded states and references stacked B times."""
    from types import SimpleNamespace

    law = RMPCLaw(p, B)
    lanes = Lanes(B, strict=False)
    rng = np.random.default_rng(0)
    idx = rng.integers(0, run.t.size, size=(batch_steps, B))
    times = []
    for rows in idx:
        ref = SimpleNamespace(x_r=run.x_r[rows], u_r=np.zeros((B, 2)))
        x = run.x[rows]
        t0 = time.perf_counter()
        law.step(0, x, ref, lanes)
        times.append((time.perf_counter() - t0) / B)
    stats(f"law step per run, batch of B = {B}", times)


def main() -> None:
    """Run Case 1 with timers around the law and the step; print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=int, default=15000)
    ap.add_argument("--batch", type=int, default=100)
    ap.add_argument("--smoke", action="store_true",
                    help="tiny size (CI: the benchmark still runs)")  # fmt: skip
    args = ap.parse_args()
    batch_steps = 200
    if args.smoke:
        args.steps, args.batch, batch_steps = SMOKE_STEPS, SMOKE_BATCH, SMOKE_BATCH_STEPS
        print(f"smoke: {args.steps} steps, a batch of B = {args.batch} over {batch_steps} "
              "steps (the figures mean nothing)")  # fmt: skip
    _, design, _ = load_or_design(
        "offline_design/scenarios/case1_paper.yaml", log=io.StringIO().write, variants=["rmpc"]
    )
    run, law_t, core_t, step_t = _timed_run(design, args.steps)
    stats("law step (RMPCLaw.step), B = 1", law_t)
    stats("controller core (messages + law), B = 1", core_t)
    stats("whole in-process step, B = 1", step_t)
    from fahv.loop.params import node_parameters, validate

    p = validate("rmpc", node_parameters(design, "rmpc")["rmpc"])
    _law_alone(p, run)
    _law_batch(p, run, args.batch, batch_steps)


if __name__ == "__main__":
    main()
