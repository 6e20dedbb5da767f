"""Cost of one control step per node computation, in process (no ROS), Case 1.

Prints milliseconds per step of each fahv.loop core and of the whole step; the SIL
graph adds the DDS hops on top (its per-step time is printed by the plant node and by
`fahv sil` as the real-time factor).

Usage: .venv/bin/python benchmarks/bench_step.py [ARTEFACT_DIR] [STEPS]
"""

import sys
import time

from fahv.loop.cores import build_core
from fahv.loop.params import node_parameters
from fahv.spec.artefacts import load_design

art = sys.argv[1] if len(sys.argv) > 1 else "offline_design/designs/cm_paper"
n = int(sys.argv[2]) if len(sys.argv) > 2 else 2000
p = node_parameters(load_design(art))
names = ("plant", "notch_filter", "nominal_trajectory", "tube_mpc", "fault_injector")
plant, notch, nom, ctrl, fault = (build_core(name, p[name]) for name in names)
t = dict.fromkeys(names, 0.0)
clock = time.perf_counter
# step 0 apart: it loads the plant's compiled RK4 (numba cache) once per process
t_first = clock()
s = plant.state()
u, _z = ctrl.on_inputs(s, notch.on_state(s), nom.on_state(s))
plant.advance(fault.on_command(u)[0])
t_first = clock() - t_first
for _ in range(n):
    a = clock()
    s = plant.state()
    b = clock()
    q = notch.on_state(s)
    c = clock()
    r = nom.on_state(s, u)
    d = clock()
    u, _z = ctrl.on_inputs(s, q, r)
    e = clock()
    act, _f = fault.on_command(u)
    f = clock()
    plant.advance(act)
    g = clock()
    for key, dt in zip(t, (b - a + g - f, c - b, d - c, e - d, f - e), strict=True):
        t[key] += dt
total = sum(t.values())
print(f"{n} steps of {art} ({n * p['plant']['Ts']:.0f} s simulated) after step 0")
print(f"  {'step 0 (one-off)':<20} {1e3 * t_first:7.1f} ms")
for key, v in t.items():
    print(f"  {key:<20} {1e3 * v / n:7.3f} ms/step")
rtf = p["plant"]["Ts"] * n / total
print(f"  {'whole step':<20} {1e3 * total / n:7.3f} ms/step (real-time factor {rtf:.0f})")
