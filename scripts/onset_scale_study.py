"""How far a closed pair along the nominal scales up: the room for the onset of a loss.

A stored closed pair (W, Z) of the integral form stays RPI for (s W, s Z) on the same
vertices (the condition is homogeneous), but s Z needs a scheduling box grown by s times
its supports, whose vertices and W bound are different. For each scale s this script
rebuilds the vertices over the nominal box grown by s x 1.01 times the supports, and
prints the exact worst one-step level of (F, s^2 N, s W) over them and the bound of W
relative to s W (1 or below: closed at that scale).

The onset of a loss is a one-step jump J of the residual, followed by the estimate's lag
(1 - gamma)^k J. In the norm of s Z, l_k = ||e_k||_sZ, the pair's S-procedure certificate
and the triangle inequality give l_k+1 <= sqrt(lam l_k^2 + 1 - lam) + (1 - gamma)^k
||J||_Z / s, and 1 - sqrt(lam l^2 + 1 - lam) >= c (1 - l) on [0, 1] with
c = 1 - sqrt(1 - lam). From e in Z (l_0 = 1 / s) the slack 1 - l_k stays positive for
every k if s >= 1 + ||J||_Z / (gamma - sqrt(1 - lam)). The script prints ||J||_Z for the
design's loss over the nominal box, the scale the onset needs with an estimate of gain
gamma (and with a one-step estimate, gamma = 1), and the largest loss whose onset fits
the largest scale that closes (first order in the loss).

Usage (after `fahv design offline_design/case1_vertex.yaml`):
    .venv/bin/python scripts/onset_scale_study.py [--pair FILE] [--scales 1,2,5,10,20]
        [--gamma 0.2] [--loss 0.24]
About 90 s per scale.
"""

import argparse
import time
from pathlib import Path

import numpy as np
from along_nominal_study import ROOT, case1_context, grown  # this folder, run as a script

import fahv.design.along_nominal as an
from fahv.design.certificate import worst_level
from fahv.plant.uncertainty import PAPER_UNCERTAINTY


def main():
    """Run the scale study of the module docstring."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pair", default=str(ROOT / "tests" / "data" / "closed_tube_integral.npz"))
    ap.add_argument("--scales", default="1,2,5,10,20")
    ap.add_argument("--gamma", type=float, default=0.2)
    ap.add_argument("--loss", type=float, default=0.24)
    o = ap.parse_args()
    _, c, veh, tp, tm = case1_context()
    p = dict(np.load(o.pair))
    W, F, N = p["W"] - p.get("eps", np.zeros(9)), p["F"], p["N"]
    nominal = an.SchedulingBox(p["nominal_lo"], p["nominal_hi"], p["nominal_other_half"])
    s6, s5 = an.segment_supports(F, N)
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    op = an.onset_pulse(nominal, veh, tm, dict(PAPER_UNCERTAINTY), 1.0 - o.loss, c["Ts"],
                     c["plant_substeps"], N, g=1, interior=4096)  # fmt: skip
    Ninv = np.linalg.inv(N)
    jz = float(np.sqrt(np.einsum("si,ij,sj->s", op.jumps, Ninv, op.jumps).max()))
    slow = float(np.sqrt(1.0 - float(p["lam"])))
    if o.gamma <= slow:
        raise SystemExit(f"gamma {o.gamma} <= sqrt(1 - lam) = {slow:.4f}: no scale holds it")
    rate = {"gamma": o.gamma - slow, "one-step": 1.0 - slow}
    print(f"pair {Path(o.pair).name}: onset of a {100 * o.loss:g} % loss, largest jump "
          f"||J||_Z = {jz:.2f} over {len(op.jumps)} points of the nominal box; the onset "
          f"needs s >= 1 + ||J||_Z / (gamma - sqrt(1 - lam)) = {1 + jz / rate['gamma']:.1f} "
          f"(gamma {o.gamma:g}), {1 + jz / rate['one-step']:.1f} with a one-step estimate",
          flush=True)  # fmt: skip
    closed = []
    for s in (float(v) for v in o.scales.split(",")):
        t0 = time.time()
        box = grown(nominal, s6, s5, 1.01 * s)
        nv = an.nominal_vertices(box, veh, tm, dict(PAPER_UNCERTAINTY), float(p["rho_min"]),
                              c["Ts"], c["plant_substeps"], scale, int(p["k"]), p["w_design"],
                              p["col_scale"], hessians=False)  # fmt: skip
        A, B = nv.vertices()
        level, _ = worst_level(A, B, F, s * s * N, s * W)
        b = an.bound_along_nominal(nv, F, s * s * N, nominal)
        ratio = b.total / (s * W)
        ok = level <= 1.0 and bool(np.all(ratio <= 1.0))
        if ok:
            closed.append(s)
        print(f"s = {s:g} ({time.time() - t0:.0f} s): worst level {level:.5f}; bound / (s W) "
              + " ".join(f"{r:.3f}" for r in ratio)
              + ("  closed" if ok else "  NOT closed"), flush=True)  # fmt: skip
    if closed:
        s_max = max(closed)
        print(f"largest closed scale {s_max:g}: onset loss that fits with gamma {o.gamma:g}: "
              f"{100 * o.loss * (s_max - 1) * rate['gamma'] / jz:.3g} %, with a one-step "
              f"estimate: {100 * o.loss * (s_max - 1) * rate['one-step'] / jz:.3g} % (first "
              "order in the loss)")  # fmt: skip
    else:
        print("no scale closed")


if __name__ == "__main__":
    main()
