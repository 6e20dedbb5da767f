"""What the onset of an elevator loss puts into the tube error, state by state (item 3).

Usage: python scripts/onset_jump_study.py [PAIR.npz] [LOSS] [SEQUENCES]

On a stored eight-state pair (default: tests/data/closed_tube_h_reset.npz, the pair whose
scheduling box case1.yaml's design reproduces) this measures

1. the first jump J_8 / rho_f of a loss (`fahv.design.along_nominal.onset_jumps`: the
   scheduling box's 64 corners with every corner of the sec. 5.1 box, and interior
   points), as a multiple of Z_8's support state by state at the worst point, and its
   Z_8 norm with groups of states left out: how much of the jump the requirement states
   (V, alpha, theta) carry, and how much the pitch rate and the bending modes;
2. the worst jump's response along random switching sequences of the pair's closed-loop
   vertices A_8 + B_8 F_8, for an estimate that knows the loss one step after it acts
   (one pulse) and for the case's isotropic estimate (gamma 0.2: the pulse train
   (1 - gamma)^k J): each state's peak as a multiple of its support, and the peak Z_8
   norm, with the steps it takes to fall back to 1.

The onset bound `fahv.design.eight_state.onset_bound` is a norm bound; this shows which
states make the norm (docs/control_design.md, "The onset's jump, state by state").
"""

import sys
import time
from pathlib import Path

import numpy as np

from fahv.design.along_nominal import SchedulingBox, nominal_vertices, onset_jumps
from fahv.model.tp_model import build_tp_model
from fahv.model.trim import trim_map
from fahv.model.vehicle import load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY

TS, N_SUB = 0.02, 4
NAMES = ("V", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot")
GROUPS = {
    "bending modes (eta_1, eta_1_dot, eta_2, eta_2_dot)": [4, 5, 6, 7],
    "mode 2 (eta_2, eta_2_dot)": [6, 7],
    "q": [3],
    "q and the bending modes": [3, 4, 5, 6, 7],
}


def main(path: Path, loss: float, sequences: int) -> None:
    """Print the jump's make-up and its propagated response (see the module docstring)."""
    t0 = time.perf_counter()
    d = dict(np.load(path))
    if "H" not in d:
        raise SystemExit(f"{path}: not an eight-state pair (no altitude bound H)")
    veh = load_vehicle()
    tm = trim_map(veh)
    box = SchedulingBox(d["lo"], d["hi"], d["other_half"])
    J, n_c = onset_jumps(box, veh, tm, dict(PAPER_UNCERTAINTY), 1.0 - loss, TS, N_SUB,
                         interior=1024)  # fmt: skip
    J8 = J[:, 1:] / (1.0 - loss)
    L = np.linalg.cholesky(d["N"])
    support = np.sqrt(np.diag(d["N"]))

    def z8(V):
        return np.sqrt((np.linalg.solve(L, V.T) ** 2).sum(axis=0))

    norm = z8(J8)
    i = int(norm.argmax())
    print(f"pair {path.name}: {len(J8)} jumps of a {100 * loss:.1f} % loss ({n_c} at corners)")
    print(f"largest Z_8 norm of the first jump: {norm[i]:.3f} (sample {i}, "
          f"{'corner' if i < n_c else 'interior'})")  # fmt: skip
    print("  at that point, per state, as a multiple of Z_8's support:")
    for name, v, s in zip(NAMES, J8[i], support, strict=True):
        print(f"    {name:>10}: {v / s:+.3f}   (jump {v:+.3e}, support {s:.3e})")
    tightening = np.sqrt(np.diag(d["F"] @ d["N"] @ d["F"].T))
    print("  the tube's answer to it one step later, F_8 J_8, as a multiple of the tightening "
          "(support of F_8 Z_8) per input (Phi, delta_e):")  # fmt: skip
    for label, idx in (("all of it", slice(0, 8)), ("through q", slice(3, 4)),
                       ("through the bending modes", slice(4, 8))):  # fmt: skip
        part = np.zeros(8)
        part[idx] = J8[i, idx]
        print(f"    {label}: {np.array2string(d['F'] @ part / tightening, precision=3)}")
    print(f"    (tightening {tightening[0]:.4f} / {np.degrees(tightening[1]):.2f} deg)")
    print("  largest Z_8 norm over all jumps with a group of states left out:")
    for label, idx in GROUPS.items():
        Jd = J8.copy()
        Jd[:, idx] = 0.0
        print(f"    without {label}: {z8(Jd).max():.3f}")
    # the worst jump along switching sequences of the closed-loop vertices
    tp = build_tp_model(veh, "cm", 4, 5, 21, 21)
    scale = np.concatenate([tp.state_scale, tp.input_scale])
    nv = nominal_vertices(box, veh, tm, dict(PAPER_UNCERTAINTY), float(d["rho_min"]), TS,
                          N_SUB, scale, int(d["k"]), d["w_design"], d["col_scale"],
                          hessians=False)  # fmt: skip
    A, B = nv.vertices()
    Acl = A[:, 1:, 1:] + B[:, 1:, :] @ d["F"]
    rng = np.random.default_rng(3)
    for label, gamma in (("one-step estimate (one pulse)", 1.0), ("estimate gamma 0.2", 0.2)):
        peak_state, peak_norm, back = np.zeros(8), 0.0, 0
        for _ in range(sequences):
            e, b = np.zeros(8), 1.0
            for k, v in enumerate(rng.integers(len(Acl), size=1500)):
                e = Acl[v] @ e + b * J8[i]
                b *= 1.0 - gamma
                peak_state = np.maximum(peak_state, np.abs(e) / support)
                n = float(np.linalg.norm(np.linalg.solve(L, e)))
                peak_norm = max(peak_norm, n)
                if n > 1.0:
                    back = max(back, k + 1)
        print(f"  response to it along {sequences} switching sequences, {label}: peak Z_8 "
              f"norm {peak_norm:.3f}, above 1 until step {back} ({back * TS:.1f} s); "
              "peak per state / support:")  # fmt: skip
        print("    " + ", ".join(f"{n} {p:.3f}" for n, p in zip(NAMES, peak_state, strict=True)))
    print(f"({time.perf_counter() - t0:.0f} s)")


if __name__ == "__main__":
    here = Path(__file__).resolve().parents[1]
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else here / "tests/data/closed_tube_h_reset.npz",
         float(sys.argv[2]) if len(sys.argv) > 2 else 0.24,
         int(sys.argv[3]) if len(sys.argv) > 3 else 20)  # fmt: skip
