"""Cost of one control step per node computation, in process (no ROS), Case 1.

Prints milliseconds per step of each fahv.loop core and of the whole step; the SIL
graph adds the DDS hops on top (its per-step time is printed by the plant node and by
`fahv sil` as the real-time factor).

Usage: .venv/bin/python benchmarks/bench_step.py [--scenario SCENARIO] [--design DIR]
       [--steps 2000] [--kalman] [--allow-uncertified] [--smoke]

The scenario (default offline_design/scenarios/case1_paper.yaml, Case 1 on the paper's
design) runs on its stored design, or on the artefact folder `--design DIR` (as
`fahv simulate --design`). `--kalman` runs the state estimator's Kalman filter on the
sensors h, V, theta, q (default: the scenario's estimator). `--allow-uncertified` runs a
scenario beyond what its design certifies (the implementable loops), as `fahv simulate`
does. `--smoke` runs 20 steps in
seconds: CI's check that the benchmark still runs (its figures mean nothing).
"""

import argparse
import io
import time

from fahv.certificate.verified import load_or_design
from fahv.loop.cores import build_core
from fahv.loop.params import node_parameters

NAMES = ("plant", "state_estimator", "notch_filter", "nominal_trajectory", "tube_mpc",
         "fault_injector")  # fmt: skip
#: --kalman: the sensors the filter reads.
KALMAN_CHANNELS = "h,V,theta,q"
#: --smoke: the steps timed.
SMOKE_STEPS = 20


def main() -> None:
    """Step the loop's cores by hand with a timer around each; print the figures."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="offline_design/scenarios/case1_paper.yaml")
    ap.add_argument("--design", default=None,
                    help="artefact folder of the stored design (default: beside its "
                    "design file)")  # fmt: skip
    ap.add_argument("--steps", type=int, default=2000, help="steps timed after step 0")
    ap.add_argument("--kalman", action="store_true",
                    help=f"the Kalman filter on the sensors {KALMAN_CHANNELS}")  # fmt: skip
    ap.add_argument("--allow-uncertified", action="store_true",
                    help="run a scenario beyond what its design certifies")  # fmt: skip
    ap.add_argument("--smoke", action="store_true",
                    help=f"{SMOKE_STEPS} steps (CI: the benchmark still runs)")  # fmt: skip
    args = ap.parse_args()
    n = SMOKE_STEPS if args.smoke else args.steps
    if args.smoke:
        print(f"smoke: {n} steps (the figures mean nothing)")
    _, design, _ = load_or_design(
        args.scenario, args.design, log=io.StringIO().write, variants=["tube_mpc"],
        allow_uncertified=args.allow_uncertified,
    )
    p = node_parameters(design, "tube_mpc")
    if args.kalman:
        p["plant"]["measured"] = p["state_estimator"]["measured"] = KALMAN_CHANNELS
        p["state_estimator"]["estimator"] = "kalman"
    plant, est, notch, nom, ctrl, fault = (build_core(name, p[name]) for name in NAMES)
    t = dict.fromkeys(NAMES, 0.0)
    clock = time.perf_counter
    # step 0 apart: it loads the plant's compiled RK4 (numba cache) once per process
    t_first = clock()
    plant.state()
    s = est.on_measurement(plant.measurement())
    u, _z = ctrl.on_inputs(s, notch.on_state(s), nom.on_state(s))
    plant.advance(fault.on_command(u)[0])
    t_first = clock() - t_first
    for _ in range(n):
        a = clock()
        plant.state()
        y = plant.measurement()
        b = clock()
        s = est.on_measurement(y, u)
        c = clock()
        q = notch.on_state(s)
        d = clock()
        r = nom.on_state(s, u)
        e = clock()
        u, _z = ctrl.on_inputs(s, q, r)
        f = clock()
        act, _f = fault.on_command(u)
        g = clock()
        plant.advance(act)
        h = clock()
        steps = (b - a + h - g, c - b, d - c, e - d, f - e, g - f)
        for key, dt in zip(t, steps, strict=True):
            t[key] += dt
    total = sum(t.values())
    Ts = p["plant"]["Ts"]
    name = design.summary.get("design_name", "?")
    print(f"{n} steps of {args.scenario} (design {name}, {n * Ts:g} s simulated) after step 0")
    print(f"  {'step 0 (one-off)':<20} {1e3 * t_first:7.1f} ms")
    for key, v in t.items():
        print(f"  {key:<20} {1e3 * v / n:7.3f} ms/step")
    rtf = Ts * n / total
    print(f"  {'whole step':<20} {1e3 * total / n:7.3f} ms/step (real-time factor {rtf:.0f})")


if __name__ == "__main__":
    main()
