"""Wall time of the tube certificate's kernels on a stored eight-state tube set.

The tube set of tests/data/closed_tube_h_reset.npz (k = 5, on the box the certified
design reproduces), its 4096 closed-loop vertices rebuilt here. Three figures, each the
best of REPEAT calls:

- the exact worst one-step level of every vertex over Z_8 and the 256 corners of W_8
  (`vertex_levels`: one trust-region dual per vertex and corner, the check behind
  every RPI certificate, the onset's steady set and the notch loops);
- the onset jumps of a 24 % loss over the box's 64 corners x 1024 parameter corners plus
  256 interior points (`onset_jumps`: the parameter records, two plant steps each);
- one onset bound of the design (`onset_bound`, interior 256, 4 bisection steps).

The machine is shared: the figures move with its load (compare two versions of the code
one right after the other).

Usage: .venv/bin/python benchmarks/bench_certificate.py [REPEAT] [--smoke]   (default 3)

`--smoke` runs the same kernels at a tiny size, once each, in seconds (CI's check that
the benchmark still runs; its figures mean nothing): k = 1 parameter direction (256
vertices), three uncertain parameters (8 parameter corners), 16 interior points, one
bisection step, and the scaling's TP model sampled on an 11 x 11 grid (not 21 x 21).
"""

import argparse
import time
import warnings
from pathlib import Path

import numpy as np

from fahv.bounds.domain import SchedulingBox
from fahv.bounds.one_step_bound import altitude_bound
from fahv.bounds.vertices import nominal_vertices
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import trim_map
from fahv.model.vehicle import load_vehicle
from fahv.onset.bound import onset_bound, onset_jumps
from fahv.plant.uncertainty import PAPER_UNCERTAINTY
from fahv.synthesis.rpi_level import vertex_levels
from fahv.tube.tube_set import TubeSet

ROOT = Path(__file__).resolve().parents[1]
TS, N_SUB = 0.02, 5  # cm_certified.yaml's period and RK4 sub-steps
#: --smoke: the uncertain parameters kept (the largest of sec. 5.1), the parameter
#: directions k and the interior points of the jumps and of the onset bound.
SMOKE_PARAMETERS, SMOKE_K, SMOKE_INTERIOR = ("m", "I_yy", "c_e"), 1, 16
#: The TP model's sampling grid (the state and input scales): full size, --smoke.
TP_GRID, SMOKE_TP_GRID = 21, 11


def best(f, repeat):
    """Smallest wall time [s] of `repeat` calls of f, and f's last result."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t0)
    return min(times), out


def main() -> None:
    """Print the three figures of the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("repeat", nargs="?", type=int, default=3, help="calls per figure (best)")
    ap.add_argument("--smoke", action="store_true",
                    help="tiny size, one call each (CI: the benchmark still runs)")  # fmt: skip
    args = ap.parse_args()
    warnings.filterwarnings("ignore", message="Solution may be inaccurate")
    d = dict(np.load(ROOT / "tests/data/closed_tube_h_reset.npz"))
    veh, unc = load_vehicle(), dict(PAPER_UNCERTAINTY)
    k, interior, iterations, repeat, grid = int(d["k"]), 256, 4, args.repeat, TP_GRID
    if args.smoke:
        unc = {p: unc[p] for p in SMOKE_PARAMETERS}
        k, interior, iterations, repeat = SMOKE_K, SMOKE_INTERIOR, 1, 1
        grid = SMOKE_TP_GRID
        print(f"smoke: k = {k}, parameters {', '.join(unc)}, interior {interior}, "
              f"1 bisection step, TP grid {grid} x {grid}, one call each (the figures mean "
              "nothing)")  # fmt: skip
    tm = trim_map(veh, 13, 13)
    tp = build_tp_model(veh, "cm", 4, 5, grid, grid)
    box = SchedulingBox(d["lo"], d["hi"], d["other_half"])
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    nv = nominal_vertices(box, veh, tm, unc, float(d["rho_min"]), TS, N_SUB, scale, k,
                          d["w_design"], d["col_scale"], interior=interior)  # fmt: skip
    A, B = nv.vertices()
    Acl = A[:, 1:, 1:] + B[:, 1:, :] @ d["F"]
    vertex_levels(Acl[:2], d["N"], d["W"])  # compile (or load) the kernel first
    t, lev = best(lambda: vertex_levels(Acl, d["N"], d["W"]), repeat)
    print(
        f"vertex_levels: {len(Acl)} vertices x 256 corners of W_8 in {t:.2f} s "
        f"({t / len(Acl) * 1e3:.2f} ms per vertex); worst level {lev.max():.6f}"
    )
    t, (J, n_c) = best(lambda: onset_jumps(box, veh, tm, unc, 0.76, TS, N_SUB, interior), repeat)
    print(f"onset_jumps: {len(J)} jumps ({n_c} at corners) in {t:.2f} s")
    ab = altitude_bound(nv, A, B, d["F"], d["N"], int(d["moves"]))
    tube_set = TubeSet(d["F"], d["N"], d["W"], ab.H, float(d["lam"]), ab.bound, 0.0,
                       int(d["moves"]), ab.step, ab.w_h)  # fmt: skip
    t, ob = best(lambda: onset_bound(nv, tube_set, veh, tm, unc, 0.2, TS, N_SUB,
                                     interior=interior, iterations=iterations), 1)  # fmt: skip
    print(
        f"onset_bound: {t:.1f} s; certified loss {100 * ob.certified_loss:.2f} %, "
        f"steady set {ob.steady_shaped:.3f} Z_8"
    )


if __name__ == "__main__":
    main()
