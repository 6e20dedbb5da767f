"""Effect of the RMPC re-solve period on cost and closed loop (Case 1, in process).

Kothare's LMI (33)-(35) costs seconds per solve, so the baseline re-solves every
``resolve_every`` steps. This runs the Case 1 RMPC over the first T seconds (the
climb, before the fault) for several periods and prints wall time, seconds per
solve, fallback and rejected solves, and the closed-loop metrics that change.

Usage: .venv/bin/python benchmarks/bench_rmpc_resolve.py [ARTEFACT_DIR] [T] [PERIOD ...]
"""

import sys
import time
import warnings

from fahv.design.artefacts import load_design
from fahv.loop.simulate import simulate
from fahv.model.vehicle import load_vehicle
from fahv.runs.metrics import metrics

warnings.filterwarnings("ignore", message="Solution may be inaccurate")
art = sys.argv[1] if len(sys.argv) > 1 else "offline_design/artefacts/case1"
T = float(sys.argv[2]) if len(sys.argv) > 2 else 60.0
periods = [int(a) for a in sys.argv[3:]] or [250, 50]
design = load_design(art)
lim = load_vehicle().limits
print(f"Case 1 RMPC, {T:g} s, Ts = {design.case['Ts']} s")
print(
    f"{'period':>8} {'solves':>6} {'fallback':>8} {'rejected':>8} {'wall [s]':>9} "
    f"{'s/solve':>8} {'alpha err':>9} {'theta err':>9} {'h err T':>8} {'V err T':>8} "
    f"{'RMS eta1dot':>11} {'Phi max':>7}"
)
for period in periods:
    t0 = time.perf_counter()
    run = simulate(design, "rmpc", T, overrides={"rmpc": {"resolve_every": period}})
    wall = time.perf_counter() - t0
    m = metrics(run, lim)
    n, fb, bad = (int(v) for v in run.lmi_counts)
    print(
        f"{period:>8} {n:>6} {fb:>8} {bad:>8} {wall:>9.1f} {wall / n:>8.2f} "
        f"{m['alpha_err_max_deg']:>9.3f} {m['theta_err_max_deg']:>9.3f} "
        f"{m['h_err_final_ft']:>8.1f} {m['V_err_final_fps']:>8.1f} "
        f"{m['eta_1_dot_rms_after_fault']:>11.5f} {m['Phi_max']:>7.3f}"
    )
