"""Case 2's sampled W against the true one-step disturbance over its tube's domain (item 1).

Case 2's design model is the ECM (eq. 40, eleven states: the notch filter's two last),
for which the domain bound of :mod:`fahv.design.certificate` is not built (nine-state
models only). This script measures what that bound would be asked to hold: the true
one-step disturbance of the perturbed nonlinear ECM (every sample at a corner of the
sec. 5.1 box, the constant part removed as the design removes it, the healthy elevator:
a loss's part is carried by the fault vertices and the estimate, which
:func:`sample_disturbance`'s LPV prediction does not model, so rho_f < 1 is left out
and the figures are lower bounds of what the domain asks for), sampled by the design's own routine
(:func:`fahv.design.disturbance.sample_disturbance`, margin 1) with the state deviations
drawn

1. from the box W was sampled over (the design's, ``DEFAULT_DEV_BOX`` plus the filter's
   states), inputs within the design's input box: a fresh draw of W's own distribution;
2. in Z itself (the tube's domain e in Z around the nominal): half the samples on its
   boundary, half uniform inside, the same inputs;

and prints the largest |w_j| per row as a multiple of the design's W. Each sample is one
RK4 step of the ECM from a random scheduling point of the envelope, so a row above 1
is a point of the tube's domain that the certificate does not cover.

    python scripts/case2_domain_study.py ARTEFACT_DIR [SAMPLES]

ARTEFACT_DIR is the folder ``fahv design offline_design/case2.yaml`` wrote (design.npz,
design.json); SAMPLES (default 2000) per configuration.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

import numpy as np

from fahv.design.case import case_from_mapping
from fahv.design.disturbance import DEFAULT_DU_BOX, deviation_box, sample_disturbance
from fahv.model.notch import NotchFilter
from fahv.model.tp_model import build_tp_model
from fahv.model.vehicle import IQ, load_vehicle
from fahv.plant.uncertainty import PAPER_UNCERTAINTY

ROWS = ("h", "V", "alpha", "theta", "q", "eta_1", "eta_1_dot", "eta_2", "eta_2_dot",
        "chi_1", "chi_2")  # fmt: skip


def main(argv: list[str]) -> int:
    """Print the largest sampled |w| per row as a multiple of W for both state boxes."""
    art = Path(argv[0])
    n_samples = int(argv[1]) if len(argv) > 1 else 2000
    data = json.loads((art / "design.json").read_text())
    case = case_from_mapping(data["case"], str(art / "design.json"))
    if case["design_model"] != "ecm":
        raise SystemExit(f"{art}: design model {case['design_model']}, this study is for the ECM")
    a = np.load(art / "design.npz")
    W, N = a["w_max"], a["N"]
    veh = load_vehicle()
    n = case["notch"]
    notch = NotchFilter(n["omega_z"], n["eps_z"], n["omega_p"], n["eps_p"])
    r_h, r_V = case["vertices"]
    n_h, n_V = case["samples"]
    tp = build_tp_model(veh, "ecm", r_h, r_V, n_h, n_V, notch)
    dev_w = deviation_box(notch, tp.state_scale[IQ])
    L = np.linalg.cholesky(N)

    def in_z(rng):  # on Z's boundary or uniform inside it, alternately
        d = rng.standard_normal(W.size)
        r = 1.0 if rng.random() < 0.5 else rng.random() ** (1.0 / W.size)
        return L @ (r * d / np.linalg.norm(d))

    draws = {"W's own box": None, "Z": in_z}
    unc = {k: v * case["uncertainty"]["scale"] for k, v in PAPER_UNCERTAINTY.items()}
    print(f"{case['name']}: W per row " + " ".join(f"{v:.3g}" for v in W))
    for label, states in draws.items():
        t0 = time.perf_counter()
        s = sample_disturbance(veh, tp, case["Ts"], unc, 1.0, dev_w, DEFAULT_DU_BOX, n_samples,
                               100, 1.0, notch=notch, constant=case["disturbance"]["constant"],
                               states=states)  # fmt: skip
        print(f"  {label}: {n_samples} samples [{time.perf_counter() - t0:.0f} s]")
        ratio = s.w_max / W
        rows = ", ".join(f"{r} {v:.2f}" for r, v in zip(ROWS, ratio, strict=True))
        worst = ROWS[int(np.argmax(ratio))]
        print(f"{label}: largest |w| / W per row: {rows}; largest {ratio.max():.2f} ({worst})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
